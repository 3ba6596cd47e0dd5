"""The voice network confirms a restart: the idle gate's detector restarts no dance on a voice or a crowd.

Part of :class:`models.networks.music_gate.MusicGate` (issue 43, held: once settled, idle for the rest
of a gap). After a song, the idle detector may take a reader's word or a crowd's murmur for music for
three frames (its logit over ``music_gate.MARGIN_START``) and restart the dance: reader 198 2 s into
its reading after brahms, fatswaller and vibeace (held 0.92-0.93, ``benchmarks/studies/idle_gate.py
--parts readers``), crowd babble at -30 dBFS 1.7 s and 7.5 s after a stop in the 20-s gap at seed 10
(held 0.71). On those start frames the voice network (fitted to hear music under a voice too) lay at
-2.9 to +0.6 (+1.7 on a later one of the crowd's, 10 s after the stop); on the start frames of the music's returns traced after a reader at +3.1 or more. The
detector's start (the frame on which its count reaches ``music_gate.START_FRAMES``) after the stream's
first dance waits until the voice network's logit on that frame is above :data:`CONFIRM_VOICE`, the
count running on meanwhile, where the gate asks it to (``idle_gate``): soon after a stop (a restart:
fewer than ``idle_gate.SONG_IDLE`` idle frames), or later without a rise (the frame less than
``idle_gate.RETURN_DB`` over the running level, which follows the gap's sound while idle): a song comes
in over a crowd or a room louder than it (room -45's next song, the voice network at -2.2 on its start
frame, 29 dB over the room), or the voice network hears it. Not within the first
``music_gate.FRESH_FRAMES`` sounding frames after ``music_gate.FRESH_SILENCE`` silent ones or more: a
sound after a silence is the music's return (a song's opening after a silence: the voice network at
-1.8 to +0.6 on its first frames; after a 3.5-s silence back in 1.67 s instead of 0.63 if it waited),
not a word or a murmur in a sound that runs on. The stream's first start stays the detector's alone,
and the starts of the voice-over start and of the three networks' agreement already need the voice
network.

State (30 fps): ``rule`` (False: the confirmation off), ``sounding`` (sounding frames since the last
silence of ``FRESH_SILENCE`` frames or more, set by the gate) and ``frames`` (start frames it held back).
The constant is read when used, so a study may set it on the module (``benchmarks/studies/idle_gate.py
--confirm-voice``).
"""

from __future__ import annotations

from typing import Callable

#: A detector's start the gate asks about waits until the voice network's logit is above CONFIRM_VOICE:
#: ``music_gate.MARGIN_STOP``, as sure of music as the stop network must be of none. The false restarts' start
#: frames: -2.9 to +0.6, and +1.7 (crowd -30, 20-s gap at seed 10, 10 s after the stop: held 0.92 at 1.5, the
#: detector's own start margin ``MARGIN_START``); the music's returns after a reader: +3.1 or more; the lowest
#: a song's return asked about at 1.5 (crowd -45, 10-s gap at seed 8: +1.50, a long break's loud end now,
#: ``sharp_return.py``). Set on that crowd: docs/presence.md.
CONFIRM_VOICE: float = 2.0


class ReturnConfirm:
    """The confirmation's state (module docstring): :meth:`confirms` on an idle frame on which the
    detector's count would start the dance.

    active: the gate has a voice network (without one, no confirmation)."""

    def __init__(self, active: bool) -> None:
        self.active = bool(active)
        self.rule = True  # False switches the confirmation off
        self.reset()

    def reset(self) -> None:
        self.frames = 0  # start frames the confirmation held back
        self.sounding = 0  # sounding frames since the last silence of FRESH_SILENCE frames or more (the gate sets it)

    def confirms(self, detector_start: bool, voice_logit: Callable[[], float], fresh_frames: int) -> bool:
        """The dance may start on this frame: True unless the rule is on, the gate has a voice network,
        ``detector_start`` (a start the gate asks about that the detector alone heard as music), ``fresh_frames`` (the gate's
        ``FRESH_FRAMES``) or more sounding frames since a silence, and the voice network's logit
        (``voice_logit()``, called only then) is at or below CONFIRM_VOICE (counts ``frames``)."""
        if not (self.rule and self.active and detector_start and self.sounding >= fresh_frames) \
                or voice_logit() > CONFIRM_VOICE:
            return True
        self.frames += 1
        return False
