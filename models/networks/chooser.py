"""The dance stream's chooser: per code step, which movement comes next.

:class:`Chooser` keeps the code predictor's context (the standardised feature history, the
coming audio token's first layer summed a frame at a time, the window of embedded tokens and the
next step's window computed ahead in pieces, :data:`PIECES_BY_8`), and every ``seg`` frames (8 at
30 fps) turns it into the next code: the predictor's logits (:class:`~models.networks.dance_numpy.
NumpyPredictor`; a requested style guided, :data:`STYLE_GUIDANCE`, and favoured, :data:`STYLE_PRIOR`),
tilted by the energy control (:data:`ENERGY_GAIN`) and the tempo (:data:`TEMPO_ENERGY`,
:data:`TEMPO_FREQ`), its repeats held back (:data:`REPEAT_PENALTY`), drawn from the stream's own
seeded generator (:data:`DRAWS` codes). It also says which exemplars of the drawn codes may play
(:meth:`Chooser.candidates`: the style's dancers, :data:`STYLE_MEMBERS`; those heading inwards near
a stage's edge; a library's nearest, :meth:`Chooser.nearest`); the stream matches them to the
motion and the player plays the chosen one (models/networks/dance_stream.py, ``_next_code``).
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from models.networks import player as player_part
from models.networks.dance_jit import push_history
from models.networks.dance_numpy import NumpyPredictor, Prefix, single_thread_blas
from models.networks.dance_vq import DanceVQ
from models.networks.library_folders import folder_choice
from models.networks.library_player import NEAREST, STYLE_BASE, member_choice
from models.networks.tempo import TempoFollower

if TYPE_CHECKING:
    from models.networks.stage import Stage

#: Codes drawn from the predictor at each step; the exemplar of theirs that best continues the
#: motion and dips in speed where the beat tracker expects the next beat is played.
DRAWS: int = 1
#: Weight of a speed dip on the expected beat against the continuity cost (median-normalised).
BEAT_WEIGHT: float = 1.0
#: Classifier-free guidance of a requested style (Ho & Salimans 2021): the logits move from
#: the music-only ones ("auto") past the style-conditioned ones by this factor. The predictor
#: was trained with the style token dropped to "auto" 40 % of the time, which is what it needs.
#: It costs a second prefix (the window in "auto"); cha-cha wins 15 of the 30 validation
#: song-seeds with it, 11 at 1.0 (benchmarks/studies/style_control.py --guidance; docs/training.md).
STYLE_GUIDANCE: float = 3.0
#: Weight of the style prior (``DanceVQ.style_prior``: how much likelier each code is in the
#: requested style's training dances) added to a requested style's logits.
STYLE_PRIOR: float = 3.0
#: With a requested style, play only exemplars from that style's dancers where the drawn
#: code has any (``DanceVQ.member_style``; a code without: all of its exemplars).
STYLE_MEMBERS: bool = True
#: The energy control (:meth:`~models.networks.dance_stream.DanceStream.set_energy`, 0..2, 1 = as the music
#: asks): the code logits move by ``ENERGY_GAIN * (energy - 1) * z``, z each code's movement speed
#: (:func:`~models.networks.member_tables.code_energy`; above 1 plus :data:`TEMPO_FREQ` times its quickness,
#: as the tempo's tilt reads it, so that at a fast tempo 2 stays livelier than 1), so energy 0 favours the
#: calmest movements and 2 the liveliest (benchmarks/studies/energy_control.py: the validation dances' motion
#: energy 0.51x, 0.97x and 1.56x the dancers' at 0, 1 and 2, rising from 0 to 1 to 2 on every song;
#: docs/show.md, "Energy").
ENERGY_GAIN: float = 3.0
#: Tempo and liveliness: the code logits also move by ``TEMPO_ENERGY * ln(T / T_ref) * z`` (T the followed
#: tempo, T_ref the memory's, z :func:`~models.networks.member_tables.code_energy` plus :data:`TEMPO_FREQ`
#: times :func:`~models.networks.member_tables.code_frequency`), blended out as the pulse fades like the rate:
#: at a faster tempo livelier movements, at a slower one calmer ones, as the dancers chose (over the memory's
#: exemplars, their own speed grows with the tempo of the song they were danced to: as its 0.64th power,
#: correlation 0.25). Without it the choice of movement ignores the tempo and only the playback rate follows
#: it; the speed caps hold the rate back at fast tempos (docs/history-listening.md, "Listening": stretch-set
#: speed ratio 1.24 at 0, 1.42 at 4 with :data:`~models.networks.player.SPEED_CAP_TEMPO`). Away from energy 1
#: (:meth:`~models.networks.dance_stream.DanceStream.set_energy`) it shrinks, to nothing at 0 and at 2: the
#: show's energy setting takes over (at full strength energy 0 moved as much as energy 1 on DANCE_R_5, and
#: energy 2 less than 1 on DANCE_C_2). 0: the choice ignores the tempo.
TEMPO_ENERGY: float = 4.0
#: The same tilt for a predictor that hears the tempo itself (``DanceVQConfig.tempo_input``,
#: models/training/tempo_predictor.py), which chooses by the tempo as the dancers did at it.
TEMPO_ENERGY_HEARD: float = 0.0
#: Tempo and frequency: the tempo's logit tilt (:data:`TEMPO_ENERGY`) reads each code's liveliness
#: plus this times its movements' frequency (:func:`~models.networks.member_tables.code_frequency`'s z-score: mean joint
#: acceleration over mean joint speed, the root's travel taken out). At a faster tempo the
#: performer then picks quicker movements, not only livelier ones, so the motion's frequency
#: follows the tempo and not only its speed; at a slower one broader, slower ones. With
#: :data:`~models.networks.player.SPEED_MATCH` and without it, the stretch set's frequency centroid ratio (1.25x over
#: 0.8x, seeds 0-5) was 1.25; with it 1.30 (docs/history.md, "Speed matching and quicker movements").
#: 0: the tilt reads liveliness only.
TEMPO_FREQ: float = 1.0
#: Repeats: a code drawn n >= :data:`REPEAT_FREE` times among the last :data:`REPEAT_WINDOW` draws has its
#: logit lowered by ``REPEAT_PENALTY * (n - REPEAT_FREE + 1)`` (a 5th time in 8 draws 1 lower, a 6th 2, ...).
#: Without it the predictor, its window (16 codes) full of one code, kept drawing it: runs of up to 27
#: movements (7 s), where the dancers' longest is 22 and 0.5 % of their movements are in runs of 12 or more
#: (4.2 % of the performer's). Each repeat restarts a movement of that kind near where the last one started
#: and the inertialization cancels most of it: the performer shuffles in place, at under half the speed of the
#: movements it plays, in loud music (1.4 % of the dancing frames on the listening recordings and validation
#: songs, DANCE_W_5 5.4 %; benchmarks/studies/repeats.py). A run broken by one other code (354 354 354 139 354
#: 354 354) shuffles as much, hence a window, not only a run. Calm codes repeat freely: the penalty is scaled
#: by ``z + REPEAT_CALM`` within [0, 1], z each code's liveliness
#: (:func:`~models.networks.member_tables.code_energy`'s z-score): none at z <= -1, full at z >= 0. Holding
#: still is no shuffle, and at energy 0 (only the calmest codes drawn) the penalty moved the calm performer
#: between still poses: DANCE_W_5 at energy 0 moved more than at 1 (1.64 against 1.47,
#: benchmarks/studies/energy_control.py). REPEAT_PENALTY 0: no limit.
REPEAT_FREE: int = 4
REPEAT_WINDOW: int = 8
REPEAT_PENALTY: float = 1.0
REPEAT_CALM: float = 1.0
#: The next code step's pieces ahead (:class:`~models.networks.dance_numpy.Prefix`: 7 for the
#: 3-layer predictor, in order the attention block of layer 0, its feed-forward's two halves, the
#: same for layer 1, layer 2's keys and values) done by the end of frame j of an 8-frame cycle,
#: in sevenths of them (rounded up; a prefix of other length takes the same shares): one on
#: frames 1, 2 and 7, two on 3 and 5, none on the code step, on frame 4 (the code step of a
#: performer staggered by half a cycle) and on 6. 4 staggered performers (phases 0, 2, 4, 6) put
#: every code step on an even hop and every lane at an odd position on the odd hops, which also
#: carry the handover's reads (frame 7): layer 0's first feed-forward half (the costliest piece
#: but one) on frame 2 and nothing on 6 make an even hop (a code step, frame 2) cost what an odd
#: one does, within 0.03 ms of CPU (p50; two pieces on frame 1, one on 2 and 6: 0.04 the other
#: way; layer 1's second half on 6 too: 0.12; benchmarks/studies/lane_parts.py, docs/latency.md),
#: and one performer's or two's costliest frame but the code step is lighter than with two pieces
#: on frame 1. Which frame computes a piece changes no value.
PIECES_BY_8: tuple[int, ...] = (0, 1, 2, 4, 4, 6, 6, 7)


class Chooser:
    """Chooses the next movement at each code step (see the module docstring).

    Shared, read-only: the predictor (``predictor``: :class:`NumpyPredictor`, one for every stream
    of a model), the memory's exemplar windows ``members`` (K, M, 2 seg, P), their speed dips
    ``dips`` (K, M, seg) and travel ``travel`` (K, M, 2 seg, 3), each code's liveliness
    ``code_energy`` (K,) and quickness ``frequency`` (K,) z-scores, the memory's mean tempo
    ``ref_period`` (frames a beat; 0 unknown). The tempo follower and the stage are the stream's,
    handed to each call that reads them.

    State (:meth:`reset`): ``rng`` (the draws' generator, from ``seed``), ``_hist`` (seg, D) the
    last ``seg`` feature rows standardised, ``_embed_acc`` / ``_embed_rows`` (the coming token's
    first layer and the frames summed into it), ``_tokens`` (the embedded tokens of the window),
    ``_prefix`` / ``_prefix_auto`` (the next step's window but its last token, in the style and in
    "auto" while a style is guided), ``_codes`` (the decoder's context), ``_last`` (the last code
    played; ``codebook``: none), ``_own`` (the library folder's style token auto keeps to; 0 any).
    ``style`` / ``pstyle`` (the exemplars' and the predictor's style token) and ``energy`` /
    ``_energy_bias`` follow the stream's controls (:meth:`set_style`, :meth:`set_energy`).
    """

    def __init__(self, model: DanceVQ, predictor: NumpyPredictor, seed: int, style: tuple[int, int],
                 feat_mean: np.ndarray, feat_std: np.ndarray, members: np.ndarray, dips: np.ndarray,
                 travel: np.ndarray, code_energy: np.ndarray, frequency: np.ndarray, speed: np.ndarray,
                 real: np.ndarray, ref_period: float) -> None:
        c = model.config
        self.model = model
        self.predictor = predictor  # the torch predictor's logits, in NumPy (dance_numpy)
        self._match = getattr(model, "code_chooser", None)  # (hist, period) -> logits (K,), or the predictor's
        self.seg, self._fd = c.seg, c.feature_dim
        self.seed = int(seed)
        self.style, self.pstyle = style  # exemplars' token, predictor's (library_player.resolve_style)
        self._feat_mean, self._feat_std = feat_mean, feat_std
        self.members, self.dips, self._travel = members, dips, travel
        self._travels = bool(travel.any())  # a memory without travel dances in place on any stage
        self.counts = model.member_count.numpy()
        self._style_prior = model.style_prior.numpy().astype(np.float32)  # (K, 4)
        self._member_style = model.member_style.numpy()  # (K, M): 0 unknown, else a style token
        self.code_energy = code_energy  # (K,) z-scores
        # what the tempo's tilt reads (TEMPO_ENERGY, TEMPO_FREQ): liveliness and quickness
        self.tempo_z = code_energy + np.float32(TEMPO_FREQ) * frequency if TEMPO_FREQ != 0.0 else code_energy
        # a library (library_player): codes drawn a step, the bend that draws the next, the tempo's tilt by exemplar
        self._draws, self.guard, self._member_tilt = member_choice(model, speed, real, DRAWS)
        where = np.argwhere(real)  # (n, 2) every exemplar's (code, slot); its first pose's quaternions (n, 4 J)
        self._first = (members[:, :, 0, 3:][real], where) if self.guard > 0.0 else None
        tok = self._member_style[where[:, 0], where[:, 1]]  # the same by member style token: a folder's own search
        self._first_of = {int(t): (self._first[0][tok == t], where[tok == t]) for t in np.unique(tok)} if self._first else {}
        self._folders = folder_choice(model, speed, real)  # under auto, the library folder the drawn codes choose; None: any
        # how much a repeat of each code is penalised (REPEAT_PENALTY): calm codes repeat freely
        self._repeat_weight = np.clip(code_energy + REPEAT_CALM, 0.0, 1.0).astype(np.float32)
        self._ref_period = ref_period
        self.energy = 1.0
        self._energy_bias: np.ndarray | None = None  # ENERGY_GAIN * (energy - 1) * z; None at 1
        # Frames of the cycle the next code step's prefix (its pieces ahead) is computed on: all but
        # the code step and the frame half a cycle from it, where the code step of a performer
        # staggered by half a cycle falls (an ensemble of 2 or 4: realtime.engine's stagger).
        # _pieces_by[j] / _pieces_den: the share of a prefix's pieces done by the end of frame j.
        # seg 8 (PIECES_BY_8): levelled for 4 staggered performers, whose code steps all fall on
        # even hops (frame 6 left free too); else spread evenly over those frames.
        skip = {0, self.seg // 2} if self.seg > 2 else {0}
        if self.seg == 8:
            self._pieces_by, self._pieces_den = PIECES_BY_8, PIECES_BY_8[-1]
        else:
            self._pieces_by = tuple(sum(1 for i in range(1, j + 1) if i not in skip) for j in range(self.seg))
            self._pieces_den = max(self._pieces_by[-1], 1)
        self.reset()

    def reset(self) -> None:
        """Forget the context: the next code step is the first of a new stream (the generator restarted)."""
        c = self.model.config
        self.rng = np.random.default_rng(self.seed)
        self._hist = np.zeros((self.seg, self._fd), np.float32)
        # the coming token's audio MLP first layer, summed a frame at a time (its bias + _embed_rows frames)
        self._embed_acc = self.predictor.embed_start()
        self._embed_rows = 0
        self._tokens: deque[np.ndarray] = deque(maxlen=c.window_codes)  # embedded (audio + previous code)
        self._prefix: Prefix | None = None  # the next code step's window but its last token, computed ahead
        self._prefix_auto: Prefix | None = None  # the same with the "auto" style, while a style is guided
        self._codes: deque[int] = deque(maxlen=c.decoder_context)
        self._last = c.codebook  # "no code yet"
        self._own = 0  # member style token the exemplars are kept to under auto (self._folders); 0 any
        if self._folders is not None:
            self._folders.reset()

    def set_style(self, style: int, pstyle: int) -> None:
        """The exemplars' style token and the predictor's (library_player.resolve_style), from the next code on."""
        self.style, self.pstyle = style, pstyle

    def set_energy(self, energy: float) -> None:
        """The stream's energy control (0..2, checked there), from the next code on (:data:`ENERGY_GAIN`)."""
        # above 1 livelier and quicker (what the tempo's tilt asks for at a fast tempo, so energy 2
        # stays above energy 1 there), below 1 calmer
        z = self.tempo_z if energy > 1.0 else self.code_energy
        self._energy_bias = None if energy == 1.0 else (ENERGY_GAIN * (energy - 1.0) * z).astype(np.float32)
        self.energy = energy

    # -- every frame -----------------------------------------------------------------------------
    def hear(self, row: np.ndarray, j: int) -> None:
        """Frame ``j`` (0..seg-1) of the cycle heard: its feature ``row`` (D,) into the history (its
        first columns, standardised), and on frames 1..seg-1 into the coming token's first layer
        (NumpyPredictor.embed_frame)."""
        push_history(self._hist, row, self._feat_mean, self._feat_std)
        if j:  # the coming token's first layer, a frame at a time (NumpyPredictor.embed_frame)
            if j == 1:
                self._embed_acc, self._embed_rows = self.predictor.embed_start(), 0
            if self._embed_rows == j - 1:
                self.predictor.embed_frame(self._embed_acc, self._hist[-1], j - 1)
                self._embed_rows = j

    def _held(self) -> list[np.ndarray]:
        """The window's tokens but the new one: the last ``window - 1`` (a full deque holds one more)."""
        return list(self._tokens)[-(self.predictor.window - 1):]

    def think(self, j: int) -> None:
        """Frame ``j`` (1..seg-1) of the cycle: its share of the next code step's pieces ahead (:data:`PIECES_BY_8`)."""
        if self._pieces_by[j] > self._pieces_by[j - 1]:
            for pre in (self._prefix, self._prefix_auto):
                if pre is not None and not pre.done:
                    keep = pre.pieces - -(-pre.pieces * self._pieces_by[j] // self._pieces_den)  # left after it
                    if pre.left > keep:
                        with single_thread_blas():  # (models/networks/dance_numpy.py)
                            while pre.left > keep:
                                pre.step()

    # -- a code step -----------------------------------------------------------------------------
    def draw(self, tempo: TempoFollower, recent: list[int], tempo_input: float) -> tuple[list[int], float]:
        """The code step: the window's new token in, the codes drawn (``DRAWS``, a library's more) and
        the tempo's tilt (:meth:`tempo_tilt`) they were drawn under. ``recent``: the codes drawn so
        far, oldest first (the repeat limit's); ``tempo_input``: what a predictor that hears the
        tempo is given (DanceStream.tempo_input; read only by such a predictor)."""
        m, pred = self.model, self.predictor
        guided = bool(self.pstyle) and STYLE_GUIDANCE != 1.0
        if self._embed_rows == self.seg - 1:  # its first seg - 1 frames were added as they came
            token = pred.embed_last(self._embed_acc, self._hist[-1], self._last)
        else:  # the stream's first token
            token = pred.embed(self._hist.reshape(-1), self._last)
        self._embed_rows = 0
        if pred.tempo is not None:  # a predictor that hears the tempo (DanceVQConfig.tempo_input)
            token = pred.with_tempo(token, tempo_input)
        prefix = self._prefix
        if prefix is None or prefix.style != self.pstyle:  # the first step, or the style changed since
            prefix = Prefix(pred, self._held(), self.pstyle)
        auto = (self._prefix_auto if self._prefix_auto is not None else Prefix(pred, self._held(), 0)) if guided else None
        if prefix.done and (auto is None or auto.done) and self._match is None:  # the new rows: compiled, no BLAS
            logits = self.logits(token, prefix, auto, tempo)
        else:  # a window's pieces not computed ahead, or a library's chooser: BLAS products
            with single_thread_blas():
                logits = self.logits(token, prefix, auto, tempo)
        if self.style and STYLE_PRIOR != 0.0:  # codes the requested style's dancers use
            logits = logits + STYLE_PRIOR * self._style_prior[:, self.style]
        bias = self._energy_bias  # read once: the control thread may swap it
        if bias is not None:  # livelier or calmer codes (set_energy)
            logits = logits + bias
        tilt = self.tempo_tilt(tempo)
        if tilt != 0.0:  # livelier codes at a faster tempo, calmer at a slower one (TEMPO_ENERGY)
            logits = logits + np.float32(tilt) * self.tempo_z
        if REPEAT_PENALTY > 0.0 and len(recent) >= REPEAT_FREE:
            logits = self.repeat_penalty(logits, recent)
        self._tokens.append(token)
        # the next step's window but its newest token is known now: its layers run on the frames between
        nxt = self._held()
        self._prefix = Prefix(pred, nxt, self.pstyle)
        self._prefix_auto = Prefix(pred, nxt, 0) if guided else None
        return [m.sample(logits, self.rng) for _ in range(self._draws)], tilt

    def commit(self, code: int) -> None:
        """``code`` is played (or held to): the next token and the decoder read it."""
        self._codes.append(code)
        self._last = code

    def decoded(self, code: int) -> np.ndarray:
        """The ``seg`` poses the decoder writes for ``code`` after the codes played (a code without exemplars)."""
        self._codes.append(code)  # the decoder reads the new code
        segment = self.model.decode_last(np.fromiter(self._codes, np.int64))
        self._codes.pop()
        return segment

    def follow_folder(self, code: int, fresh: bool, tilt: float) -> None:
        """A library's folders (library_folders.FolderChoice): a requested folder plays, and auto takes over
        from it; under auto the folder drawn ``code`` chooses (at once where ``fresh``: no dance seen)."""
        if self._folders is not None and self.style:  # a requested folder plays: auto takes over from it
            self._folders.follow(self.style - STYLE_BASE)
        elif self._folders is not None:  # the folder the drawn code chooses, at once where no dance is seen
            self._own = STYLE_BASE + self._folders.step(code, fresh, tilt)

    def logits(self, token: np.ndarray, prefix: Prefix, auto: Prefix | None, tempo: TempoFollower) -> np.ndarray:
        """The predictor's logits (K,) of the window ``prefix`` + ``token``, guided away from ``auto``'s
        (the same window in "auto": classifier-free guidance; None: unguided), or a library's chooser's."""
        pred = self.predictor
        logits = pred.logits_after(prefix, token)
        if auto is not None:  # classifier-free guidance towards the requested style
            base = pred.logits_after(auto, token)
            logits = base + STYLE_GUIDANCE * (logits - base)
        if self._match is not None:  # library_player chooser="match": the music's descriptors choose
            logits = self._match(self._hist, tempo.period)
        return logits

    def repeat_penalty(self, logits: np.ndarray, recent: list[int]) -> np.ndarray:
        """``logits`` (K,) with each code drawn n >= :data:`REPEAT_FREE` times among the last
        :data:`REPEAT_WINDOW` of ``recent`` lowered by ``REPEAT_PENALTY * (n - REPEAT_FREE + 1)``, times
        its liveliness weight (:data:`REPEAT_CALM`); a copy where any is lowered. Once per code
        step (every 8 frames)."""
        recent = recent[-REPEAT_WINDOW:]
        out = None
        for c in set(recent):
            n = recent.count(c)
            if n >= REPEAT_FREE:
                out = logits.copy() if out is None else out
                out[c] -= np.float32(REPEAT_PENALTY * (n - REPEAT_FREE + 1) * self._repeat_weight[c])
        return logits if out is None else out

    def tempo_tilt(self, tempo: TempoFollower) -> float:
        """:data:`TEMPO_ENERGY` (:data:`TEMPO_ENERGY_HEARD` for a predictor that hears the tempo) times
        ln(T / T_ref), blended to 0 as the pulse fades and as the energy control goes from 1 to 0 or
        to 2 (0 without a tempo, or with the player's ``FOLLOW_TEMPO`` off)."""
        period = tempo.period
        gain = TEMPO_ENERGY if self.predictor.tempo is None else TEMPO_ENERGY_HEARD
        if not player_part.FOLLOW_TEMPO or gain == 0.0 or self._ref_period <= 0.0 or period <= 0.0:
            return 0.0
        w = min(1.0, tempo.confidence / player_part.RATE_CONFIDENCE) * max(0.0, 1.0 - abs(self.energy - 1.0))  # the energy control set away from 1 takes over
        return gain * w * math.log(self._ref_period / period)

    # -- which exemplars may play ------------------------------------------------------------------
    def pairs(self, codes: list[int]) -> list[tuple[int, int]]:
        """(code, exemplar) of every exemplar of ``codes``."""
        return [(c, j) for c in codes for j in range(int(self.counts[c]))]

    def nearest(self, pose: np.ndarray) -> list[tuple[int, int]]:
        """(code, exemplar) of the :data:`~models.networks.library_player.NEAREST` exemplars of any code (of the
        requested style's) whose first pose is nearest ``pose`` (P,) (mean over the bones of sqrt(1 - |q . q'|))."""
        tok = self.style or self._own  # a requested style (or auto's folder): its own exemplars, where it has any
        first, where = self._first_of.get(tok, self._first) if tok and STYLE_MEMBERS else self._first  # (n, 4 J), (n, 2)
        q = pose[3:].reshape(-1, 4)
        block = np.zeros((q.size, len(q)), np.float32)  # each bone's quaternion in its own column: one matmul
        block[np.arange(q.size), np.repeat(np.arange(len(q)), 4)] = q.ravel()
        with single_thread_blas():
            dot = first @ block  # (n, J)
        d = np.sqrt(np.maximum(1.0 - np.abs(dot), 0.0)).mean(1)
        k = min(NEAREST, len(d))
        return [(int(where[n, 0]), int(where[n, 1])) for n in np.argpartition(d, k - 1)[:k]]

    def candidates(self, pairs: list[tuple[int, int]],
                   stage: Stage) -> tuple[list, np.ndarray, np.ndarray, np.ndarray | None]:
        """(pairs (code, exemplar), their windows (n, 2 seg, P), dips (n, seg), liveliness weights (n,)
        or None) of ``pairs`` as the style and the ``stage`` (models/networks/stage.py) allow."""
        tok = self.style or self._own
        if tok and STYLE_MEMBERS:  # a requested style (or auto's folder): its own exemplars where the codes have some
            own = [(c, j) for c, j in pairs if self._member_style[c, j] == tok]
            pairs = own or pairs
        if self._travels:  # near an edge: exemplars whose own travel heads inwards (stage.INWARDS)
            keep = stage.inwards([(float(self._travel[c, j, self.seg, 0]), float(self._travel[c, j, self.seg, 1]))
                                  for c, j in pairs])
            pairs = pairs if keep is None else [p for p, k in zip(pairs, keep) if k]
        tilt = self._member_tilt
        c, a = pairs[0] if pairs else (-1, 0)
        if pairs == [(c, j) for j in range(a, a + len(pairs))]:  # a run of one code's (a folder's): a slice, no gathering
            b = a + len(pairs)
            return pairs, self.members[c, a:b], self.dips[c, a:b], None if tilt is None else tilt[c, a:b]
        return (pairs, np.stack([self.members[c, j] for c, j in pairs]), np.stack([self.dips[c, j] for c, j in pairs]),
                None if tilt is None else np.array([tilt[p] for p in pairs]))
