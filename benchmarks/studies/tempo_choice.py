"""Does the choice of movement hear the tempo? (issue 43: a predictor trained with the tempo as an input)

Three readings, each of a code's quickness z (``code_frequency``), liveliness z (``code_energy``: the
tempo tilt's two parts) and its exemplars' mean excursion (cm; ``member_size.exemplar_measures``):

1. ``--targets``: what stage 2 is trained to predict at each tempo factor of the config: the codes of the
   verified training dances, stretched with their music (``training_clips``), at grid phase 0.
2. ``--targets``: which tempo factor each exemplar of the memory was cut from (its window found among the
   training motion at every factor), and their quickness (ln, per frame) and excursion.
3. For each ``--checkpoint``: the codes the stream draws (after the first 3 s) on the listening benchmark's
   stretch set at 0.8x and 1.25x, seeds ``--seeds``, with the tempo's logit tilt off (``TEMPO_ENERGY`` and
   ``TEMPO_ENERGY_HEARD`` 0) and at 4 (as shipped).

Run::

    PYTHONPATH=. .venv/bin/python benchmarks/studies/tempo_choice.py --targets \\
        --checkpoint models/assets/default.pt runs/tempo_predictor.pt
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402


def code_measures(model) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Per code (K,): quickness z, liveliness z, mean excursion of its exemplars (cm); and the exemplars' measures."""
    import models.networks.dance_stream as ds
    from benchmarks.studies.member_size import exemplar_measures

    members = ds._cached_members(model)
    counts = model.member_count.numpy()
    lively, _ = ds._cached_energy(model, members, model.config.seg)
    quick = ds._cached_frequency(model, members)
    meas = exemplar_measures(members)
    real = np.arange(members.shape[1])[None] < counts[:, None]
    return quick, lively, np.nanmean(np.where(real, meas["exc"], np.nan), 1) * 100, meas


def targets(data: Path, cache: str) -> None:
    """Readings 1 and 2 for the shipped checkpoint (the config it was trained with: configs/dance_vq.toml)."""
    from models.generate import load_model
    from models.training.config import TrainConfig
    from models.training.dance_vq import encode_clips, training_clips

    lm = load_model(None)
    m = lm.model
    cfg = TrainConfig.from_toml(REPO / "configs" / "dance_vq.toml")
    train, motion = training_clips(cfg, lm.features, data / "dwm", cache, progress=False)
    quick, lively, exc, meas = code_measures(m)
    for tempo in cfg.tempos:
        got = encode_clips(m, [c for c in train if c.tempo == tempo], range(1))
        c = np.concatenate([cd[v] for cd, v in zip(got.codes, got.valid)])
        print(f"targets at factor {tempo:g}: {len(c)} codes, quickness z {quick[c].mean():+.3f}, "
              f"liveliness z {lively[c].mean():+.3f}, excursion {np.nanmean(exc[c]):.2f} cm")
    mp, counts = m.member_poses.numpy(), m.member_count.numpy()
    key = lambda w: np.round(w[:, :7].astype(np.float16).astype(np.float32), 3).tobytes()  # noqa: E731
    want: dict[bytes, list] = {}
    for k in range(len(mp)):
        for j in range(int(counts[k])):
            want.setdefault(key(mp[k, j]), []).append((k, j))
    found: dict[tuple, set] = {}
    s = m.config.seg
    for clip in motion:
        for p in (0, 4):  # fit_members' phases
            for i in range((clip.num_frames - p) // s - 1):
                for kj in want.get(key(clip.poses[p + i * s: p + (i + 2) * s]), []):
                    found.setdefault(kj, set()).add(clip.tempo)
    print(f"exemplars found in the training motion: {len(found)} of {int(counts.sum())}")
    by = collections.defaultdict(list)
    for kj, ts in found.items():
        if len(ts) == 1:
            by[next(iter(ts))].append(kj)
    for t in sorted(by):
        q = np.log([meas["quick"][kj] for kj in by[t]])
        e = np.array([meas["exc"][kj] for kj in by[t]]) * 100
        print(f"  cut from factor {t:g}: {len(by[t])}, ln quickness {q.mean():+.3f}, excursion {e.mean():.2f} cm")


def choices(path: str | None, data: Path, cache: str, seeds: list[int]) -> None:
    """Reading 3 for the checkpoint at ``path`` (None: the shipped one)."""
    import models.networks.chooser as chooser
    import models.networks.dance_stream as ds
    from models.evaluation import listening as L
    from models.features.spectral import extract_features
    from models.generate import load_model

    lm = load_model(path)
    m = lm.model
    quick, lively, exc, _ = code_measures(m)
    opts = L.Options(dwm=data / "dwm", music=data / "music", progress=False)
    audio = L.AudioCache(cache)
    skip = int(L.SETTLE_S * L.FPS) // m.config.seg
    print(f"{lm.path}: drawn codes' quickness z, liveliness z, excursion (cm), 0.8x -> 1.25x, seeds {seeds}")
    for song, _ in L.stretch_songs(audio, opts):
        start, secs = L._excerpt_window(audio, song, opts)
        got = {}
        for rate in (0.8, 1.25):
            feats = extract_features(audio.excerpt(song, start, secs, rate), lm.features)
            for gain in (0.0, 4.0):
                chooser.TEMPO_ENERGY = chooser.TEMPO_ENERGY_HEARD = gain
                codes = []
                for seed in seeds:
                    s = ds.DanceStream(m, seed=seed)
                    s.push(feats)
                    codes += s.codes_drawn[skip:]
                c = np.array(codes)
                got[rate, gain] = (quick[c].mean(), lively[c].mean(), np.nanmean(exc[c]))
        line = "; ".join(f"tilt {g:g}: " + ", ".join(f"{a:+.2f} -> {b:+.2f}" if i < 2 else f"{a:.1f} -> {b:.1f}"
                                                     for i, (a, b) in enumerate(zip(got[0.8, g], got[1.25, g])))
                         for g in (0.0, 4.0))
        print(f"  {L.song_name(song)}: {line}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("Run::")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=str(REPO.parent / "shared" / "data"), metavar="DIR",
                   help="the shared data (holds dwm/ and music/)")
    p.add_argument("--checkpoint", nargs="*", default=[], metavar="CKPT", help="checkpoints whose choice to read")
    p.add_argument("--targets", action="store_true", help="also readings 1 and 2 (the shipped checkpoint)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="SEED")
    p.add_argument("--cache", default=".cache", metavar="DIR", help="holds corpus/ and listening/ (default .cache)")
    a = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    data = Path(a.data)
    if a.targets:
        targets(data, str(Path(a.cache) / "corpus"))
    for ck in a.checkpoint:
        choices(ck, data, str(Path(a.cache) / "listening"), a.seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
