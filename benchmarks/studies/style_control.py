"""Style control, measured (issue 18, target 8): does ``--style`` make the performer dance that style?

For every validation dance (``models.data.split``, the split ``performer evaluate``
uses), the checkpoint generates the whole tempo-1 corpus clip from the song's features
(``models.generate.run_model``, as ``performer generate`` runs it) once per style: auto
(None: the music decides), "chacha", "rumba" and "waltz". Each generated dance is cut
into the style classifier's 64-frame windows (hop 32) and classified by the evaluation's
style classifier (``models.evaluation.evaluate.style_classifier``: trained on the
TRAINING dances' real motion, the judge behind FD and GAN-test, cached under
``--cache`` and shared with ``performer evaluate``). Printed per song:

* for each requested style, the share of windows the classifier assigns to that style,
  and in brackets its margin over the most frequent other style (positive: it wins);
* for auto, the share assigned to the song's own style (the style the music suggests);
* for the real dancer, the same share on the real motion (the classifier's ceiling on
  this song).

A style is "controlled" on a song when its share beats every other style's by at least
``--margin`` (default 0.2); the summary line counts the songs. ``--json`` writes every
song's full class shares::

    .venv/bin/python benchmarks/studies/style_control.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --json runs/style_control.json

``--seed 0 1 2 3 4`` prints one summary per seed and their pool (every song-seed a row);
``--styles chacha rumba`` requests only those styles; ``--guidance G`` sets
``STYLE_GUIDANCE`` (models/networks/dance_stream.py) for the run, ``--guidance 1``
switching the classifier-free guidance off.

Exit status 2 on a missing or unreadable checkpoint or dataset, or a checkpoint whose
model takes no style.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Requested styles, in table order (None = auto).
REQUESTS: tuple[str | None, ...] = (None, "chacha", "rumba", "waltz")


def style_letter(style: str) -> str:
    """Dataset style letter (the classifier's class name) of a style name: "waltz" -> "W"."""
    from models.networks.dance_vq import STYLE_TOKEN

    token = STYLE_TOKEN[style]
    return next(k for k, v in STYLE_TOKEN.items() if len(k) == 1 and v == token)


def window_shares(classifier, pos: np.ndarray) -> dict[str, float]:
    """Share of the classifier windows of one FK sequence ``(T, 30, 3)`` assigned to each
    class, by class name (e.g. ``{"C": 0.1, "R": 0.2, "W": 0.7}``); DataError if shorter
    than one window."""
    from models.errors import DataError
    from models.evaluation.classifier import predict
    from models.evaluation.evaluate import classifier_windows

    x = classifier_windows([pos])
    if len(x) == 0:
        raise DataError(f"{len(pos)} frames: shorter than one style-classifier window")
    pred = predict(classifier, x)
    return {name: float(np.mean(pred == i)) for i, name in enumerate(classifier.class_names)}


def margin(shares: dict[str, float], cls: str) -> float:
    """``shares[cls]`` minus the largest share of any other class (> 0: ``cls`` wins)."""
    return shares[cls] - max(v for k, v in shares.items() if k != cls)


def measure(classifier, songs: Sequence[tuple[str, str, np.ndarray]],
            generate: Callable[[str, str | None], np.ndarray],
            requests: Sequence[str | None] = REQUESTS) -> dict[str, dict]:
    """``{song: {"style": letter, "real": shares, "auto"|style: shares}}``.

    ``songs``: (name, true style letter, real FK positions); ``generate(name, style)``
    returns FK positions of the model's dance for that song and requested style
    (None = auto). Shares: :func:`window_shares`.
    """
    out: dict[str, dict] = {}
    for name, letter, real_pos in songs:
        row: dict = {"style": letter, "real": window_shares(classifier, real_pos)}
        for req in requests:
            row[req or "auto"] = window_shares(classifier, generate(name, req))
        out[name] = row
    return out


def summary(results: dict[str, dict], requests: Sequence[str | None] = REQUESTS,
            clear: float = 0.2) -> dict[str, dict[str, float]]:
    """Per column (``real``, ``auto`` and each requested style): mean share of the target
    class over songs, the smallest margin, and on how many songs the target wins by at
    least ``clear``. The target is the song's own style for ``real`` and ``auto``, the
    requested style otherwise."""
    out = {}
    for col in ["real", *(r or "auto" for r in requests)]:
        shares, margins = [], []
        for row in results.values():
            cls = row["style"] if col in ("real", "auto") else style_letter(col)
            shares.append(row[col][cls])
            margins.append(margin(row[col], cls))
        out[col] = {"mean_share": float(np.mean(shares)), "min_margin": float(np.min(margins)),
                    # 1e-9: a margin of exactly `clear` in window counts (0.6 - 0.4) is 0.19999999999999996
                    "songs_clear": int(sum(m >= clear - 1e-9 for m in margins)), "songs": len(margins)}
    return out


def table(results: dict[str, dict], requests: Sequence[str | None] = REQUESTS, clear: float = 0.2) -> str:
    """Markdown table of :func:`measure`'s results plus the :func:`summary` rows."""
    cols = ["real", *(r or "auto" for r in requests)]
    head = ["song (style)", "real dancer: own style", *(
        "auto: song's style" if c == "auto" else f"{c}: {style_letter(c)}" for c in cols[1:])]
    lines = ["| " + " | ".join(head) + " |", "| --- |" + " ---: |" * (len(head) - 1)]
    for name, row in results.items():
        cells = []
        for c in cols:
            cls = row["style"] if c in ("real", "auto") else style_letter(c)
            cells.append(f"{row[c][cls]:.2f} ({margin(row[c], cls):+.2f})")
        lines.append(f"| {name} ({row['style']}) | " + " | ".join(cells) + " |")
    s = summary(results, requests, clear)
    lines.append("| mean share | " + " | ".join(f"{s[c]['mean_share']:.2f}" for c in cols) + " |")
    lines.append(f"| songs won by >= {clear:g} | " +
                 " | ".join(f"{s[c]['songs_clear']}/{s[c]['songs']}" for c in cols) + " |")
    return "\n".join(lines)


def seeds_table(runs: dict[int, dict[str, dict]], requests: Sequence[str | None] = REQUESTS,
                clear: float = 0.2) -> str:
    """Markdown table of several seeds' :func:`summary`: per seed and pooled (:func:`pool`), each
    column's mean share of the target style and the songs it wins by at least ``clear``."""
    cols = ["real", *(r or "auto" for r in requests)]
    lines = ["| seed | " + " | ".join(cols) + " |", "| --- |" + " ---: |" * len(cols)]
    for label, results in [*((str(k), v) for k, v in runs.items()), ("all", pool(runs))]:
        s = summary(results, requests, clear)
        lines.append(f"| {label} | " + " | ".join(
            f"{s[c]['mean_share']:.3f} ({s[c]['songs_clear']}/{s[c]['songs']})" for c in cols) + " |")
    return "\n".join(lines)


def pool(runs: dict[int, dict[str, dict]]) -> dict[str, dict]:
    """One results dict of several seeds' (``{seed: results}``): every song-seed a row."""
    return {f"{name} seed {seed}": row for seed, results in runs.items() for name, row in results.items()}


def run(checkpoint: str, data_root: str | Path, cache_dir: str | Path | None, seeds: Sequence[int] = (0,),
        requests: Sequence[str | None] = REQUESTS, log=print) -> tuple[dict[int, dict[str, dict]], list[str]]:
    """Load, generate and classify (see the module docstring) once per seed; returns
    (``{seed: results}``, class names)."""
    import torch

    from models.errors import ConfigError
    from models.evaluation.evaluate import (EvalOptions, _audio_kw, load_clips, positions, real_set, split_dances,
                                            style_classifier)
    from models.generate import load_model, run_model

    lm = load_model(checkpoint)
    if not getattr(lm.model, "takes_style", False):
        raise ConfigError(f"{checkpoint}: model {type(lm.model).__name__} takes no style (dance_vq models do)")
    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    train_names, val_names = split_dances(data_root, opts)
    log(f"style classifier on {len(train_names)} training dances (cached under {cache_dir})...")
    train = real_set(data_root, load_clips(data_root, train_names, lm.features, opts), with_beats=False,
                     progress=False)
    classifier = style_classifier(train, opts.classifier_epochs, opts.seed, cache_dir)
    clips = {c.name: c for c in load_clips(data_root, val_names, lm.features, opts)}

    def generate(seed: int, name: str, style: str | None) -> np.ndarray:
        c = clips[name]
        log(f"  {name}: {style or 'auto'}, seed {seed}")
        with torch.no_grad():
            return positions(run_model(lm.model, c.features, opts.window, opts.hop, seed=seed, style=style,
                                       **_audio_kw(lm.model, data_root, c)))

    log(f"generating {len(val_names)} validation dances x {len(requests)} styles x {len(seeds)} seeds...")
    songs = [(n, clips[n].style, positions(clips[n].poses)) for n in val_names]
    return ({seed: measure(classifier, songs, functools.partial(generate, seed), requests) for seed in seeds},
            list(classifier.class_names))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint or dataset, "
                                       "or a checkpoint whose model takes no style.")
    p.add_argument("--checkpoint", default="models/assets/default.pt", metavar="CKPT",
                   help="a checkpoint whose model takes a style (default: models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR",
                   help="corpus and style-classifier cache (default .cache/corpus)")
    p.add_argument("--seed", type=int, nargs="+", default=[0],
                   help="generation seeds (default 0); several: a summary per seed and their pool")
    p.add_argument("--styles", nargs="+", choices=[r or "auto" for r in REQUESTS], metavar="STYLE",
                   help="request only these styles (auto, chacha, rumba, waltz; default all)")
    p.add_argument("--guidance", type=float, metavar="G",
                   help="STYLE_GUIDANCE for this run (default: the shipped one; 1: no guidance)")
    p.add_argument("--margin", type=float, default=0.2,
                   help="a style wins a song 'clearly' when its share beats every other style's by this "
                        "much (default 0.2)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    p.add_argument("--json", metavar="OUT", help="also write the results (every song's class shares) as JSON")
    a = p.parse_args(argv)
    if not 0 <= a.margin < 1:
        p.error("--margin must be in [0, 1)")
    if a.threads < 1:
        p.error("--threads must be >= 1")
    if a.guidance is not None and not a.guidance > 0:
        p.error("--guidance must be > 0")
    import torch

    import models.networks.chooser as ds
    from models.errors import PerformerError

    requests = [r for r in REQUESTS if (r or "auto") in (a.styles or [r or "auto"])]
    shipped = ds.STYLE_GUIDANCE
    guidance = shipped if a.guidance is None else a.guidance
    torch.set_num_threads(a.threads)
    try:
        ds.STYLE_GUIDANCE = guidance  # read by every code step of this run's streams
        runs, classes = run(a.checkpoint, a.data, a.cache, a.seed, requests, log=lambda m: print(m, file=sys.stderr))
    except (PerformerError, OSError) as e:
        print(f"style_control.py: {e}", file=sys.stderr)
        return 2
    finally:
        ds.STYLE_GUIDANCE = shipped
    seeds = " ".join(map(str, a.seed))
    print(f"Style classifier's share of each generated dance's windows for the target style "
          f"(in brackets: margin over the most frequent other style); {a.checkpoint}, seed {seeds}, "
          f"STYLE_GUIDANCE {guidance:g}\n")
    if len(runs) == 1:
        print(table(next(iter(runs.values())), requests, clear=a.margin))
    else:
        print(f"Mean share of the target style (songs won by >= {a.margin:g})\n")
        print(seeds_table(runs, requests, clear=a.margin))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({
            "checkpoint": a.checkpoint, "seeds": a.seed, "guidance": guidance, "classes": classes,
            "margin": a.margin, "runs": {str(k): {"songs": v, "summary": summary(v, requests, a.margin)}
                                         for k, v in runs.items()},
            "summary": summary(pool(runs), requests, a.margin)}, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
