"""When the playing exemplar hands over to the next one: after its recorded frames, not after 8 output frames.

:class:`~models.networks.dance_stream.DanceStream` draws a code every ``seg`` (8) output frames
(the predictor's tokens, the ensemble's stagger and the prefix schedule all keep that cadence),
and plays one exemplar of it at the tempo's rate ``r`` (exemplar frames per output frame).
Handed over at every code step (shipped), an exemplar plays ``8 r`` of its recorded frames: at
the speed-matched rates the stream plays (0.76-0.78 of the tempo's) each movement is cut short
and a sway built over several movements shrinks with it (docs/history.md, "The amplitude gap").

With :data:`ON_FRAMES` the handover waits until the playing exemplar has played its ``seg``
recorded frames (to the nearest frame): a code step whose coming ``seg`` output frames end
before that holds (its drawn code is not played, the exemplar plays on), and the next code
step hands over at the row where the exemplar reaches its frame ``seg``, that many rows into
the coming movement. At ``r >= 1`` the exemplar has played its frames by the code step and the
handover is at once, as before.

State (:class:`Handover`, one per stream, ``reset`` with it): ``base``, the row of the player's
buffer (``Player._played``, models/networks/player.py) the current code step's frame 0 reads (un-warped; ``seg``
after a handover, moved on by a hold), ``start``, the row of the playing exemplar's frame 0,
the counts of handovers and holds, and ``rows``, the rows the exemplar last handed over from
had played (all three for measuring).
"""

from __future__ import annotations

#: True: an exemplar is handed over when it has played its ``seg`` recorded frames (8 frames over
#: ``8 / r`` output frames). False (shipped): at every code step (every 8 output frames, ``8 r``
#: recorded frames). On, with the beat warp at 0.5 (``player.BEAT_WARP``), the headline's
#: band amplitude reads 0.854 (0.833 off) at FD 3.04, beat hit 0.593, jerk 101.4 (3.10, 0.566,
#: 103.2), but the default 3x2 stage's raw jitter passes 1.3 at 4 of seeds 0-7 and its FD at seed 2
#: reads 13.43 against 12.11: not shipped (docs/history.md, "The amplitude gap"). Measure it with
#: ``benchmarks/studies/amp_parts.py --part shipped= --part new=handover.ON_FRAMES=1,stream.BEAT_WARP=0.5``.
ON_FRAMES: bool = False


class Handover:
    """Where the playing exemplar stands in the player's buffer and whether a code step hands
    over (see the module docstring). Rows are of ``Player._played`` (30 fps exemplar
    frames; ``4 seg`` rows: at most ``seg`` rows of the last exemplar before the new window)."""

    def __init__(self, seg: int) -> None:
        self.seg = int(seg)
        self.reset()

    def reset(self) -> None:
        """Nothing played: the first code step hands over at once."""
        self.base = float(self.seg)  # row the current code step's frame 0 reads (before the beat warp's lag)
        self.start = self.seg  # row of the playing exemplar's frame 0
        self.handovers = 0
        self.holds = 0
        self.rows = 0.0  # rows the exemplar last handed over from had played (its exemplar frames)

    def due(self, reached: float, ahead: float, playing: bool) -> int | None:
        """At a code step: ``reached`` the row the last movement has got to, ``ahead`` the exemplar
        rows the coming ``seg`` frames play (about ``seg * rate``), ``playing`` an exemplar plays
        with frames to continue. Returns the rows (0..seg) the playing exemplar still plays before
        the new one starts, or None: hold, it plays its own frames on past the next code step."""
        if not ON_FRAMES or not playing:
            return 0
        left = self.start + self.seg - reached  # rows to its frame seg
        if left <= 0.5:
            return 0
        if left >= ahead:
            return None
        return min(int(round(left)), self.seg)

    def hold(self, advanced: float) -> None:
        """A code step without a handover: the next one reads on from ``advanced`` rows further."""
        self.base += advanced
        self.holds += 1

    def handed(self, lead: int, at: float) -> None:
        """A handover at row ``at`` of the last buffer: the new buffer has ``lead`` rows of the
        last exemplar (``seg`` + the rows :meth:`due` gave) before the new exemplar's frame 0."""
        self.rows = at - self.start
        self.base = float(self.seg)
        self.start = int(lead)
        self.handovers += 1
