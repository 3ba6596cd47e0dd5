"""A shipped model's evaluation, recomputed from the audio, equals the numbers stored in the repo.

constraints.txt pins every Python package of ``make setup`` so that a fresh clone's
``performer evaluate`` gives the digits the docs print. This test is the check: it runs the
evaluation of ``models/assets/dtm.pt`` (a shipped checkpoint that no training of the project
replaces) on two validation dances the way ``performer evaluate`` does, features decoded and
computed afresh (no cache), and compares its per-dance metrics with
``tests/data/eval_reference.json``, written from that command's ``per_dance.json``. A
changed numpy, scipy, librosa, soundfile or torch that moves the audio features, the beat
tracking inside ``dtm`` or the metrics fails it; float-order noise does not (see REL).

Update the reference (docs/install.md, "Updating the pins") only for a change that is meant:

    performer evaluate --checkpoint models/assets/dtm.pt ...   # the "command" in the JSON
    python tests/test_eval_reference.py write runs/eval_reference/per_dance.json

How far the metrics move when the features do (what REL can see):

    python tests/test_eval_reference.py perturb --data ../shared/data/dwm 1e-4 1e-3 1e-2

The shipped default (``models/assets/default.pt``) is pinned too, by its headline numbers on
the whole validation split as ``performer evaluate`` prints them: dance-scale amplitude and
jitter ratios, jerk, beat hit rate, FD and the real row's FD (the style classifier itself),
stored in ``tests/data/default_reference.json`` and compared within :data:`HEADLINE_REL`.
After a meant change of the default's playback (e.g. its tempo following) or checkpoint, print
the new values in the file's format (about 30 s of CPU), put them in the docs where the old ones
stand (README, docs/training.md: ``performer evaluate --checkpoint models/assets/default.pt ...``
prints the same digits) and write them:

    python tests/test_eval_reference.py headline --data ../shared/data/dwm           # print
    python tests/test_eval_reference.py headline --data ../shared/data/dwm --write   # rewrite

``--noise`` and ``--threads`` print what feature noise or a second torch thread would move.
"""

from __future__ import annotations

import hashlib
import json
import sys
from importlib import metadata
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REFERENCE = Path(__file__).resolve().parent / "data" / "eval_reference.json"
#: Relative tolerance. Measured (docs/install.md): the metrics are bit-identical with 1 and 2
#: torch threads and within 3e-16 with numpy 2.2.6 / scipy 1.15.3, librosa 0.10.2.post1 or
#: soundfile 0.12.1 instead of the pins, so float-order noise is far below it; `dtm` is
#: insensitive to its features (Gaussian noise of 1e-3 / 1e-2 of each feature column's spread
#: moves the metrics by at most 6e-5 / 6e-4, `perturb` below), so 1e-5 rather than 1e-4.
REL = 1e-5
#: Packages whose versions the reference records (shown when the numbers differ).
PACKAGES = ("numpy", "scipy", "librosa", "soundfile", "audioread", "soxr", "numba", "torch")
DEFAULT_REFERENCE = Path(__file__).resolve().parent / "data" / "default_reference.json"
#: Relative tolerance of the default's pinned headline numbers (HEADLINE). Measured (2026-11-26,
#: this file's ``headline`` command): a rerun, 2 torch threads for the generation, torch's kernels
#: capped at AVX2 or SSE4.1 (ONEDNN_MAX_CPU_ISA, MKL_CBWR, ATEN_CPU_CAPABILITY: an older CPU) and
#: feature noise of 1e-6 of each column's std move them by at most 1.5e-7 relative (beat hit
#: rate not at all), so 1e-5 leaves 60x room. The dance is one sample of its code draws: what
#: flips one draw (feature noise of 1e-4: another dance) moves every number but fd_real by 0.85 %
#: (jerk) to 27 % (FD), as much as a change of the playback does (BEAT_WARP 0: beat hit rate
#: 0.462 -> 0.288; temperature 0.9: jitter 0.925 -> 0.875, FD 12.96 -> 13.92), so a tolerance
#: wide enough for another dance would pass those changes too: the pins hold the same dance.
HEADLINE_REL = 1e-5


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def installed_versions() -> dict[str, str]:
    return {p: metadata.version(p) for p in PACKAGES}


def noisy(features, noise: float):
    """``features`` (T, D) plus seeded Gaussian noise of ``noise`` times each column's std (0: unchanged)."""
    import numpy as np

    if not noise:
        return features
    rng = np.random.default_rng(0)
    return features + (noise * features.std(0) * rng.standard_normal(features.shape)).astype(features.dtype)


def per_dance_metrics(data_root: Path, checkpoint: Path, dances: list[str], max_frames: int,
                      noise: float = 0.0) -> dict[str, dict]:
    """Paired metrics of each dance as ``performer evaluate`` computes them (its defaults:
    causal windows 128/64, 300-frame segments, seed 0 for stochastic models, one torch thread).

    ``noise``: add seeded Gaussian noise of this fraction of each feature column's standard
    deviation to the features first (how sensitive the metrics are; 0 for the check)."""
    import torch

    from models.evaluation.evaluate import EvalOptions, _audio_kw, _quats, load_clips, paired_metrics, positions
    from models.generate import load_model, run_model
    from models.networks.streaming import torch_threads

    opts = EvalOptions(cache_dir=None, max_frames=max_frames, progress=False)
    with torch_threads(1):
        lm = load_model(checkpoint)
        out = {}
        for clip in load_clips(data_root, dances, lm.features, opts):
            clip.features = noisy(clip.features, noise)
            with torch.no_grad():
                poses = run_model(lm.model, clip.features, opts.window, opts.hop, **_audio_kw(lm.model, data_root, clip))
            out[clip.name] = paired_metrics(positions(poses), positions(clip.poses), _quats(poses), _quats(clip.poses),
                                            opts.segment)
    return out


def max_relative_change(expected: dict[str, dict], got: dict[str, dict]) -> float:
    return max(abs(got[d][k] - v) / max(abs(v), 1e-12) for d, m in expected.items() for k, v in m.items())


def differences(expected: dict[str, dict], got: dict[str, dict], rel: float = REL) -> list[str]:
    """One line per metric that is off by more than ``rel`` (relative; 1e-12 absolute near 0)."""
    bad = []
    for dance, metrics in expected.items():
        for key, want in metrics.items():
            have = got.get(dance, {}).get(key)
            if have is None or have != pytest.approx(want, rel=rel, abs=1e-12):
                bad.append(f"{dance} {key}: stored {want!r}, now {have!r}")
    return bad


def test_differences_catch_a_moved_metric() -> None:
    ref = {"D": {"rot_l1": 0.0945, "lcss": 0.0}}
    assert differences(ref, {"D": {"rot_l1": 0.0945 * (1 + 2e-6), "lcss": 0.0}}) == []
    assert differences(ref, {"D": {"rot_l1": 0.0945 * (1 + 3e-5), "lcss": 0.0}}) == [
        f"D rot_l1: stored 0.0945, now {0.0945 * (1 + 3e-5)!r}"]
    assert differences(ref, {"D": {"rot_l1": 0.0945, "lcss": 1 / 600}})  # one LCSS frame more
    assert differences(ref, {"D": {"rot_l1": 0.0945}}) == ["D lcss: stored 0.0, now None"]


def test_reference_file_names_its_command_and_checkpoint() -> None:
    ref = json.loads(REFERENCE.read_text())
    assert ref["command"].startswith(f"performer evaluate --checkpoint {ref['checkpoint']} ")
    assert f"--max-frames {ref['max_frames']} " in ref["command"]
    assert len(ref["per_dance"]) == 2 and all(len(m) == 9 for m in ref["per_dance"].values())
    assert set(ref["versions"]) == set(PACKAGES)


@pytest.mark.slow  # 15-25 s on 2 busy cores (2.5 min on a fresh venv: numba compiles librosa first)
@pytest.mark.data
def test_shipped_model_evaluates_to_the_stored_numbers(dwm_root: Path) -> None:
    ref = json.loads(REFERENCE.read_text())
    checkpoint = REPO / ref["checkpoint"]
    assert sha256(checkpoint) == ref["checkpoint_sha256"], (
        f"{ref['checkpoint']} is not the file the reference was written with; if it was replaced on "
        "purpose, rewrite tests/data/eval_reference.json (docs/install.md, 'Updating the pins')")
    dances = list(ref["per_dance"])
    missing = [d for d in dances if not (dwm_root / d).is_dir()]
    if missing:
        pytest.skip(f"dances {', '.join(missing)} not found under {dwm_root}")
    got = per_dance_metrics(dwm_root, checkpoint, dances, ref["max_frames"])
    bad = differences(ref["per_dance"], got)
    now = installed_versions()
    changed = [f"{p} {ref['versions'][p]} -> {now[p]}" for p in PACKAGES if now[p] != ref["versions"][p]]
    assert not bad, (
        f"{len(bad)} metric(s) of {ref['checkpoint']} moved by more than rel {REL} from "
        f"tests/data/eval_reference.json:\n  " + "\n  ".join(bad)
        + f"\npackages not at the reference's versions: {', '.join(changed) or 'none'} "
        "(make setup installs constraints.txt; docs/install.md)")


HEADLINE = ("band_amp", "jitter", "jerk", "beat_hit_rate", "fd", "fd_real")


def default_headline(data_root: Path, cache_dir: Path | None, noise: float = 0.0, threads: int = 1) -> dict[str, float]:
    """The default's headline numbers on the validation split, as ``performer evaluate
    --checkpoint models/assets/default.pt`` computes them (its defaults: seed 0, one torch
    thread, the packaged style classifier; corpus clips cached under ``cache_dir``), keyed as
    :data:`HEADLINE`. ``noise``: feature noise as in :func:`noisy`; ``threads``: torch threads
    of the generation (both to measure what the pins can see)."""
    import torch

    from models.evaluation.classifier import embed
    from models.evaluation.evaluate import (EvalOptions, classifier_windows, load_clips, positions, real_set,
                                            set_metrics, split_dances, style_classifier)
    from models.evaluation.metrics import frechet_distance
    from models.generate import load_model, run_model
    from models.networks.streaming import torch_threads

    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    lm = load_model(REPO / "models" / "assets" / "default.pt")
    train_names, val_names = split_dances(data_root, opts)
    real = real_set(data_root, load_clips(data_root, val_names, lm.features, opts), progress=False)
    train = real_set(data_root, load_clips(data_root, train_names, lm.features, opts), False, False)
    classifier = style_classifier(train, opts.classifier_epochs, opts.seed, cache_dir)
    real_emb = embed(classifier, classifier_windows(real.positions))
    with torch_threads(threads), torch.no_grad():
        gen = [positions(run_model(lm.model, noisy(c.features, noise))) for c in real.clips]
    row = set_metrics(gen, real, real_emb, classifier)
    row["fd_real"] = frechet_distance(real_emb, embed(classifier, classifier_windows(train.positions)))
    return {k: float(row[k]) for k in HEADLINE}


def headline_differences(expected: dict[str, float], got: dict[str, float], rel: float = HEADLINE_REL) -> list[str]:
    """One line per headline number further than ``rel`` (relative) from the pinned one."""
    return [f"{k}: pinned {expected[k]!r}, now {got[k]!r}"
            for k in HEADLINE if got[k] != pytest.approx(expected[k], rel=rel, abs=1e-12)]


def test_headline_differences_catch_a_moved_number() -> None:
    ref = json.loads(DEFAULT_REFERENCE.read_text())["headline"]
    assert set(ref) == set(HEADLINE)
    assert headline_differences(ref, dict(ref)) == []
    for k in HEADLINE:
        near = {**ref, k: ref[k] * (1 + 0.5 * HEADLINE_REL)}
        far = {**ref, k: ref[k] * (1 - 2 * HEADLINE_REL)}
        assert headline_differences(ref, near) == [] and len(headline_differences(ref, far)) == 1, k


@pytest.mark.slow  # 55-60 s on 2 busy cores, about 25 s of CPU, corpus cached (a fresh clone builds it first)
@pytest.mark.data
def test_shipped_default_keeps_its_headline_numbers(dwm_root: Path) -> None:
    ref = json.loads(DEFAULT_REFERENCE.read_text())
    assert sha256(REPO / "models" / "assets" / "default.pt") == ref["checkpoint_sha256"], (
        "models/assets/default.pt is not the file tests/data/default_reference.json was written with; if it "
        "was replaced on purpose: python tests/test_eval_reference.py headline --data DWM --write")
    got = default_headline(dwm_root, REPO / ".cache" / "corpus")
    bad = headline_differences(ref["headline"], got)
    assert not bad, ("the default's headline numbers on the validation split moved (a meant change: "
                     "python tests/test_eval_reference.py headline --data DWM --write, and the docs' figures):\n  "
                     + "\n  ".join(bad))


def write_reference(per_dance_json: Path) -> None:
    """Rewrite the reference's numbers from a ``performer evaluate`` run of its command."""
    ref = json.loads(REFERENCE.read_text())
    details = json.loads(per_dance_json.read_text())
    run = details["_run"]
    assert run["options"]["max_frames"] == ref["max_frames"], "run the reference's command"
    (row,) = [v for k, v in details.items() if k != "_run" and v.get("checkpoint", "").endswith(ref["checkpoint"])]
    ref["per_dance"] = {d: row["per_dance"][d] for d in ref["per_dance"]}
    ref["checkpoint_sha256"] = sha256(REPO / ref["checkpoint"])
    ref["versions"] = installed_versions()
    REFERENCE.write_text(json.dumps(ref, indent=1) + "\n")
    print(f"wrote {REFERENCE}")


def perturb(data_root: Path, scales: list[float]) -> None:
    """Print how far the reference's metrics move under feature noise of each scale."""
    ref = json.loads(REFERENCE.read_text())
    args = (data_root, REPO / ref["checkpoint"], list(ref["per_dance"]), ref["max_frames"])
    base = per_dance_metrics(*args)
    print(f"unperturbed: max relative change {max_relative_change(ref['per_dance'], base):.1e} from the reference")
    for scale in scales:
        got = per_dance_metrics(*args, noise=scale)
        print(f"noise {scale:g} x column std: max relative change {max_relative_change(base, got):.1e}")


if __name__ == "__main__":
    import argparse

    sys.path.insert(0, str(REPO))
    parser = argparse.ArgumentParser(description="Rewrite tests/data/eval_reference.json, or measure what it can see.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("write", help="take the numbers from a run of the reference's command")
    w.add_argument("per_dance", type=Path, help="per_dance.json of that run")
    p = sub.add_parser("perturb", help="how far the metrics move with noise on the features")
    p.add_argument("--data", type=Path, required=True, help="the DWM dataset directory")
    p.add_argument("scales", type=float, nargs="+", help="noise, as a fraction of each feature column's std")
    h = sub.add_parser("headline", help="print the default's headline numbers in default_reference.json's format")
    h.add_argument("--data", type=Path, required=True, help="the DWM dataset directory")
    h.add_argument("--cache", type=Path, default=REPO / ".cache" / "corpus", help="corpus and classifier cache")
    h.add_argument("--noise", type=float, default=0.0, help="feature noise (fraction of each column's std)")
    h.add_argument("--threads", type=int, default=1, help="torch threads of the generation")
    h.add_argument("--write", action="store_true", help="rewrite tests/data/default_reference.json with them")
    a = parser.parse_args()
    if a.cmd == "headline" and a.write and (a.noise or a.threads != 1):
        parser.error("--write takes the unperturbed numbers: leave out --noise and --threads")
    if a.cmd == "write":
        write_reference(a.per_dance)
    elif a.cmd == "perturb":
        perturb(a.data, a.scales)
    else:
        values = default_headline(a.data, a.cache, a.noise, a.threads)
        out = {"checkpoint": "models/assets/default.pt",
               "checkpoint_sha256": sha256(REPO / "models" / "assets" / "default.pt"),
               "command": "python tests/test_eval_reference.py headline --data ../shared/data/dwm --write",
               "versions": installed_versions(), "headline": values}
        text = json.dumps(out, indent=1) + "\n"
        print(text, end="")
        if a.write:
            DEFAULT_REFERENCE.write_text(text)
            print(f"wrote {DEFAULT_REFERENCE}")
