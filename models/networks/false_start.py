"""The false start's doubt of the idle gate: a dance the stop network never heard as music.

Part of :class:`models.networks.music_gate.MusicGate` (issue 43: an espeak-ng host talking from a
stream's start). The idle detector may take a host's first words for music (its statistics hear a
voice whose vowels hold their pitch as a song's notes); the voice-over and pause rules then keep the
dance, and once it stops, the voice-over start's count (the voice network hearing music under an
unbroken floor) starts it again, and again: an espeak-ng host from a stream's start danced 45 % of
30 s (``benchmarks/studies/idle_gate.py --parts leadin``). A song, even under a voice, is heard as
music by the stop network itself within seconds; a host alone rarely. A dance that stops before the
stop network's logit (its running mean) has been over 0 on :data:`CONFIRM_FRAMES` of its sounding
frames is a **false start**: after it, the voice-over start no longer starts the dance (its count
runs on) until a dance is confirmed, one the detector started on its own (over
``music_gate.MARGIN_START``), or :data:`RESUME_FRAMES` sounding frames after the stop at most (the
resume: a band that dropped under a voice and comes back at once).

State (30 fps, sounding frames only): ``rule`` (False: the doubt off), ``heard`` (frames of the
current dance the stop network heard as music), ``doubt`` (the last dance was a false start and none
confirmed since), ``since`` (sounding frames since the last stop), ``dancing`` (the state on the last
sounding frame) and ``frames`` (idle frames on which the doubt held back the voice-over start). The
constants are read when used, so a study may set them on the module
(``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

#: Sounding frames of a dance on which the stop network's logit (running mean) lies over 0 that confirm
#: it as music (1.5 s). The espeak-ng host from a stream's start: 21-36 in each of its four dances; the
#: songs under the readers or a host from their start: 99 or more in their first 10 s (sweetwaltz at 0 dB
#: 15 in its first 5 s: the doubt waits for the stop, it never ends a dance).
CONFIRM_FRAMES: int = 45
#: Sounding frames after a false start's stop within which the voice-over start may still start the dance
#: (the resume, 0.5 s: the readers over nutcracker at -6 dB start again 6 frames after a stop).
RESUME_FRAMES: int = 15


class FalseStart:
    """The doubt's state (module docstring): :meth:`step` on every sounding frame, :meth:`trusts` where
    the voice-over start would start an idle performer."""

    def __init__(self) -> None:
        self.rule = True  # False switches the doubt off
        self.reset()

    def reset(self) -> None:
        self.heard = 0  # frames of the current dance the stop network heard as music
        self.doubt = False  # the last dance was a false start, none confirmed since
        self.since = 0  # sounding frames since the last stop
        self.dancing = False  # the state on the last sounding frame
        self.frames = 0  # idle frames on which the doubt held the voice-over start back

    def step(self, dancing: bool, logit: float) -> None:
        """One sounding frame of a performer that is ``dancing`` (the gate's logit ``logit``: the stop
        network's running mean while dancing): count what the stop network heard, judge a dance at its stop."""
        if dancing:
            if not self.dancing:
                self.heard = 0  # a dance starts
            self.heard += logit > 0.0
            if self.heard >= CONFIRM_FRAMES:
                self.doubt = False
        else:
            if self.dancing:  # the dance stopped: a false start if the stop network never confirmed it
                self.doubt = self.doubt or self.heard < CONFIRM_FRAMES
                self.since = 0
            self.since += 1
        self.dancing = dancing

    def trusts(self) -> bool:
        """The voice-over start may start the dance on this idle frame: no false start in doubt, or still
        within RESUME_FRAMES of its stop (counts ``frames`` where it may not)."""
        if self.rule and self.doubt and self.since > RESUME_FRAMES:
            self.frames += 1
            return False
        return True
