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

Exit status 2 on a missing or unreadable checkpoint or dataset, or a checkpoint whose
model takes no style.
"""

from __future__ import annotations

import argparse
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


def run(checkpoint: str, data_root: str | Path, cache_dir: str | Path | None, seed: int = 0,
        log=print) -> tuple[dict[str, dict], list[str]]:
    """Load, generate and classify (see the module docstring); returns (results, class names)."""
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

    def generate(name: str, style: str | None) -> np.ndarray:
        c = clips[name]
        log(f"  {name}: {style or 'auto'}")
        with torch.no_grad():
            return positions(run_model(lm.model, c.features, opts.window, opts.hop, seed=seed, style=style,
                                       **_audio_kw(lm.model, data_root, c)))

    log(f"generating {len(val_names)} validation dances x {len(REQUESTS)} styles...")
    songs = [(n, clips[n].style, positions(clips[n].poses)) for n in val_names]
    return measure(classifier, songs, generate), list(classifier.class_names)


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
    p.add_argument("--seed", type=int, default=0, help="generation seed (default 0)")
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
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(a.threads)
    try:
        results, classes = run(a.checkpoint, a.data, a.cache, a.seed, log=lambda m: print(m, file=sys.stderr))
    except (PerformerError, OSError) as e:
        print(f"style_control.py: {e}", file=sys.stderr)
        return 2
    print(f"Style classifier's share of each generated dance's windows for the target style "
          f"(in brackets: margin over the most frequent other style); {a.checkpoint}, seed {a.seed}\n")
    print(table(results, clear=a.margin))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({
            "checkpoint": a.checkpoint, "seed": a.seed, "classes": classes, "margin": a.margin,
            "songs": results, "summary": summary(results, clear=a.margin)}, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
