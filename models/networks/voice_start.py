"""The voice-over start of the idle gate: a song that starts under a voice starts the dance, and the resume.

Part of :class:`models.networks.music_gate.MusicGate`'s voice-over rule (issue 43). The voice-over
and the pause rules keep a dancing performer dancing but never start an idle one, whose detector
hears a voice over a song as a voice (a song that starts under a host; a band that drops under the
voice). An idle performer's frame also counts as music once both cues of the voice-over rule (the
voice network hears music, the floor holds) have held for long enough: a count of the frames where
they hold, up 1 a frame, down :data:`START_DECAY` a frame without, reaches :data:`START_EVIDENCE`
(1.5 s; :meth:`VoiceStart.hears`). **The resume** (:meth:`VoiceStart.resume`): while the performer
dances, the same count goes up 1 a frame that the voice-over or the pause rule keeps as music and
down :data:`START_DECAY` a frame that they do not keep, so a performer that a voice over the music
stopped after all starts again from what it had heard (a band that stays under a host restarts the
dance sooner; a host after a song has no voice over the music before it).

State (30 fps, sounding frames only: silence leaves it as it is): ``evidence`` (the count, frames,
0 to START_EVIDENCE), ``frames`` (idle frames the start heard as music), ``rule`` (False: the start
off, the resume with it) and ``resume_rule`` (False: the resume off, the count starts from 0 at the
stop). The constants are read when used, so a study may set them on the module
(``benchmarks/studies/idle_gate.py``).
"""

from __future__ import annotations

from typing import Callable

#: The voice-over start (module docstring): an idle performer's frame is evidence of music under
#: a voice when both cues of the voice-over rule hold (the voice network hears music, the floor
#: holds); a count up by 1 a frame of evidence and down by START_DECAY a frame without (capped at
#: START_EVIDENCE) starts the dance on a frame of evidence at START_EVIDENCE (1.5 s of evidence).
#: Chosen on espeak-ng hosts after training songs (idle_gate.py --parts espeak: at 40 frames one
#: host held 0.93; docs/history-listening.md, issue 43).
START_EVIDENCE: float = 45.0
START_DECAY: float = 0.25


class VoiceStart:
    """The voice-over start's state (module docstring): :meth:`hears` on an idle frame the detector
    alone does not start, :meth:`resume` on a dancing frame.

    rule: False switches the start off (an idle performer starts on its detector alone), the resume
    with it; resume_rule: False switches the resume off."""

    def __init__(self, rule: bool = True, resume_rule: bool = True) -> None:
        self.rule = bool(rule)
        self.resume_rule = bool(resume_rule)
        self.reset()

    def reset(self) -> None:
        self.evidence = 0.0  # the count (frames, START_EVIDENCE starts)
        self.frames = 0  # frames the voice-over start heard as music

    def hears(self, voice_over: Callable[[], bool]) -> bool:
        """The voice-over start on this idle frame: with the start on, the count up 1 where both cues
        of the voice-over rule hold (``voice_over()``, called only with the start on), down START_DECAY
        where not; True on a frame of evidence with the count at START_EVIDENCE (counts ``frames``)."""
        if not self.rule:
            return False
        ev = voice_over()
        self._count(ev)
        if ev and self.evidence >= START_EVIDENCE:
            self.frames += 1
            return True
        return False

    def resume(self, kept: bool, voice_rule: bool = True) -> None:
        """The resume on a dancing frame: the count up 1 where a rule ``kept`` the frame as music, down
        START_DECAY where not; 0 with the resume, the start or the voice-over rule (``voice_rule``) off."""
        if not (voice_rule and self.rule and self.resume_rule):
            self.evidence = 0.0
        else:
            self._count(kept)

    def _count(self, up: bool) -> None:
        """The count up 1 (capped at START_EVIDENCE) or down START_DECAY (floored at 0)."""
        self.evidence = min(START_EVIDENCE, self.evidence + 1.0) if up else max(0.0, self.evidence - START_DECAY)
