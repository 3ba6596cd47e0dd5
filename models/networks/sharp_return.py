"""The music's sharp return: an idle performer takes one network's word where the sound comes back sharply.

Part of :class:`models.networks.music_gate.MusicGate` (issue 43, back within 1 s of the music). The three
networks' agreement (``agreement.py``) needs the detector, the stop and the voice network to lean to music
at once; at some returns only one of them does for the first 0.5-1 s:

* out of a silence: room tone at -60 dBFS lies under the silence threshold, and the next song opens with a
  hit, then 0.7 s at -20 to -38 dB; the stop network hears music (+1.6 to +2.5) on the hit's 3 frames (its
  statistics, frozen through the silence, still partly the song before), the detector and the voice network do not (``benchmarks/studies/idle_gate.py --parts gaps --seed 9 --trace
  'gap:room -60'``: back in 1.70 s);
* on a rise: trance after a reader comes in 18 dB over the reading's level; the voice network hears music
  (+4.8 to +5.5) from 0.13 s, the stop network its detuned synthesizers at -0.8 to -2.6 (``--trace
  sweetwaltz@198``: back in 1.07 s).

A silence followed by a sound, or a sound far over the gap's own level, is not how a voice, a crowd or a
noise goes on (their words and murmurs rise back to their level), so there one network is enough. An
idle performer that has danced in this stream (``agreement.has_danced``) hears music on a *return frame*
(one of the first ``music_gate.FRESH_FRAMES`` sounding frames after ``music_gate.FRESH_SILENCE`` silent
ones or more, or a frame ``idle_gate.RETURN_DB`` or more over the running level, which follows the gap's
sound while idle: :attr:`SharpReturn.rise`, set by the idle gate) where the stop network's logit is above
:data:`RETURN_STOP` or the voice network's above :data:`RETURN_VOICE` (the agreement's own thresholds).

Room tone at about the silence threshold may leave the statistics holding the room's flickers, not the song
before (``--gap-s 20 --seed 10``: the stop network at -4.6 to +0.6 on the hit, back 1.70 s). A break (silence,
or 20 dB under the music's level, ``idle_gate.BREAK_DB``) of ``idle_gate.BREAK_HOLD`` frames or more has
stopped any dance (the music gone) and leaves the running level at the music's; the frame that ends it back
within ``idle_gate.RETURN_DB`` of that level starts the dance: its first :data:`LOUD_FRAMES` frames are music
whatever the networks hear (:meth:`SharpReturn.ends_break`). And a detector's start within ``FRESH_FRAMES``
sounding frames of a long break's end, at any level, is the music's return, as one right after a silence: the
confirmation (``return_confirm.py``) does not ask (:meth:`SharpReturn.exempts`). A stream's first start stays
the detector's (no gap before it). A gate without both networks has none.

State (30 fps): ``rule`` (False: the sharp return off), ``rise`` (the frame is a rise), ``loud`` (frames of a
long break's loud end left), ``since_end`` (sounding frames since a long break ended), all from the idle gate's
:meth:`SharpReturn.see` before each frame, ``since_silence`` (sounding frames since a silence, from the music
gate), and ``frames`` (idle frames it heard as music). The constants
are read when used.
"""

from __future__ import annotations

from typing import Callable

#: On a return frame the stop network alone hears music above RETURN_STOP, the voice network alone above
#: RETURN_VOICE: the agreement's AGREE_STOP (``music_gate.MARGIN_START``) and AGREE_VOICE, not tuned.
RETURN_STOP: float = 1.5
RETURN_VOICE: float = 5.0
#: A long break's loud end: its first LOUD_FRAMES frames are music (``music_gate.START_FRAMES``: the dance starts).
LOUD_FRAMES: int = 3


class SharpReturn:
    """The sharp return's state (module docstring): :meth:`hears` on an idle frame that no other rule
    starts.

    active: the gate has a stop and a voice network (without both, no sharp return)."""

    def __init__(self, active: bool) -> None:
        self.active = bool(active)
        self.rule = True  # False switches the sharp return off
        self.reset()

    def reset(self) -> None:
        self.frames = 0  # idle frames the sharp return heard as music
        self.rise = False  # this frame lies idle_gate.RETURN_DB or more over the running level (set by the idle gate)
        self.loud = 0  # frames of a long break's loud end left to hear as music
        self.since_end = 1 << 30  # sounding frames since a long break ended (at any level)
        self.since_silence = 1 << 30  # sounding frames since a silence (the stream's start is none)

    def sound(self, after_silence: bool) -> None:
        """A sounding frame (the music gate's word): the first after ``music_gate.FRESH_SILENCE`` silent ones or more
        (``after_silence``) or not."""
        self.since_silence = 0 if after_silence else self.since_silence + 1

    def see(self, rise: bool, broke: bool, ended: bool, loud: bool) -> None:
        """The idle gate's word on an idle frame, before the detector: it ``rise``s RETURN_DB or more over the running
        level, it is a break frame (``broke``), it ``ended`` a break of ``idle_gate.BREAK_HOLD`` frames or more (silence
        or quiet: the music had gone), ``loud``: back within ``idle_gate.RETURN_DB`` of the level."""
        self.rise = rise
        self.loud = LOUD_FRAMES if ended and loud else 0 if broke else self.loud
        self.since_end = 0 if ended else self.since_end + (not broke)

    def exempts(self, fresh_frames: int) -> bool:
        """A start within ``fresh_frames`` (``music_gate.FRESH_FRAMES``) sounding frames of a long break's end is the
        music's return, as one right after a silence: the confirmation (``return_confirm.py``) does not ask."""
        return self.rule and self.active and self.since_end < fresh_frames

    def ends_break(self, has_danced: bool) -> bool:
        """This idle frame of a performer that ``has_danced`` is one of the first LOUD_FRAMES after a long break's
        loud end (:meth:`see`): music, whatever the networks hear; counts ``frames``."""
        if not (self.loud > 0 and self.rule and self.active and has_danced):
            return False
        self.loud -= 1
        self.frames += 1
        return True

    def hears(self, has_danced: bool, fresh_frames: int, stop_logit: Callable[[], float],
              voice_logit: Callable[[], float]) -> bool:
        """One network hears music on this idle frame of a performer that ``has_danced`` in this stream,
        a return frame (within ``fresh_frames``, ``music_gate.FRESH_FRAMES``, sounding frames of a silence, or
        :attr:`rise`): the stop network's logit (``stop_logit()``) above RETURN_STOP or the voice network's
        (``voice_logit()``) above RETURN_VOICE, each called only when needed; counts ``frames``."""
        if not (self.rule and self.active and has_danced and (self.since_silence < fresh_frames or self.rise)):
            return False
        if stop_logit() > RETURN_STOP or voice_logit() > RETURN_VOICE:
            self.frames += 1
            return True
        return False
