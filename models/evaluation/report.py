"""Evaluation report: ``results.json``, a Markdown table ``results.md`` and a bar chart ``results.png``.

``results`` maps a model name to its metrics, ``{"model": {"dtw": 0.12, ...}}``,
using the metric keys of :data:`METRICS` (unknown keys are reported too, without
unit or direction). Models are rows, metrics columns; each header carries the
unit and the better direction.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

from models.errors import DataError


@dataclass(frozen=True)
class MetricInfo:
    """How a metric is shown: column label, unit ("" if none), better direction, source."""

    label: str
    unit: str
    better: str  # "higher" | "lower" | "one" (closer to 1) | "real" (closer to the real-motion row)
    #              | "max1.5" (at most 1.5: lower is better up to that target, issue 18) | "none"
    source: str


#: Known metric keys, in table order. See docs/metrics.md.
METRICS: dict[str, MetricInfo] = {
    "rot_l1": MetricInfo("Rot L1", "", "lower", "test loss on xyzw quaternions"),
    "pos_l1": MetricInfo("Pos L1", "m", "lower", "Kao & Su, ACM MM 2020"),
    "hand_l1": MetricInfo("Hand L1", "m", "lower", "Kao & Su, ACM MM 2020"),
    "dtw": MetricInfo("DTW", "m", "lower", "Chen et al., IEEE TVCG 2021"),
    "lcss": MetricInfo("LCSS", "", "higher", "Chen et al., IEEE TVCG 2021"),
    "pck@0.1": MetricInfo("PCK@0.1", "", "higher", "Kao & Su, ACM MM 2020"),
    "pck@0.2": MetricInfo("PCK@0.2", "", "higher", "Kao & Su, ACM MM 2020"),
    "dir_f1": MetricInfo("Dir-change F1", "", "higher", "Kao & Su, ACM MM 2020 (bowing attack)"),
    "cosine": MetricInfo("Cosine", "", "higher", "Kao & Su, ACM MM 2020"),
    "beat_coverage": MetricInfo("Beat coverage", "", "real", "Lee et al., NeurIPS 2019"),
    "beat_hit_rate": MetricInfo("Beat hit rate", "", "higher", "Lee et al., NeurIPS 2019"),
    "beat_hit_chance": MetricInfo("Hit rate by chance", "", "none", "hit rate of beats at random frames"),
    "fd": MetricInfo("FD", "", "lower", "Heusel et al., NeurIPS 2017 (style-classifier features)"),
    "diversity": MetricInfo("Diversity", "", "higher", "Lee et al., NeurIPS 2019"),
    "multimodality": MetricInfo("Multimodality", "", "higher",
                                "Lee et al., NeurIPS 2019 (distinct generations per song; n/a: deterministic)"),
    "energy_ratio": MetricInfo("Energy ratio", "", "one", "velocity spread generated / real"),
    "jerk": MetricInfo("Jerk", "m/s³", "real", "third derivative of positions"),
    "band_amp": MetricInfo("Dance amp 0.25-3 Hz", "", "one", "band RMS of FK positions generated / real (issue 18)"),
    "jitter": MetricInfo("Jitter >6 Hz", "", "max1.5", "band RMS of FK positions generated / real (issue 18)"),
    "gan_train": MetricInfo("GAN-train", "", "higher", "Shmelkov et al., ECCV 2018 (optional, --gan-scores)"),
    "gan_test": MetricInfo("GAN-test", "", "higher", "Shmelkov et al., ECCV 2018 (optional, --gan-scores)"),
}

ARROWS: dict[str, str] = {"higher": "↑", "lower": "↓", "one": "→1", "real": "≈real", "max1.5": "≤1.5", "none": ""}

#: Metrics drawn in the bar chart when present.
CHART_METRICS: tuple[str, ...] = (
    "pos_l1", "dtw", "pck@0.2", "dir_f1", "beat_hit_rate", "fd", "diversity", "energy_ratio", "band_amp", "jitter",
)


def _clean(results: dict) -> dict[str, dict[str, float | None]]:
    """Validate ``results``; values as float, None or non-finite as None (JSON has no NaN)."""
    if not isinstance(results, dict) or not results:
        raise DataError("expected a non-empty dict of model name -> {metric: value}", source="results")
    out: dict[str, dict[str, float | None]] = {}
    for model, metrics in results.items():
        if not isinstance(metrics, dict):
            raise DataError(f"model {model!r}: expected a dict of metric -> value, got {type(metrics).__name__}", source="results")
        row: dict[str, float | None] = {}
        for key, value in metrics.items():
            if value is None:  # a metric that could not be computed
                row[str(key)] = None
                continue
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise DataError(f"model {model!r}, metric {key!r}: not a number: {value!r}", source="results") from None
            row[str(key)] = v if math.isfinite(v) else None
        out[str(model)] = row
    return out


def _columns(results: dict[str, dict]) -> list[str]:
    present = {k for row in results.values() for k in row}
    return [k for k in METRICS if k in present] + sorted(present - METRICS.keys())


def _header(key: str) -> str:
    info = METRICS.get(key)
    if info is None:
        return key
    unit = f" ({info.unit})" if info.unit else ""
    return f"{info.label}{unit} {ARROWS[info.better]}".rstrip()


def _cell(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4g}"


def markdown_table(results: dict[str, dict[str, float]]) -> str:
    """The results as a Markdown table: models as rows, metrics as columns."""
    rows = _clean(results)
    cols = _columns(rows)
    lines = [
        "| model | " + " | ".join(_header(c) for c in cols) + " |",
        "| --- | " + " | ".join("---:" for _ in cols) + " |",
    ]
    for model, row in rows.items():
        name = model.replace("|", "\\|")
        lines.append(f"| {name} | " + " | ".join(_cell(row.get(c)) if c in row else "–" for c in cols) + " |")
    return "\n".join(lines)


def _bar_chart(rows: dict[str, dict[str, float | None]], path: Path, title: str) -> bool:
    """Draw one bar panel per chart metric; returns False when none is present."""
    from matplotlib.figure import Figure  # no pyplot: no global backend state

    keys = [k for k in CHART_METRICS if any(row.get(k) is not None for row in rows.values())]
    if not keys:
        return False
    ncols = min(4, len(keys))
    nrows = -(-len(keys) // ncols)
    fig = Figure(figsize=(3.2 * ncols, 2.8 * nrows + 0.6), layout="constrained")
    fig.suptitle(title)
    models = list(rows)
    for i, key in enumerate(keys):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        values = [rows[m].get(key) for m in models]
        ax.bar(range(len(models)), [math.nan if v is None else v for v in values], color=f"C{i % 10}")  # missing: no bar
        ax.set_xticks(range(len(models)), models, rotation=30, ha="right", fontsize=8)
        ax.set_title(_header(key), fontsize=9)
        if METRICS[key].better == "one":
            ax.axhline(1.0, color="k", lw=0.8, ls="--")
        elif METRICS[key].better == "max1.5":
            ax.axhline(1.5, color="k", lw=0.8, ls="--")
    fig.savefig(path, dpi=110)
    return True


def write_report(
    results: dict[str, dict[str, float]],
    out_dir: str | os.PathLike,
    title: str,
    commands: list[str],
) -> dict[str, Path]:
    """Write ``results.json``, ``results.md`` and (when a chart metric is present) ``results.png``.

    ``results``: model name -> {metric key -> value}; ``commands``: the command
    lines that produced the numbers (shown in the Markdown so a reader can rerun
    them). Returns the written paths keyed ``"json"``, ``"md"``, ``"png"``.
    """
    rows = _clean(results)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"cannot create report directory: {exc.strerror}", source=out) from None
    cols = _columns(rows)
    doc = {
        "title": title,
        "commands": list(commands),
        "metrics": {k: asdict(METRICS[k]) for k in cols if k in METRICS},
        "results": rows,
    }
    paths = {"json": out / "results.json", "md": out / "results.md"}
    paths["json"].write_text(json.dumps(doc, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")

    legend = ", ".join(f"{a} {d}" for d, a in (
        ("higher is better", "↑"), ("lower is better", "↓"), ("closer to 1 is better", "→1"),
        ("closer to the real-motion row is better", "≈real"), ("at most 1.5 is the target", "≤1.5"),
    ))
    md = [f"# {title}", "", markdown_table(rows), "", f"{legend}. Definitions: docs/metrics.md.", ""]
    if commands:
        md += ["Produced by:", "", "```sh", *commands, "```", ""]
    png = out / "results.png"
    if _bar_chart(rows, png, title):
        paths["png"] = png
        md += ["![main metrics](results.png)", ""]
    paths["md"].write_text("\n".join(md), encoding="utf-8")
    return paths
