"""Why the performer's dance-scale motion is smaller than the dancers' (issue 39: band amplitude 0.85-1.15).

The validation dances, the shipped checkpoint's live stream (seeds ``--seeds``, on each of
``--stages``, 0 = in place) against the dancers in place, as ``performer evaluate`` reads them
(:func:`models.evaluation.metrics.band_ratios`: each song's own FFT, energies pooled over songs).
For every seed and stage the variants (``--part NAME=SETS``, SETS ``stream.CONST=VALUE`` of
models/networks/dance_stream.py joined by ``,``, as ``jitter_parts.py`` takes them; ``chord``
as a SET: the speed matching reads each window's net displacement over the frames it plays, its
chord, instead of its path) run one after the other in the same process (same load). Printed per run:

- ``amp``: the headline's band amplitude (0.25-3 Hz), then the same ratio in the sub-bands
  ``<.25`` (drift), ``.25-.5``, ``.5-1``, ``1-2``, ``2-3``, ``3-6`` (the handovers come every
  8 frames: 3.75 Hz) and ``6-15`` Hz (the jitter band);
- ``x y z``: the dance band's ratio per axis (y up, z the audience's direction);
- ``idle``: the share of frames the idle gate holds the performer at least half idle, and
  ``dancing``: the band amplitude with each song's start-up (until the gate first lets the
  performer dance fully) left out of both the performer and the dancer;
- ``f``: the speed matching's factor ``v_own / v_bent`` (``SPEED_MATCH``), median over the
  handovers, and ``rate``: the geometric mean playback rate the tempo asks, then the one played
  after the matching.

``--songs``: per song the band amplitude and the sub-bands; ``--points``: per point of the
skeleton the dance band's ratio and its share of the dancers' energy::

    .venv/bin/python benchmarks/studies/amp_parts.py --data ../shared/data/dwm --seeds 0 \\
        --part shipped= --part match=stream.SPEED_MATCH=0 --part decay24=stream.DECAY_FRAMES=24

Exit status 2 on a missing or unreadable checkpoint or dataset.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [p for p in (str(HERE.parents[1]), str(HERE)) if p not in sys.path]  # the repo and the studies

import numpy as np  # noqa: E402

#: Sub-bands, Hz (both edges included, as band_ratios takes its bands).
BANDS: tuple[tuple[float, float], ...] = ((0.0, 0.25), (0.25, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 6.0),
                                          (6.0, 15.0))
DEFAULT_PARTS = ("shipped=", "match=stream.SPEED_MATCH=0", "carry=stream.VEL_CAP=0", "decay24=stream.DECAY_FRAMES=24")


def run(data_root: str, checkpoint: str, seeds: list[int], stages: list[str], parts: list[tuple], cache: str,
        songs: bool, points: bool) -> None:
    """Print the table (see the module docstring)."""
    import math

    import torch

    from models.evaluation.evaluate import positions
    from models.evaluation.metrics import DANCE_BAND, FPS, band_energy_points, in_place
    from models.networks import dance_stream, player
    from models.networks.dance_jit import joint_speed
    from models.rig.skeleton import POINT_INDEX

    from jitter_parts import _apply, _restore
    from jitter_wrap import validation_clips

    class Probe(dance_stream.DanceStream):
        """The stream, noting each handover's speed-matching factor and rates and each frame's idle
        weight; ``chord``: the matching reads the net displacement of the frames it plays."""

        chord = False

        def reset(self) -> None:
            super().reset()
            self.log: list[tuple[float, float, float]] = []  # (v_own / v_bent, rate asked, rate played)
            self.idle: list[float] = []
            step = type(self._idle).step.__get__(self._idle)  # the gate's own, however often reset

            def noted(row):
                w = step(row)
                self.idle.append(float(w))
                return w

            self._idle.step = noted
            self._player.speed_matched = self._speed_matched  # the player's, noted (models/networks/player.py)

        def _speed_matched(self, own: np.ndarray, bent: np.ndarray, rate: float) -> float:
            pl = self._player
            if player.SPEED_MATCH <= 0.0:  # the matching off: no handover is matched (nor noted)
                return rate
            n = min(len(bent), int(math.ceil(self.seg * rate)) + 1)
            if self.chord:
                ends = [0, n - 1]
                own, bent, n = np.ascontiguousarray(own[ends]), np.ascontiguousarray(bent[ends]), 2
                v_own = joint_speed(own, n, pl._fk_parents, pl._fk_offsets)
                v_bent = joint_speed(bent, n, pl._fk_parents, pl._fk_offsets)
                lo, hi = player.SPEED_MATCH_RANGE
                f = min(max((v_own / v_bent) ** player.SPEED_MATCH, lo), hi) if v_own > 0 and v_bent > 0 else 1.0
                out = min(max(rate * f, player.RATE_RANGE[0]), player.RATE_RANGE[1])
            else:
                out = type(pl).speed_matched(pl, own, bent, rate)
                v_own = joint_speed(own, n, pl._fk_parents, pl._fk_offsets)
                v_bent = joint_speed(bent, n, pl._fk_parents, pl._fk_offsets)
            self.log.append((v_own / v_bent if v_bent > 0 else 1.0, rate, out))
            return out

    lm, clips = validation_clips(data_root, checkpoint, cache)
    real = {c.name: in_place(positions(c.poses)) for c in clips}
    r_band = {c: {b: band_energy_points(p, b, FPS) for b in (DANCE_BAND,) + BANDS} for c, p in real.items()}
    names = {i: n for n, i in POINT_INDEX.items()}

    def ratio(gen: dict, keys, band, sl=np.s_[...]) -> float:
        return math.sqrt(sum(gen[k][band][sl].sum() for k in keys) / sum(r_band[k][band][sl].sum() for k in keys))

    head = " ".join(f"{lo:g}-{hi:g}".replace("0.", ".") for lo, hi in BANDS)
    print(f"{'stage':<6} {'seed':>4} {'part':<9} {'amp':>6} | {head} | {'x':>5} {'y':>5} {'z':>5} | "
          f"{'idle':>5} {'dancing':>7} | {'f':>5} {'rate':>11}", flush=True)
    for stage in stages:
        for seed in seeds:
            for name, sets, feet_on, _ in parts:
                old = _apply([s for s in sets if s[1] != "CHORD"])
                Probe.chord = any(s[1] == "CHORD" for s in sets)
                try:
                    kw = {} if stage in ("0", "") else {"stage": stage}
                    gen, logs, idle, dancing = {}, [], [], [0.0, 0.0]
                    for c in clips:
                        s = Probe(lm.model, seed=seed, feet=feet_on, **kw)
                        with torch.no_grad():
                            pos = in_place(positions(s.push(c.features)))
                        gen[c.name] = {b: band_energy_points(pos, b, FPS) for b in (DANCE_BAND,) + BANDS}
                        logs += s.log
                        w = np.array(s.idle)
                        idle.append(w > 0.5)
                        cut = int(np.argmax(w <= 0.0)) if (w <= 0.0).any() else 0
                        dancing[0] += band_energy_points(pos[cut:], DANCE_BAND, FPS).sum()
                        dancing[1] += band_energy_points(real[c.name][cut:], DANCE_BAND, FPS).sum()
                finally:
                    _restore(old)
                keys = list(gen)
                lg = np.array(logs)
                sub = " ".join(f"{ratio(gen, keys, b):.3f}" for b in BANDS)
                axes = " ".join(f"{ratio(gen, keys, DANCE_BAND, np.s_[:, a]):5.3f}" for a in range(3))
                print(f"{stage:<6} {seed:>4} {name:<9} {ratio(gen, keys, DANCE_BAND):6.3f} | {sub} | {axes} | "
                      f"{np.concatenate(idle).mean():5.1%} {math.sqrt(dancing[0] / dancing[1]):7.3f} | "
                      + (f"{np.median(lg[:, 0]):5.3f} {math.exp(np.log(lg[:, 1]).mean()):5.3f}>"
                         f"{math.exp(np.log(lg[:, 2]).mean()):5.3f}" if len(lg) else "  (no matching)"), flush=True)
                if songs:
                    for k in keys:
                        print(f"    {k:<11} {ratio(gen, [k], DANCE_BAND):6.3f} | "
                              + " ".join(f"{ratio(gen, [k], b):.3f}" for b in BANDS))
                if points:
                    eg = sum(gen[k][DANCE_BAND] for k in keys).sum(axis=1)
                    er = sum(r_band[k][DANCE_BAND] for k in keys).sum(axis=1)
                    for j in np.argsort(-er):
                        if er[j] / er.sum() >= 0.01:
                            print(f"    {names[j]:<14} {math.sqrt(eg[j] / er[j]):6.3f} ({er[j] / er.sum():5.1%} of the dancers')")


def main(argv: list[str] | None = None) -> int:
    from foot_skating import study_parser
    from jitter_parts import parse_part

    p = study_parser(__doc__)
    p.add_argument("--seeds", type=int, nargs="+", default=[0], metavar="N", help="the stream's seeds (default 0)")
    p.add_argument("--stages", nargs="+", default=["0"], metavar="WxD",
                   help="stages to dance on, 0 = in place (default: 0)")
    p.add_argument("--songs", action="store_true", help="also per song: the band amplitude and its sub-bands")
    p.add_argument("--points", action="store_true",
                   help="also per point: the dance band's ratio (points with 1 %% or more of the dancers' energy)")
    p.add_argument("--part", action="append", default=None, metavar="NAME=SETS",
                   help="a variant: NAME=stream.CONST=V,...,chord (repeatable; default: " + " ".join(DEFAULT_PARTS) + ")")
    a = p.parse_args(argv)
    if a.set:
        p.error("--set: use --part NAME=stream.CONST=VALUE here")
    try:
        parts = []
        for text in a.part or DEFAULT_PARTS:
            chord = text.endswith(",chord") or text.endswith("=chord")
            name, sets, feet_on, tail = parse_part(text.replace(",chord", "").replace("=chord", "="))
            if tail is not None:
                raise ValueError(f"--part {name}: tail/lowpass are jitter_parts.py's")
            parts.append((name, sets + ([("stream", "CHORD", "1")] if chord else []), feet_on, None))
    except ValueError as e:
        p.error(str(e))
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    try:
        run(a.data, a.checkpoint, a.seeds, a.stages, parts, a.cache, a.songs, a.points)
    except (PerformerError, OSError) as e:
        print(f"amp_parts.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
