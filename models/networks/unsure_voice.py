"""A voice heard while the stop network wavers: evidence for the voice-over context.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43: a rapper or a host
who comes in after a song's instrumental start). The voice-over context
(:mod:`models.networks.voice_context`) holds a stop where a voice was heard over the dance before, and
it counted only the frames the voice-over or the pause rule kept: frames the stop network heard as no
music (its running logit at or below ``-music_gate.MARGIN_STOP``). Over much of a song a voice only
lowers the stop network's logit, so a voice that came in after the performer had danced often left no
kept frame 10 s to 2.5 s back, and a dip of the song under it stopped the dance (the shared readers over
vibeace from 12 s: 7.7 % idle at 0 dB, the context's count 1 at its stop at 53.6 s;
``benchmarks/studies/idle_gate.py --parts mixes --voice-from 12``, ``--trace vibeace@0 --voice-from 12``).

A dancing frame the stop network still hears as music but wavers on (running logit at or below
:data:`UNSURE_TOP`) where both cues of the voice-over rule hold (the voice network hears music, the
floor holds) is also a voice heard over the music for the context (:meth:`UnsureVoice.hears`); the frame
was music anyway, nothing else changes. A host after a song adds such frames only within the context's
lag (its first words), as it adds kept ones.

State (30 fps, a dancing performer's frames the stop network hears as music): ``rule`` (False: off, the
context counts kept frames only) and ``frames`` (frames counted). :data:`UNSURE_TOP` is read when used,
so a study may set it on the module (``benchmarks/studies/idle_gate.py --unsure-top``).
"""

from __future__ import annotations

from typing import Callable

#: A dancing frame whose stop logit (running mean) lies at or below UNSURE_TOP, the voice-over rule's
#: cues holding, counts as a voice heard over the music. Half MARGIN_STOP, as the veto's VETO_TOP; 0 and
#: 0.5 left vibeace under the readers from 12 s at -6 dB at 3.5 % idle (fishin at 0 dB 0.2 %), 2 reads as 1
#: (idle_gate.py --parts mixes --voice-from 12 --unsure-top N; docs/history-listening.md).
UNSURE_TOP: float = 1.0


class UnsureVoice:
    """The unsure voice's state (module docstring): :meth:`hears` on a dancing frame heard as music."""

    def __init__(self) -> None:
        self.rule = True  # False switches it off
        self.reset()

    def reset(self) -> None:
        self.frames = 0  # frames counted as a voice heard over the music

    def hears(self, stop_logit: float, voice_over: Callable[[], bool]) -> bool:
        """A voice heard over the music on this dancing frame that the stop network heard as music
        (``stop_logit``: its running logit; ``voice_over()``: both cues of the voice-over rule, called
        only with the rule on and the logit at or below UNSURE_TOP)."""
        if self.rule and stop_logit <= UNSURE_TOP and voice_over():
            self.frames += 1
            return True
        return False
