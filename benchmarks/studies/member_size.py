"""How big against how quick the memory's exemplars are, and what the tempo's tilt draws (issue 43).

Issue 43 asks the band amplitude at 1.25x over 0.8x within 0.8-1.2: at a faster tempo quicker
movements, not bigger ones. Would the tempo's tilt of the choice find them among the dancers' own?
For every real exemplar window of the shipped memory (16 frames, low-passed as the stream reads it:
``dance_stream._cached_members``), its FK points put in place (the Hips' x, z path removed, as the
band amplitude reads them):

- excursion: RMS over frames, points and axes of the positions less their window mean (m);
- quickness: mean joint acceleration / mean joint speed, root-relative (``code_frequency``'s measure,
  per frame; 2 pi f for a sinusoid);
- size: speed^2 / acceleration, root-relative (m; the amplitude of a sinusoid);
- speed: the stream's own (``MemberTables.speed``: mean joint speed over the movement's 8 frames).

Printed: correlations of their logs over the exemplars, within codes (each code's mean taken out;
a code has up to 3), over codes against the tilt's z (``code_energy`` + ``TEMPO_FREQ`` x
``code_frequency``), quintiles of quickness, and the codes weighted by the tilt alone
(``exp(TEMPO_ENERGY ln(T / T_ref) z)``) at several tempi::

    PYTHONPATH=. .venv/bin/python benchmarks/studies/member_size.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402


def exemplar_measures(members: np.ndarray) -> dict[str, np.ndarray]:
    """(K, M) excursion (m), quickness (1/frame) and size (m) of exemplar windows (K, M, F, P) (module docstring)."""
    from models.networks.member_tables import member_positions

    k, m = members.shape[:2]
    out = {n: np.zeros((k, m)) for n in ("exc", "quick", "size")}
    for a in range(0, k, 64):  # bounded FK memory
        pos = member_positions(members[a: a + 64])
        flat = pos.copy()
        flat[..., [0, 2]] -= pos[..., :1, [0, 2]]
        out["exc"][a: a + 64] = np.sqrt(((flat - flat.mean(2, keepdims=True)) ** 2).sum(-1).mean((-1, -2)))
        rel = pos - pos[..., :1, :]
        v = np.linalg.norm(np.diff(rel, axis=2), axis=-1).mean((-1, -2))
        acc = np.linalg.norm(np.diff(rel, 2, axis=2), axis=-1).mean((-1, -2))
        out["quick"][a: a + 64] = acc / np.maximum(v, 1e-9)
        out["size"][a: a + 64] = v * v / np.maximum(acc, 1e-9)
    return out


def _corr(x: np.ndarray, y: np.ndarray) -> float:
    ok = np.isfinite(x) & np.isfinite(y)
    return float(np.corrcoef(x[ok], y[ok])[0, 1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("::")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default="models/assets/default.pt", help="the checkpoint (default the shipped one)")
    a = p.parse_args(argv)
    import models.networks.chooser as chooser
    import models.networks.dance_stream as ds
    from models.generate import load_model

    model = load_model(Path(a.checkpoint)).model
    members = ds._cached_members(model)
    counts = model.member_count.numpy()
    real = np.arange(members.shape[1])[None, :] < counts[:, None]
    tables = ds._cached_tables(model, members)
    logs = {n: np.log(np.maximum(x, 1e-12)) for n, x in exemplar_measures(members).items()}
    logs["speed"] = np.log(np.maximum(tables.speed, 1e-12))
    exc = np.exp(logs["exc"][real])
    print(f"{int(real.sum())} exemplars of {int((counts > 0).sum())} codes; excursion median {np.median(exc) * 100:.1f} cm "
          f"(10-90 %: {np.percentile(exc, 10) * 100:.1f}-{np.percentile(exc, 90) * 100:.1f})")
    within = {n: np.where(real, x - np.nanmean(np.where(real, x, np.nan), axis=1, keepdims=True), np.nan)[real]
              for n, x in logs.items()}
    for x, y in (("exc", "quick"), ("size", "quick"), ("speed", "exc"), ("speed", "quick")):
        print(f"ln {x} / ln {y}: correlation over exemplars {_corr(logs[x][real], logs[y][real]):+.2f}, "
              f"within codes {_corr(within[x], within[y]):+.2f}")
    for n in ("exc", "quick", "size", "speed"):
        share = np.var(within[n]) * real.sum() / max(real.sum() - (counts > 0).sum(), 1) / np.var(logs[n][real])
        print(f"ln {n}: {share:.0%} of its variance within codes")
    has = counts > 0
    code = {n: (np.where(real, x, 0.0).sum(1) / np.maximum(counts, 1))[has] for n, x in logs.items()}
    z = (tables.energy + np.float32(chooser.TEMPO_FREQ) * tables.frequency)[has]
    print("over codes, the tilt's z against: " + ", ".join(f"ln {n} {_corr(z, code[n]):+.2f}" for n in code))
    q = logs["quick"][real]
    edges = np.quantile(q, np.linspace(0.0, 1.0, 6))
    for i in range(5):
        sel = (q >= edges[i]) & (q <= edges[i + 1])
        print(f"quickness quintile {i + 1}: {np.exp(q[sel]).mean():.3f} a frame, excursion "
              f"{np.exp(logs['exc'][real][sel]).mean() * 100:.2f} cm, speed {np.exp(logs['speed'][real][sel]).mean() * 30:.2f} m/s")
    period = model.member_period.numpy().astype(np.float64)
    t_ref = 1800.0 / float(np.exp(np.log(period[real & (period > 0)]).mean()))  # bpm
    for bpm in (70.0, 90.0, 112.0, 140.0, 162.0):
        g = chooser.TEMPO_ENERGY * np.log(bpm / t_ref) * z
        w = np.exp(g - g.max())
        w /= w.sum()
        print(f"{bpm:.0f} bpm, the codes weighted by the tilt alone: excursion {np.exp((w * code['exc']).sum()) * 100:.2f} cm, "
              f"quickness {np.exp((w * code['quick']).sum()):.3f}, speed {np.exp((w * code['speed']).sum()) * 30:.2f} m/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
