"""Where the performer's jitter between a song's ends comes from: each part of the stream switched off (issue 39).

The validation dances, the shipped checkpoint's live stream (seeds ``--seeds``) on each of
``--stages`` (0 = in place), against the dancers in place, as ``jitter_wrap.py`` reads them
(its ``interior``: the jitter band's energy, above 6 Hz, with the first and last ``--ends`` s of
every song left out, the FFT over the whole song). For every seed and stage the variants run one
after the other in the same process (same load), each a set of constants (``--part NAME=SETS``,
SETS ``part.CONST=VALUE`` joined by ``,``; part ``stream`` (models/networks/dance_stream.py and its
parts chooser.py and player.py, wherever the constant lives), ``stage``, ``feet``, ``tables``
(member_tables.py) or ``handover``; ``nofeet`` as a SET: the feet step off). Default parts:

- ``shipped``: as shipped;
- ``warp``: the beat warp off (``BEAT_WARP=0``);
- ``tempo``: every movement at its own pace and chosen regardless of the tempo (``FOLLOW_TEMPO=0``);
- ``tilt``: the tempo's tilt of the choice off, the rate still following (``TEMPO_ENERGY=0``);
- ``match``: speed matching off (``SPEED_MATCH=0``);
- ``carry``: the inertialization carries no velocity (``VEL_CAP=0``);
- ``feet``: the feet step off.

Printed per run: ``raw`` (the headline's jitter ratio), ``interior``, ``hands`` / ``feet`` (the
interior ratio of those points alone, jitter_wrap's groups), ``amp`` (0.25-3 Hz band amplitude),
``jerk`` (ratio, travel included), ``hann`` (the jitter ratio without the wrap: each song
Hann-windowed before its FFT, :func:`hann_energy`), and where the hands' interior energy lies: ``hand/o`` the
share within one frame of a handover (3 of every 8 frames), ``clamp`` the share of the frames
whose beat-warp lag sits at a bound (0 or 2 ``WARP_LAG``: its read-out speed jumps there) and
the share of the hands' energy within 2 frames of such a frame. ``--songs``: per song too, the
hands' interior RMS above 6 Hz (mm, summed over the hand points) against the dancer's, its share of
the run's hand energy, and the mean tempo z (``Chooser.tempo_z``) of the codes drawn, above each run's row;
then by the drawn code's tempo z (:func:`by_z`) the movements' share and their share of the hands' energy.
``--fd`` (in place only): ``performer evaluate``'s FD and beat hit rate too. A SET ``tail=Z:SIGMA`` plays
the exemplars of the codes whose tempo z is above Z low-passed by a further Gaussian of SIGMA frames,
``lowpass=Z:HZ`` by a zero-phase Butterworth at HZ (:func:`lowpass_windows`; Z -99: every code); the
draw reads the tables as shipped::

    .venv/bin/python benchmarks/studies/jitter_parts.py --data ../shared/data/dwm --seeds 0 1 2 3

Exit status 2 on a missing or unreadable checkpoint or dataset.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))
if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

DEFAULT_PARTS = ("shipped=", "warp=stream.BEAT_WARP=0", "tempo=stream.FOLLOW_TEMPO=0", "tilt=stream.TEMPO_ENERGY=0",
                 "match=stream.SPEED_MATCH=0", "carry=stream.VEL_CAP=0", "feet=nofeet")


def parse_part(text: str) -> tuple[str, list[tuple[str, str, str]], bool, tuple[float, float] | None]:
    """``NAME=part.CONST=V,...`` -> (name, [(part, const, value)], feet on, (tail z, sigma) or None);
    ValueError on a bad one."""
    name, _, sets = text.partition("=")
    if not name:
        raise ValueError(f"--part wants NAME=part.CONST=VALUE,..., got {text!r}")
    out, feet_on, tail = [], True, None
    for item in filter(None, sets.split(",")):
        if item == "nofeet":
            feet_on = False
            continue
        key, _, value = item.partition("=")
        if key in ("tail", "lowpass"):  # tail=Z:SIGMA, lowpass=Z:HZ
            try:
                z, sigma = (float(v) for v in value.split(":"))
            except ValueError:
                raise ValueError(f"--part {name}: {key} wants Z:{'SIGMA' if key == 'tail' else 'HZ'}, got {value!r}") from None
            tail = (z, sigma, key)
            continue
        part, _, const = key.partition(".")
        mod = _module(part, const)
        if mod is None or not const.isupper() or not hasattr(mod, const) or not value:
            raise ValueError(f"--part {name}: wants stream.|stage.|feet.|tables.|handover.CONST=VALUE of an existing "
                             f"constant, got {item!r}")
        out.append((part, const, value))
    return name, out, feet_on, tail


def lowpass_windows(windows: np.ndarray, hz: float) -> np.ndarray:
    """Exemplar windows (N, F, P: root position m, then unit quaternions) at 30 fps low-passed
    along F at ``hz`` (zero-phase: 4th-order Butterworth forwards and back, odd extension at the
    ends), the quaternions renormalised; float32."""
    from scipy.signal import butter, filtfilt

    b, a = butter(4, hz / 15.0)
    x = filtfilt(b, a, windows.astype(np.float64), axis=1, padtype="odd", padlen=min(windows.shape[1] - 1, 15))
    q = x[..., 3:].reshape(*x.shape[:2], -1, 4)
    x[..., 3:] = (q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-9)).reshape(*x.shape[:2], -1)
    return x.astype(np.float32)


def _module(part: str, const: str):
    """The module a ``part.CONST`` names (``stream``: dance_stream.py, chooser.py or player.py, the one
    holding CONST); None for an unknown part."""
    from models.networks import chooser, dance_stream, feet, handover, member_tables, player, stage

    if part == "stream":
        return next((m for m in (dance_stream, chooser, player) if hasattr(m, const)), dance_stream)
    return {"feet": feet, "stage": stage, "tables": member_tables, "handover": handover}.get(part)


def _apply(sets: list[tuple[str, str, str]]) -> dict:
    """Set the constants; returns what to restore."""
    old = {}
    for part, const, value in sets:
        mod = _module(part, const)
        was = getattr(mod, const)
        old[(part, const)] = was
        if isinstance(was, bool):
            setattr(mod, const, value.lower() in ("1", "true"))
        elif isinstance(was, tuple):
            setattr(mod, const, tuple(float(v) for v in value.split(":")))
        else:
            setattr(mod, const, type(was)(float(value)))
    return old


def _restore(old: dict) -> None:
    for (part, const), was in old.items():
        setattr(_module(part, const), const, was)


def hann_energy(pos: dict[str, np.ndarray], band: tuple[float, float], fps: float = 30.0) -> tuple[float, int]:
    """(band energy, values) of every song's positions (T, J, 3) m, each minus its mean and
    Hann-windowed before its FFT (so no step from its last frame back to its first), the energy
    divided by the window's mean square (what the window took away from a steady signal)."""
    from models.evaluation.metrics import _band_energy

    e, n = 0.0, 0
    for p in pos.values():
        w = np.hanning(len(p))
        e += _band_energy((p - p.mean(axis=0)) * w[:, None, None], band, fps) / float((w * w).mean())
        n += p.size
    return e, n


def run(data_root: str, checkpoint: str, seeds: list[int], stages: list[str], ends_s: float,
        parts: list[tuple], cache: str, songs: bool = False, fd: bool = False) -> None:
    """Print the table (see the module docstring)."""
    import torch

    from models.evaluation.evaluate import positions
    from models.evaluation.metrics import JITTER_BAND, band_ratios, in_place, jerk
    from models.networks import dance_stream, player
    from models.rig.skeleton import POINT_INDEX

    from jitter_wrap import FEET, HANDS, style_judge, summary, validation_clips

    from scipy.ndimage import gaussian_filter1d

    tails: dict = {}  # (z, sigma) -> the memory with those codes' exemplars low-passed further

    class Probe(dance_stream.DanceStream):
        """The stream, noting each frame whether the beat warp's lag sits at a bound; with ``tail``
        (z, sigma) the exemplars of the codes whose tempo z is above z low-passed by a further
        Gaussian of sigma frames (the draw, read from the shipped tables, unchanged)."""

        def __init__(self, *args, tail: tuple[float, float] | None = None, **kw) -> None:
            super().__init__(*args, **kw)
            if tail is not None:
                if tail not in tails:
                    mem = self._chooser.members.copy()
                    for c in np.where((self._chooser.tempo_z > tail[0]) & (self._counts > 0))[0]:
                        n = int(self._counts[c])
                        if tail[2] == "lowpass":  # zero-phase Butterworth
                            mem[c, :n] = lowpass_windows(mem[c, :n], tail[1])
                            continue
                        mem[c, :n] = dance_stream._unit(gaussian_filter1d(mem[c, :n], tail[1], axis=1,
                                                                          mode="nearest").astype(np.float32))
                    tails[tail] = mem
                self._chooser.members = tails[tail]

        def reset(self) -> None:
            super().reset()
            self.clamped: list[bool] = []
            pl = self._player
            warped = type(pl).warped.__get__(pl)

            def noted(j: int, row: np.ndarray, tempo) -> np.ndarray:  # the player's read-out, noted
                out = warped(j, row, tempo)
                self.clamped.append(pl._lag <= 0.0 or pl._lag >= 2.0 * player.WARP_LAG)
                return out

            pl.warped = noted

    lm, clips = validation_clips(data_root, checkpoint, cache)
    if fd:  # performer evaluate's FD and beat hit (in place), its style classifier
        from models.evaluation.evaluate import set_metrics

        val, classifier, real_emb = style_judge(data_root, lm, clips, cache)
    cut = int(round(ends_s * 30))
    real = {c.name: in_place(positions(c.poses)) for c in clips}
    rs = summary(real, cut)
    rh, rn = hann_energy(real, JITTER_BAND)
    hands = [POINT_INDEX[n] for n in HANDS]
    feet_ix = [POINT_INDEX[n] for n in FEET]
    print(f"{'stage':<6} {'seed':>4} {'part':<10} {'raw':>6} {'interior':>8} {'hands':>6} {'feet':>6} {'amp':>6} "
          f"{'jerk':>6} {'hann':>6} {'hand/o':>7} {'clamp':>6} {'near':>6}" + ("     FD   beat" if fd else ""), flush=True)
    for stage in stages:
        for seed in seeds:
            for name, sets, feet_on, tail in parts:
                old = _apply(sets)
                try:
                    kw = {} if stage in ("0", "") else {"stage": stage}
                    pos, world, clamp, drawn, zs = {}, [], {}, {}, {}
                    for c in clips:
                        s = Probe(lm.model, seed=seed, feet=feet_on, tail=tail, **kw)
                        with torch.no_grad():
                            poses = s.push(c.features)
                        world.append(positions(poses))
                        pos[c.name] = in_place(world[-1])
                        clamp[c.name] = np.array(s.clamped)
                        zs[c.name] = s._chooser.tempo_z[np.array(s.codes_drawn)]  # movement i: frames 8i .. 8i + 7
                        drawn[c.name] = float(zs[c.name].mean())
                finally:
                    _restore(old)
                gs = summary(pos, cut)
                gh, gn = hann_energy(pos, JITTER_BAND)
                bands = band_ratios(list(pos.values()), list(real.values()), root=None)
                inner = np.sqrt((gs["inner"] / gs["n_inner"]) / (rs["inner"] / rs["n_inner"]))
                part = {g: np.sqrt(gs["inner_j"][ix].sum() / rs["inner_j"][ix].sum())
                        for g, ix in (("hands", hands), ("feet", feet_ix))}
                e_h = e_ho = e_near = 0.0
                n_cl = n_all = 0
                for cname, e in gs["frames"].items():
                    he = e[:, hands].sum(axis=1)[cut:-cut]
                    t = np.arange(cut, len(e) - cut)
                    ho = np.isin(t % 8, (7, 0, 1))
                    cl = clamp[cname][cut:-cut]
                    near = np.convolve(cl.astype(float), np.ones(5), mode="same") > 0
                    e_h += he.sum()
                    e_ho += he[ho].sum()
                    e_near += he[near].sum()
                    n_cl += cl.sum()
                    n_all += len(cl)
                extra = ""
                if fd:
                    row = set_metrics(world, val, real_emb, classifier)
                    extra = f" {row['fd']:>6.2f} {row['beat_hit_rate']:>6.3f}"
                if songs:  # per song: the hands' interior RMS above 6 Hz (mm, over the hand points), the drawn z
                    for cname, e in gs["frames"].items():
                        he = e[cut:-cut, hands].sum(axis=1).mean()
                        hr = rs["frames"][cname][cut:-cut, hands].sum(axis=1).mean()
                        print(f"  {cname:<11} hands {np.sqrt(he) * 1000:6.2f} mm (dancer {np.sqrt(hr) * 1000:6.2f}), "
                              f"{he * (len(e) - 2 * cut) / e_h:6.1%} of the run's hand energy; drawn codes' "
                              f"tempo z {drawn[cname]:+.2f}")
                    by_z(gs["frames"], zs, hands, cut, s.seg)
                print(f"{stage:<6} {seed:>4} {name:<10} {bands['jitter']:>6.3f} {inner:>8.3f} {part['hands']:>6.2f} "
                      f"{part['feet']:>6.2f} {bands['band_amp']:>6.3f} {jerk(world) / jerk(list(real.values())):>6.3f} "
                      f"{np.sqrt((gh / gn) / (rh / rn)):>6.3f} {e_ho / e_h:>7.1%} {n_cl / n_all:>6.1%} {e_near / e_h:>6.1%}" + extra, flush=True)


def by_z(frames: dict[str, np.ndarray], zs: dict[str, np.ndarray], hands: list[int], cut: int, seg: int) -> None:
    """Print, for the movements whose drawn code's tempo z lies in each of (-inf, 1], (1, 2], (2, 3],
    (3, inf), their share of the interior movements, of the hands' interior energy above 6 Hz,
    and their energy per movement against the calmest bin's (``frames``: per song (T, J) band
    energy per frame and point; ``zs``: per song the drawn codes' tempo z, movement i on frames seg i ..)."""
    edges = (1.0, 2.0, 3.0)
    n, e = np.zeros(4), np.zeros(4)
    for name, f in frames.items():
        he = f[:, hands].sum(axis=1)
        for i, z in enumerate(zs[name]):
            a = seg * i
            if cut <= a and a + seg <= len(he) - cut:
                b = int(np.searchsorted(edges, z))
                n[b] += 1
                e[b] += he[a: a + seg].sum()
    per = e / np.maximum(n, 1)
    print("  tempo z " + ", ".join(f"{lab}: {n[b] / n.sum():.0%} of the movements, {e[b] / e.sum():.0%} of the "
                                   f"hands' energy, {per[b] / max(per[0], 1e-30):.1f}x" for b, lab in
                                   enumerate(("<= 1", "1-2", "2-3", "> 3"))))


def main(argv: list[str] | None = None) -> int:
    from foot_skating import study_parser

    p = study_parser(__doc__)
    p.add_argument("--seeds", type=int, nargs="+", default=[0], metavar="N", help="the stream's seeds (default 0)")
    p.add_argument("--stages", nargs="+", default=["0", "3x2"], metavar="WxD",
                   help="stages to dance on, 0 = in place (default: 0 3x2)")
    p.add_argument("--ends", type=float, default=0.5, metavar="S",
                   help="seconds at each end of a song left out (default 0.5)")
    p.add_argument("--fd", action="store_true",
                   help="also performer evaluate's FD and beat hit rate (with --stages 0; trains or loads its style classifier)")
    p.add_argument("--songs", action="store_true",
                   help="also per song: the hands' interior RMS against the dancer's, and the drawn codes' mean tempo z")
    p.add_argument("--part", action="append", default=None, metavar="NAME=SETS",
                   help="a variant: NAME=stream.CONST=V,feet.CONST=V,nofeet (repeatable; default: "
                        + " ".join(DEFAULT_PARTS) + ")")
    a = p.parse_args(argv)
    if a.ends <= 0 or a.ends > 10:
        p.error(f"--ends must be in (0, 10] seconds, got {a.ends:g}")
    if a.set:
        p.error("--set: use --part NAME=feet.CONST=VALUE here")
    try:
        parts = [parse_part(t) for t in (a.part or DEFAULT_PARTS)]
    except ValueError as e:
        p.error(str(e))
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    try:
        if a.fd and any(st not in ("0", "") for st in a.stages):
            p.error("--fd scores the dance in place, as performer evaluate does: give --stages 0")
        run(a.data, a.checkpoint, a.seeds, a.stages, a.ends, parts, a.cache, a.songs, a.fd)
    except (PerformerError, OSError) as e:
        print(f"jitter_parts.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
