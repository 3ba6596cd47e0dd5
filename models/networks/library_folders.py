"""Which folder (style) of a library the music's choice plays under ``auto`` (issue 40, docs/library.md).

A library's stream matches the drawn codes' exemplars to the playing motion; a move to another
folder's poses is a far handover, which the far-handover guard (library_player.HANDOVER_GUARD)
declines, so without a choice of its own the stream kept to the folder it started in. Here the
music chooses the folder, one at a time: every code step each folder's evidence is the drawn
code's style prior (library_player: ln P(folder | code), K x F) plus the tempo's tilt times the
folder's liveliness (:data:`FOLDER_TEMPO`), averaged over the last code steps (:data:`FOLDER_MEMORY`);
the stream plays only the playing folder's exemplars, and moves

* at the first movement and while the idle is full (nothing of the dance is seen): to the folder
  of the highest evidence of that code step, at once;
* while dancing: to another folder once its mean leads the playing one's by :data:`FOLDER_MARGIN`
  and the playing one has danced :data:`FOLDER_DWELL` code steps. The handover to it is matched
  like any other (the drawn codes' exemplars of that folder, else its nearest: the smallest bend
  it has) and inertialized.

A requested style (``--style``, the live control) plays its folder, and ``auto`` takes over from it.
State: the playing folder, the means (F,), code steps since the last move. A few operations a
code step (every 8 frames at 30 fps); never blocks.
"""

from __future__ import annotations

import numpy as np

#: Off: under ``auto`` a library's stream matches among all folders' exemplars (it keeps to the one it starts in).
FOLDER_CHOICE: bool = True
#: Weight of the newest drawn code's prior in the running mean (per code step of 267 ms).
FOLDER_MEMORY: float = 0.25
#: ln-probability the running mean of another folder must lead the playing folder's by to move there.
FOLDER_MARGIN: float = 0.5
#: Code steps (267 ms each) a folder plays at least before the music's choice may move the stream on.
FOLDER_DWELL: int = 8
#: The tempo's say: each code step's evidence for a folder also gains the tempo's tilt (dance_stream's
#: ``Chooser.tempo_tilt``: + above the memory's tempo, - below) times this times the folder's liveliness (the
#: mean z-score of ln its exemplars' joint speed over the memory): a faster tempo, the livelier folder.
FOLDER_TEMPO: float = 1.0


class FolderChoice:
    """The folder a library's stream plays under ``auto``. ``prior`` (K, F): ln P(folder | code) of
    the library's F >= 2 folders (``style_prior[:, STYLE_BASE:]``); ``lively`` (F,): each folder's
    liveliness (:data:`FOLDER_TEMPO`); :meth:`step` every code step."""

    def __init__(self, prior: np.ndarray, lively: np.ndarray | None = None) -> None:
        self._prior = np.asarray(prior, np.float64)
        self._lively = np.zeros(self._prior.shape[1]) if lively is None else np.asarray(lively, np.float64)
        self.reset()

    def reset(self) -> None:
        """No folder yet (a new stream)."""
        self.folder = -1  # index of the playing folder, -1 before the first movement
        self._mean = np.zeros(self._prior.shape[1])
        self._since = 0
        self.moves = 0  # moves while dancing since the reset

    def step(self, code: int, free: bool, tilt: float = 0.0) -> int:
        """The folder (index) whose exemplars this code step plays, given the first ``code`` the
        predictor drew and the tempo's ``tilt``; ``free``: nothing of the dance is seen (first
        movement, full idle), move at once."""
        p = self._prior[code] + FOLDER_TEMPO * tilt * self._lively
        self._since += 1
        if free or self.folder < 0:
            self._mean = p.copy()
            self.folder, self._since = int(np.argmax(p)), 0
            return self.folder
        self._mean += FOLDER_MEMORY * (p - self._mean)
        best = int(np.argmax(self._mean))
        if (best != self.folder and self._since >= FOLDER_DWELL
                and self._mean[best] - self._mean[self.folder] >= FOLDER_MARGIN):
            self.folder, self._since = best, 0
            self.moves += 1
        return self.folder

    def follow(self, folder: int) -> None:
        """A requested style plays ``folder`` (index) this code step: ``auto`` takes over from it, after
        :data:`FOLDER_DWELL` code steps at the earliest."""
        self.folder, self._since = folder, 0


def folder_choice(model, speed: np.ndarray, real: np.ndarray) -> FolderChoice | None:
    """A :class:`FolderChoice` for a stream of ``model`` (``speed`` (K, M): each exemplar's mean joint
    speed, m/frame; ``real`` (K, M): the exemplars that exist): a library model of two or more folders
    that chooses with the far-handover guard (library_player.library_model sets ``handover_guard``);
    None otherwise (a checkpoint's own memory, ``--mix``, one folder) or with :data:`FOLDER_CHOICE` off."""
    from models.networks.library_player import STYLE_BASE, library_styles

    names = library_styles(model)
    if not FOLDER_CHOICE or len(names) < 2 or not getattr(model, "handover_guard", 0.0):
        return None
    ln = np.log(np.maximum(speed, 1e-6))
    z = (ln - ln[real].mean()) / max(float(ln[real].std()), 1e-6)
    style = model.member_style.numpy()
    lively = np.array([float(z[real & (style == STYLE_BASE + i)].mean()) for i in range(len(names))])
    return FolderChoice(model.style_prior.numpy()[:, STYLE_BASE:], lively)
