"""The pause rule of the idle gate: the music heard in a voice's pauses is music.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43; with the
steadiness column only). Between a voice's words the music under it is heard alone, and music
holds its notes; a voice alone pauses into room noise or its own reverberation. A dancing
performer's frame the stop network hears as no music also counts as music when the steadiness
column's mean over the quietest quarter of the last :data:`PAUSE_FRAMES` sounding frames
(:func:`pause_steadiness`, the gate's ``pause_steady``) is above :data:`PAUSE_STEADY`
(:meth:`VoicePauses.keeps`).

State (30 fps, sounding frames only: silence leaves it as it is): a ring of the last
:data:`PAUSE_FRAMES` frames' log energy (dB) and steadiness (``ring_e``, ``ring_s``) with its next
slot and slots filled (``ring_at``), advanced by the gate's one compiled call a sounding frame
(``music_gate.sound_cues``); ``rule`` (False: the pause rule off) and ``frames`` (dancing frames it
kept as music). The constants are read when used (PAUSE_FRAMES when the gate is built), so a study
may set them on the module (``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: The pause rule (module docstring): the steadiness column's mean over the quietest quarter of
#: the last PAUSE_FRAMES sounding frames (0.67 s) above PAUSE_STEADY hears the music under a
#: voice. Chosen on espeak-ng voices over and after training songs (idle_gate.py --parts espeak;
#: docs/history-listening.md, issue 43).
PAUSE_FRAMES: int = 20
PAUSE_STEADY: float = 0.25


@njit(cache=True, nogil=True)
def pause_steadiness(ring_e, ring_s, state, e, s):  # pragma: no cover - compiled
    """Push log energy ``e`` (dB) and steadiness ``s`` into ``ring_e``, ``ring_s`` (PAUSE_FRAMES,)
    float64 at ``state[0]`` (the next slot; ``state[1]``: slots filled, both advanced in place) and
    return the mean steadiness of the quietest quarter of the filled slots (``1 + (m - 1) // 4`` of
    ``m``): what sounds in a voice's pauses. ``music_gate.sound_cues`` calls it, and numba's cache of that
    kernel does not see an edit here (touch music_gate.py, or clear its ``__pycache__``)."""
    n = ring_e.shape[0]
    i = int(state[0])
    ring_e[i] = e
    ring_s[i] = s
    state[0] = (i + 1) % n
    m = min(int(state[1]) + 1, n)
    state[1] = m
    k = 1 + (m - 1) // 4
    taken = 0  # bit j: slot j counted (PAUSE_FRAMES <= 63); no allocation, k passes over m slots
    acc = 0.0
    for _ in range(k):
        best = -1
        for j in range(m):
            if not (taken >> j) & 1 and (best < 0 or ring_e[j] < ring_e[best]):
                best = j
        taken |= 1 << best
        acc += ring_s[best]
    return acc / k


class VoicePauses:
    """The pause rule's state (module docstring): the rings that :func:`pause_steadiness` advances on
    every sounding frame, :meth:`keeps` on a dancing performer's frame the stop network hears as no music.

    rule: False switches the pause rule off."""

    def __init__(self, rule: bool = True) -> None:
        self.rule = bool(rule)
        self.ring_e = np.zeros(PAUSE_FRAMES)  # the last sounding frames' log energy (dB) and steadiness
        self.ring_s = np.zeros(PAUSE_FRAMES)
        self.ring_at = np.zeros(2)  # next slot, slots filled
        self.reset()

    def reset(self) -> None:
        self.ring_at[:] = 0.0  # no slot filled: the rings' old values are not read
        self.frames = 0  # frames the pause rule kept as music

    def would_keep(self, pause_steady: float) -> bool:
        """The pause rule is on and the steadiness in the voice's pauses (``pause_steady``,
        :func:`pause_steadiness`; -inf without the steadiness column) is above PAUSE_STEADY."""
        return self.rule and pause_steady > PAUSE_STEADY

    def keeps(self, pause_steady: float) -> bool:
        """The pause rule keeps this frame as music (:meth:`would_keep`); counts ``frames``."""
        if not self.would_keep(pause_steady):
            return False
        self.frames += 1
        return True
