"""Speech's syllable rate: the presence networks' 13th statistic, the log energy's 4-Hz modulation (issue 43).

The classic speech/music discriminators (Scheirer & Slaney 1997) rely most on the energy modulated at 3-6 Hz,
speech's syllable rate. Here: the frame's log energy (dB, feature column 13, 30 fps) through a causal
2nd-order Butterworth band-pass at 3-6 Hz (:data:`BP_B0`, :data:`BP_A`), squared, its exponential mean over
:data:`TAU_MOD` frames (1 s, whatever the performer's state, as the beat statistics' own), in dB
(``10 log10``: the modulation depth's power; the band-pass removes the level). On the idle gate study's
material (``benchmarks/studies/modulation.py``): read speech and espeak-ng hosts lie over music (AUC 0.94 /
0.95), a host alone over the readers over music (0.97); crowd, applause and noise under it. The gate calls
:func:`modulation_step` on sounding frames only (silence freezes it, as the other statistics); its first frame
is its own past (no step from 0 dB).

State (:data:`N_MOD_STATE` numbers, in the presence detector's state vector): the band-pass's last two inputs
and outputs, the mean squared output, whether it has started.
"""

from __future__ import annotations

import math

from numba import njit

#: The band-pass (Hz at 30 fps): ``scipy.signal.butter(1, (3, 6), btype="band", fs=30)``; b = (B0, 0, -B0).
BP_B0: float = 0.24523727525278563
BP_A: tuple[float, float] = (-0.9329380346705198, 0.5095254494944288)
#: Time constant (frames) of the modulation's mean square (1 s).
TAU_MOD: float = 30.0
MOD_A: float = math.exp(-1.0 / TAU_MOD)
#: Numbers of state :func:`modulation_step` keeps.
N_MOD_STATE: int = 6


@njit(cache=True, nogil=True)
def modulation_step(e, state, at):  # pragma: no cover - compiled
    """Advance the modulation by one sounding frame's log energy ``e`` (dB) and return it (dB): ``state``
    (>= ``at`` + :data:`N_MOD_STATE`,) float64 in place, from index ``at``: x[t-1], x[t-2], y[t-1], y[t-2], the mean
    square, started (0 / 1)."""
    if state[at + 5] == 0.0:  # the first frame: its own past, no step
        state[at] = e
        state[at + 1] = e
        state[at + 5] = 1.0
    y = BP_B0 * (e - state[at + 1]) - BP_A[0] * state[at + 2] - BP_A[1] * state[at + 3]
    state[at + 1] = state[at]
    state[at] = e
    state[at + 3] = state[at + 2]
    state[at + 2] = y
    state[at + 4] = MOD_A * state[at + 4] + (1.0 - MOD_A) * y * y
    return 10.0 * math.log10(state[at + 4] + 1e-6)
