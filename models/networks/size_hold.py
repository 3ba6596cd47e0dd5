"""Quicker, not bigger: the tempo's tilt of the code choice with the movements' size held (issue 43).

``DanceStream`` tilts the predictor's code logits towards livelier and quicker movements at a
faster tempo and calmer, slower ones at a slower tempo (``dance_stream.TEMPO_ENERGY``). Liveliness
is speed, and speed is size times frequency: left alone the tilt draws larger movements at a fast
tempo and smaller ones at a slow one, and the dance-band amplitude of one song 1.25x over 0.8x
read 1.02-1.80 (issue 43 asks 0.8-1.2). :func:`hold_size` adds ``mu * s`` to the tilted logits
(s each code's size z, :func:`models.networks.member_tables.code_size`), ``mu`` chosen by a few
Newton steps so that the tilted distribution's mean size is the untilted one's (the music's ask):
the tilt then picks quicker movements of the size the predictor asked for. It holds
:data:`SIZE_HOLD` of the shift (1: all of it, 0: off). One call per code step (every 8 frames at
30 fps): a few softmaxes over the K codes, no allocation beyond K-sized temporaries.
"""

from __future__ import annotations

import numpy as np

#: Share of the tempo tilt's shift of the drawn codes' mean size z taken back by :func:`hold_size`
#: (1: the tilted choice has the untilted one's mean size; 0: off, the tilt as before). Shipped off
#: (docs/listening.md, "The amplitude"): held, the stretch set's 1.25x / 0.8x amplitude read
#: rate-neutral is within 0.90-1.14 on every song, but measured it stays over 1.2 on 5 songs (the
#: measure's own rate effect, 1.09-1.27), DANCE_C_2's centroid ratio falls 1.41 -> 1.23 and the 3x2
#: stage's raw jitter reads 1.32 at seed 2 (issue 39: 1.3); with TEMPO_FREQ 2, 1.35 at seed 3.
SIZE_HOLD: float = 0.0
#: The share where the tempo is faster than the memory's (the tilt positive); None: :data:`SIZE_HOLD`.
SIZE_HOLD_FAST: float | None = None
#: Newton steps of :func:`hold_size` at most (each moves mu by at most HOLD_STEP_CAP logit per size z,
#: the mean size being steep where the tilt is strong), the tolerance (size z) that ends them early
#: and the largest |mu| (logit per size z).
HOLD_STEPS: int = 10
HOLD_STEP_CAP: float = 0.5
HOLD_TOL: float = 0.01
HOLD_MU_CAP: float = 8.0


def share(tilt: float) -> float:
    """The hold's share for a tempo tilt ``tilt`` (logit per z; > 0 at a tempo over the memory's):
    :data:`SIZE_HOLD`, or :data:`SIZE_HOLD_FAST` where that is set and the tilt is positive."""
    return SIZE_HOLD if tilt < 0.0 or SIZE_HOLD_FAST is None else SIZE_HOLD_FAST


def _mean_var(logits: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """Mean and variance of ``s`` (K,) under softmax(``logits``) (K,)."""
    p = np.exp(logits - logits.max())
    p /= p.sum()
    m = float(p @ s)
    return m, float(p @ (s - m) ** 2)


def hold_size(before: np.ndarray, after: np.ndarray, size: np.ndarray, hold: float | None = None) -> np.ndarray:
    """``after`` (K,) logits (``before`` (K,) tilted) plus ``mu * size`` (K,) with ``mu`` such that the
    mean of ``size`` under their softmax moves from ``after``'s towards ``before``'s by ``hold`` (0-1;
    None: :data:`SIZE_HOLD`); ``after`` itself where it is 0. Logits at temperature 1 (``DanceVQ.sample``)."""
    hold = SIZE_HOLD if hold is None else hold
    if hold <= 0.0:
        return after
    s = size.astype(np.float64)
    target, _ = _mean_var(before.astype(np.float64), s)
    a = after.astype(np.float64)
    m, v = _mean_var(a, s)
    target = m + hold * (target - m)
    mu = 0.0
    for _ in range(HOLD_STEPS):  # the mean size rises with mu: damped Newton steps
        if abs(m - target) <= HOLD_TOL:
            break
        step = min(max((target - m) / max(v, 1e-6), -HOLD_STEP_CAP), HOLD_STEP_CAP)
        mu = min(max(mu + step, -HOLD_MU_CAP), HOLD_MU_CAP)
        m, v = _mean_var(a + mu * s, s)
    return (a + mu * s).astype(after.dtype)
