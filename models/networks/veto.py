"""The veto of the idle gate: an unsure stop network, a voice network sure of no music (a crowd).

Part of :class:`models.networks.music_gate.MusicGate` (issue 43: a crowd after a song). The stop
network may hear a crowd between ``-music_gate.MARGIN_STOP`` and 0 for as long as it lasts, neither
music nor sure enough to stop. A dancing performer's frame in that band is no music when the voice
network is sure there is none (logit at or below ``-``:data:`VOICE_NO`) and the floor holds (the log
energy's range over 1 s under ``music_gate.FLOOR_DB``: a crowd or a noise has no pauses; over a
song's quiet passage with a voice, or a voice alone, the floor breaks). Once a stop count runs
(:attr:`Veto.counting`, set by the idle gate) the stop network may climb back just over 0 in a crowd
while the voice network stays at -2 to -4: the count went back to 0 and the stop came 0.7 s later.
While it runs the veto also covers a stop logit up to :data:`VETO_TOP` with the voice network at or
below ``-``:data:`VOICE_NO_RUN`.

State (30 fps, a dancing performer's sounding frames): ``rule`` (False: the veto off) and ``counting``
(a stop count runs). The constants are read when used, so a study may set them on the module
(``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

from typing import Callable

#: A dancing frame the stop network is unsure of (its logit between -MARGIN_STOP and 0) is no music when
#: the voice network's logit lies at or below -VOICE_NO and the floor holds (under FLOOR_DB: no pauses, a
#: crowd or a noise, not a voice over a song's quiet passage). Twice MARGIN_STOP (where a frame counts
#: SURE_COUNT), not tuned (docs/presence.md).
VOICE_NO: float = 4.0
#: While a stop count runs (:attr:`Veto.counting`, module docstring) the veto also covers a stop logit up
#: to VETO_TOP, the voice network at or below -VOICE_NO_RUN. Half and once MARGIN_STOP, round figures; set
#: on crowd -30 in idle_gate.py's 20-s gap at seed 10 (the voice network -2.1 to -3.7 there; 2.5 reads the
#: same on every part). VETO_TOP 0 and VOICE_NO_RUN VOICE_NO: as when no count runs (docs/presence.md).
VETO_TOP: float = 1.0
VOICE_NO_RUN: float = 2.0


class Veto:
    """The veto's state (module docstring): :meth:`vetoes` on a dancing performer's frame that the
    stop network does not hear as no music.

    active: the gate has a voice network (without one, no veto); rule: False switches the veto off."""

    def __init__(self, active: bool, rule: bool = True) -> None:
        self.active = bool(active)
        self.rule = bool(rule)
        self.reset()

    def reset(self) -> None:
        self.counting = False  # a dancing performer's stop count runs (set by the idle gate): VETO_TOP

    def vetoes(self, stop_logit: float, floor_held: bool, voice_logit: Callable[[], float]) -> bool:
        """The veto on this frame: the stop network's logit (running mean) ``stop_logit`` at or below 0
        (VETO_TOP while a stop count runs), the veto on with a voice network, the floor held
        (``floor_held``: the log energy's range over 1 s under ``music_gate.FLOOR_DB``) and the voice
        network's logit (``voice_logit()``, called only when the rest holds) at or below -VOICE_NO
        (-VOICE_NO_RUN while a count runs)."""
        return (stop_logit <= (VETO_TOP if self.counting else 0.0) and self.rule and self.active and floor_held
                and voice_logit() <= -(VOICE_NO_RUN if self.counting else VOICE_NO))
