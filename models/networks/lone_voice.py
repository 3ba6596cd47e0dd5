"""The lone voice of the idle gate: a voice after a song that no voice was heard over.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43: a host talking
after a song idles within 2 s). The pause rule (:mod:`models.networks.voice_pauses`) keeps a dancing
performer's frame as music where the steadiness in the quietest quarter of the last 0.67 s holds as
music's does; a continuous espeak-ng voice, its vowels holding their pitch, is as steady, so it kept
a host's first 1-1.4 s after a song as music and three of sixteen hosts took 2.20-2.23 s to idle
(``benchmarks/studies/idle_gate.py --parts espeak``). Over a song the voice network mostly hears the
music under the voice; after one it is often sure there is none. Where the voice-over context has
judged the dance (``voice_context.CONTEXT_FRAMES`` sounding frames danced) and heard no voice over the
music (fewer than ``voice_context.CONTEXT_MIN`` kept frames 10 s to 2.5 s ago: the context would not
hold a stop), a frame the pause rule would keep is

* **not kept** where the voice network is sure there is no music (logit at or below
  ``-veto.VOICE_NO``, the veto's threshold), and
* **holds the stop count** (neither counts towards the stop nor clears it) where it leans that way
  (at or below ``-veto.VOICE_NO_RUN``, the veto's threshold while a count runs): one steady pause of
  the host's no longer sends a count of 14 back to 0 (:attr:`LoneVoice.holding`, read by
  :class:`models.networks.idle_gate.IdleGate`).

No constant of its own. State (30 fps, a dancing performer's frames the pause rule would keep):
``rule`` (False: the lone voice off, the pause rule as before), ``holding`` (this frame holds the
count), ``frames`` (frames not kept) and ``held`` (frames that held the count).
"""

from __future__ import annotations

from typing import Callable

from models.networks import veto, voice_context, voice_pauses
from models.networks.voice_context import VoiceContext


class LoneVoice:
    """The lone voice's state (module docstring): :meth:`pause_keeps` where the pause rule is asked."""

    def __init__(self) -> None:
        self.rule = True  # False switches the lone voice off
        self.reset()

    def reset(self) -> None:
        self.holding = False  # this frame, kept by the pause rule, holds the stop count
        self.frames = 0  # frames the pause rule would have kept that the lone voice did not
        self.held = 0  # frames that held the stop count

    def pause_keeps(self, pauses: voice_pauses.VoicePauses, pause_steady: float, context: VoiceContext,
                    voice_logit: Callable[[], float]) -> bool:
        """The pause rule on a dancing frame the stop network hears as no music (``pause_steady``: the
        steadiness in the voice's pauses; ``context``: the voice-over context; ``voice_logit()``: the
        voice network's logit, called only where the pause rule would keep the frame in a judged dance
        without a voice heard over it): whether the frame is kept; sets :attr:`holding`."""
        self.holding = False
        if not pauses.would_keep(pause_steady):
            return False
        if (self.rule and context.dance_run >= voice_context.CONTEXT_FRAMES
                and context.count < voice_context.CONTEXT_MIN):
            z = voice_logit()
            if z <= -veto.VOICE_NO:
                self.frames += 1
                return False  # a lone voice: not kept
            if z <= -veto.VOICE_NO_RUN:
                self.holding = True
                self.held += 1
        return pauses.keeps(pause_steady)
