"""The song's end of the idle gate: a host after a song is no voice over it.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43: a host talking
after a song idles within 2 s). Right after a song the statistics still hold it for a moment, and the
voice network reads a host's first words as a voice over music (an espeak-ng host after DANCE_W_6 of
``benchmarks/studies/idle_gate.py --parts espeak``: -3 to +2.5, as over a song), so the voice-over and
pause rules kept 1.0 s of them as music and the host idled 2.20 s after the song. What sets the host
apart is how the music went: the stop network's logit (its running mean, ``music_gate.LOGIT_TAU``) fell
from sure music (:data:`SURE_TOP` or over) to no music (``-music_gate.MARGIN_STOP`` or under) within
one time constant of the statistics (the gate's ``tau_music``, 10 frames for the shipped model): the
song stopped at once. A voice that joins a song only lowers the stop network (-2 to +1), and a song's
quieter passage under a voice falls slower (fatswaller under the shared readers at 0 dB, 73.3-73.8 s:
14 frames). Where the voice-over context has judged the dance and heard no voice over it (the lone
voice's condition, ``lone_voice.py``: ``voice_context.CONTEXT_FRAMES`` danced, under
``voice_context.CONTEXT_MIN`` kept frames 10 to 2.5 s ago), after such a fall and until the stop
network hears music again (its logit over 0) the voice-over and pause rules keep no frame the voice
network does not lean to music on (its logit at or under ``veto.VOICE_NO_RUN``, the veto's threshold
while a count runs, mirrored; :meth:`SongEnd.ended`): the host's first words count towards the stop.
Where it leans to music the rules keep the frame as before: without that, the shared readers over fishin
at 0 dB (12.7-13.0 s, the voice network at +2.6 to +4.7) took a quiet bar for a fall, and the stop count
reached 14.99 of 15. A silence starts the fall's window again (a song's silent break is the break hold's,
``idle_gate.py``: the statistics wait through it and listen afresh after it; counted across it, pistachio
with 2-s breaks idled 1.2 % instead of 0.6), and the stop ends the song's end.

State (30 fps, sounding frames): ``rule`` (False: the song's end off), ``since_sure`` (sounding frames
danced since the stop network's running logit last lay at SURE_TOP or over, without a silence between),
``fell`` (the fall seen, the logit not back over 0 since) and ``frames`` (dancing frames heard as no
music that it kept the rules from keeping). The constant is read when used, so a study may set it on the
module (``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

from typing import Callable

from models.networks import veto, voice_context
from models.networks.voice_context import VoiceContext

#: Sure music: the stop network's running logit at or over SURE_TOP (twice ``music_gate.MARGIN_STOP``, the
#: mirror of the sure count, ``music_gate.SURE_COUNT``), not tuned.
SURE_TOP: float = 4.0
#: ``since_sure`` with no sure frame to count from (a silence, the idle).
_NEVER: int = 1 << 30


class SongEnd:
    """The song's end's state (module docstring): :meth:`step` on every sounding frame, :meth:`silence` on a
    silent one, :meth:`ended` on a dancing frame the stop network hears as no music.

    fall_frames: the most sounding frames from sure music to no music that is a fall (the gate's
    ``tau_music``); margin_stop: no music (``music_gate.MARGIN_STOP``)."""

    def __init__(self, fall_frames: int, margin_stop: float) -> None:
        self.fall_frames = int(fall_frames)
        self.margin_stop = float(margin_stop)
        self.rule = True  # False switches the song's end off
        self.reset()

    def reset(self) -> None:
        self.since_sure = _NEVER  # sounding frames danced since the running logit was sure of music
        self.fell = False  # the fall seen, the logit not back over 0 since
        self.frames = 0  # dancing frames heard as no music the rules were kept from keeping

    def silence(self) -> None:
        """A silent frame: a fall counts from sure music after it."""
        self.since_sure = _NEVER

    def step(self, dancing: bool, logit: float) -> None:
        """One sounding frame of a performer that is ``dancing`` (``logit``: the gate's running logit, the
        stop network's while dancing): the frames since it was sure of music, the fall."""
        if not dancing:
            self.since_sure, self.fell = _NEVER, False
            return
        self.since_sure = 0 if logit >= SURE_TOP else min(_NEVER, self.since_sure + 1)
        if logit > 0.0:
            self.fell = False
        elif logit <= -self.margin_stop and self.since_sure <= self.fall_frames:
            self.fell = True

    def ended(self, context: VoiceContext, voice_logit: Callable[[], float]) -> bool:
        """The voice-over and pause rules keep no frame on this dancing frame heard as no music: with the
        rule on, after the fall, in a dance the voice-over ``context`` has judged and heard no voice over,
        the voice network's logit (``voice_logit()``, called only then) at or under VOICE_NO_RUN (counts
        ``frames``)."""
        if not (self.rule and self.fell and context.dance_run >= voice_context.CONTEXT_FRAMES
                and context.count < voice_context.CONTEXT_MIN) or voice_logit() > veto.VOICE_NO_RUN:
            return False
        self.frames += 1
        return True
