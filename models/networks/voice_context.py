"""The voice-over context of the idle gate: a voice heard over this dance before holds its stop.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43, the voices at
0 dB). Under a voice as loud as the music the gate hears no music for up to 0.8-1.03 s at a time
(the floor broken by a dip, the music's own rest), and a stop takes 8-15 such frames. A dance of
:data:`CONTEXT_FRAMES` sounding frames or more in which a voice has been heard over the music
before (:data:`CONTEXT_MIN` frames kept by the voice-over or the pause rule, from
:data:`CONTEXT_FRAMES` to :data:`CONTEXT_LAG` sounding frames ago) stops only after
:data:`VOICE_HOLD` frames of no music in a row (:meth:`VoiceContext.holds`). A host after a song
has no voice over the music before the last 2.5 s (what the rules keep of a host's first words
lies within it) and stops as before; a false start on a host alone dances less than 10 s.
**The music gone** releases the hold: a frame whose floor is broken by more than
:data:`GONE_FLOOR_DB` and whose pauses are as unsteady as a voice alone (pause steadiness under
:data:`GONE_STEADY`; a gate without the steadiness column has none of this) or on which the voice network
is sure there is no music (its logit at or below ``-``:data:`GONE_VOICE`) is not held, so a voice going
on alone after the song stops as it would without the context.

State (30 fps, sounding frames only: silence leaves it as it is): a ring of the last
:data:`CONTEXT_FRAMES` frames' "a rule kept it" flags, ``count`` (kept frames from
CONTEXT_FRAMES to CONTEXT_LAG frames ago), ``unheard`` (a dancing performer's frames heard as no
music in a row) and ``dance_run`` (frames danced since the last idle one). The constants are read
when used, so a study may set them on the module (``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

from typing import Callable

#: A performer dancing CONTEXT_FRAMES sounding frames or more (10 s) that heard a voice over the music
#: (CONTEXT_MIN frames or more the voice-over or the pause rule kept, from CONTEXT_FRAMES to CONTEXT_LAG
#: frames ago: 10 s to 2.5 s) stops only after VOICE_HOLD frames of no music in a row (1.07 s; the longest
#: the readers' stretches last, 0.8-1.03 s: idle_gate.py --parts stretches). The lag outlasts what the
#: rules keep of a host's first words after a song (1-1.4 s): an espeak-ng host after a training song
#: (idle_gate.py --parts espeak) had no kept frame in the window at its stop, a voice over one 4 or more
#: (the readers too: brahms' 4); CONTEXT_MIN 3 lies between. The 10 s of dance keep a detector's false
#: start on a host alone (from a stream's start, --parts leadin; a restart within 5 s of a stop) from
#: holding its stops: without it an espeak host from a stream's start was not fully idle 73 % of 30 s
#: instead of 47 %, the host after DANCE_W_21 held 0.37 instead of 0.57. The window's ends are round
#: figures, not tuned; VOICE_HOLD 16-28 lost brahms or vibeace at 0 dB (3.0-3.7 % idle: idle_gate.py
#: --parts mixes --voice-hold N; docs/history-listening.md).
CONTEXT_FRAMES: int = 300
CONTEXT_LAG: int = 75
CONTEXT_MIN: int = 3
VOICE_HOLD: int = 32
#: The music gone (module docstring): a held frame is released where the floor (dB range over 1 s) is
#: above GONE_FLOOR_DB and the pause steadiness under GONE_STEADY (a voice alone; the readers' own
#: steadiness medians 0.02 and 0.06, music's 0.30-0.60: docs/presence.md). Set on the readers over the
#: shared recordings and going on after them (idle_gate.py --parts mixes,talkover --gone-floor-db ...):
#: at brahms', pistachio's and vibeace's held (due) stops the music under a voice kept a floor of 12-23 dB or a
#: steadiness of 0.10 or more; a floor of 21 dB reads the same, a steadiness of 0.1 too but for one talkover.
GONE_FLOOR_DB: float = 24.0
GONE_STEADY: float = 0.08
#: The music gone, too, where the floor is broken (over GONE_FLOOR_DB) and the voice network's logit lies at or
#: below -GONE_VOICE: sure there is no music. Three times MARGIN_STOP, not tuned: at 4 (the veto's VOICE_NO)
#: vibeace under the readers at 0 dB lost its held stop at 53.5 s (0.5 -> 3.8 % idle); with the voice heard where
#: the stop network wavers (unsure_voice.py) a voice going on alone after vibeace at -6 dB idled 1.30 s after the
#: music without it, 0.97 with it (idle_gate.py --parts mixes,talkover --gone-voice N; inf: off).
GONE_VOICE: float = 6.0


class VoiceContext:
    """The voice-over context's state (module docstring): :meth:`step` on every sounding frame,
    :meth:`holds` where a dancing performer's frame was heard as no music.

    release: the music gone may release the hold (the gate has a steadiness column)."""

    def __init__(self, release: bool) -> None:
        self.release = bool(release)
        self._kept = bytearray(CONTEXT_FRAMES)  # a rule kept the sounding frame (1), a ring
        self.reset()

    def reset(self) -> None:
        self._kept[:] = bytes(len(self._kept))
        self._at = 0  # the next slot of ``_kept``
        self.count = 0  # frames the rules kept from CONTEXT_FRAMES to CONTEXT_LAG sounding frames ago
        self.unheard = 0  # a dancing performer's sounding frames heard as no music in a row
        self.dance_run = 0  # sounding frames danced since the last idle one

    def step(self, kept: bool, heard: bool, dancing: bool) -> None:
        """One sounding frame: push whether a rule ``kept`` it as music into the ring (the count from
        CONTEXT_FRAMES to CONTEXT_LAG frames ago follows), count the frames not ``heard`` as music in a
        row, and the frames danced (0 on an idle frame)."""
        i = self._at
        self.count += self._kept[i - CONTEXT_LAG] - self._kept[i]  # a negative index wraps round the ring
        self._kept[i] = kept
        self._at = (i + 1) % len(self._kept)
        self.unheard = 0 if heard else self.unheard + 1
        self.dance_run = self.dance_run + 1 if dancing else 0

    def holds(self, floor_db: float, pause_steady: float, voice_logit: Callable[[], float] | None = None) -> bool:
        """The context holds a dancing performer's stop on this frame (floor ``floor_db``: the log
        energy's range over 1 s, dB; ``pause_steady``: the steadiness in the voice's pauses;
        ``voice_logit()``: the voice network's logit, called only where the floor is broken): it has
        danced CONTEXT_FRAMES sounding frames, a voice was heard over the music before (CONTEXT_MIN kept
        frames) and the music has been unheard for fewer than VOICE_HOLD frames in a row, unless the
        music is gone (floor above GONE_FLOOR_DB and pause steadiness under GONE_STEADY, with ``release``,
        or the voice network's logit at or below -GONE_VOICE)."""
        if not (self.dance_run >= CONTEXT_FRAMES and self.count >= CONTEXT_MIN and 0 < self.unheard < VOICE_HOLD):
            return False
        if floor_db <= GONE_FLOOR_DB:
            return True
        return not ((self.release and pause_steady < GONE_STEADY)
                    or (voice_logit is not None and voice_logit() <= -GONE_VOICE))
