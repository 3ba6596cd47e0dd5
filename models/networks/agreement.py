"""The three networks' agreement of the idle gate: an idle performer hears the music's return.

Part of :class:`models.networks.music_gate.MusicGate` (issue 43, back within 1 s of the music). At
the music's return the statistics (idle time constant, 0.2 s) hear the step from the gap's quiet to
the music's level as spread, as in speech, and the detector's logit stays between 0 and
``music_gate.MARGIN_START`` for 0.4-0.6 s while the stop and voice networks, which weigh the spread
less, already hear music. An idle performer that has danced in this stream (the music's return; a
stream's first start is as before: its statistics start from its first frame, no step) also hears
music where all three do: the detector above :data:`AGREE_START`, the stop network above
:data:`AGREE_STOP` and the voice network above :data:`AGREE_VOICE` (a gate without both networks has
none).

State (30 fps, sounding frames only): ``rule`` (False: the agreement off), ``has_danced`` (the
performer has danced in this stream) and ``frames`` (idle frames it heard as music). The constants
are read when used, so a study may set them on the module (``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

from typing import Callable

#: An idle performer's frame is music where the detector's logit is above AGREE_START (it leans to music),
#: the stop network's above AGREE_STOP (``music_gate.MARGIN_START``, the detector's own start margin) and
#: the voice network's above AGREE_VOICE (it hears music under a voice too, so it must be surer).
#: AGREE_VOICE set on espeak-ng hosts from a stream's start (idle_gate.py --parts leadin --agree-voice 4:
#: the dance started 29 s into one host; 4.5 the lowest that did not; docs/history-listening.md).
AGREE_START: float = 0.0
AGREE_STOP: float = 1.5
AGREE_VOICE: float = 5.0


class Agreement:
    """The agreement's state (module docstring): ``has_danced`` set by the gate on every sounding
    frame, :meth:`hears` on an idle frame the detector alone does not start.

    active: the gate has a stop and a voice network (without both, no agreement)."""

    def __init__(self, active: bool) -> None:
        self.active = bool(active)
        self.rule = True  # False switches the agreement off
        self.reset()

    def reset(self) -> None:
        self.frames = 0  # idle frames the agreement heard as music
        self.has_danced = False  # the performer has danced in this stream: a start is the music's return

    def hears(self, logit: float, stop_logit: Callable[[], float], voice_logit: Callable[[], float]) -> bool:
        """The three networks agree on music on this idle frame of a performer that has danced in this
        stream: the detector's logit ``logit`` above AGREE_START, the stop network's (``stop_logit()``)
        above AGREE_STOP and the voice network's (``voice_logit()``) above AGREE_VOICE, each called only
        when the rest before it holds; counts ``frames``."""
        if not (self.rule and self.has_danced and self.active and logit > AGREE_START
                and stop_logit() > AGREE_STOP and voice_logit() > AGREE_VOICE):
            return False
        self.frames += 1
        return True
