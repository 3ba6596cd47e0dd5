"""A training run's ``log.csv`` (one row per step) and its loss-curve plot ``losses.png``.

Every trainer (``train.py``, ``dtm.py``, ``gcn_train.py``) logs one CSV row per step,
with empty cells where a value was not measured that step, and names the plot's panels
(:data:`Panel`). On resume the log is cut back to the saved step, so a run that was
interrupted after its last ``state.pt`` logs no step twice.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

import numpy as np

# (panel title, CSV columns, log-scale y axis)
Panel = tuple[str, Sequence[str], bool]


def plot_log(log_path: str | Path, png: str | Path, panels: Sequence[Panel]) -> None:
    """Write ``png``: one panel per ``(title, columns, log_y)``, each column against ``step``.

    Columns missing from the log or empty throughout are left out, and so are panels
    left with none (a run without a GAN stage has no GAN panel). A panel whose title
    starts with "validation" draws points joined by lines (it is logged every
    ``eval_every`` steps), the others plain lines. Nothing is written for an empty log.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(log_path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return
    step = np.array([int(r["step"]) for r in rows])
    cols = {key: np.array([float(r[key]) if r.get(key) else np.nan for r in rows]) for _, keys, _ in panels for key in keys}
    shown = [pn for pn in panels if any(np.isfinite(cols[k]).any() for k in pn[1])] or list(panels[:1])
    fig, axes = plt.subplots(1, len(shown), figsize=(5 * len(shown), 4), squeeze=False)
    for ax, (title, keys, log_y) in zip(axes[0], shown):
        for key in keys:
            ok = np.isfinite(cols[key])
            if ok.any():
                style = "o-" if title.startswith("validation") else "-"
                ax.plot(step[ok], cols[key][ok], style, label=key, alpha=0.8)
        if log_y and ax.lines and all((ln.get_ydata() > 0).all() for ln in ax.lines):
            ax.set_yscale("log")
        ax.set_title(title)
        ax.set_xlabel("step")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)


class RunLog:
    """``OUT/log.csv`` with columns ``fields`` (``step`` first) and ``OUT/losses.png`` with ``panels``."""

    def __init__(self, out_dir: str | Path, fields: Sequence[str], panels: Sequence[Panel]) -> None:
        self.path = Path(out_dir) / "log.csv"
        self.png = Path(out_dir) / "losses.png"
        self.fields = list(fields)
        self.panels = panels

    def start(self, resume_step: int | None = None) -> None:
        """A new log (``resume_step`` None), or the existing one cut to rows with step <= ``resume_step``."""
        rows: list[dict] = []
        if resume_step is not None and self.path.exists():
            with open(self.path, newline="") as f:
                rows = [r for r in csv.DictReader(f) if int(r["step"]) <= resume_step]
        with open(self.path, "w", newline="") as f:
            w = csv.DictWriter(f, self.fields)
            w.writeheader()
            w.writerows(rows)

    def append(self, row: dict) -> None:
        """Log one step's row (keys a subset of ``fields``)."""
        with open(self.path, "a", newline="") as f:
            csv.DictWriter(f, self.fields).writerow(row)

    def plot(self) -> None:
        """Redraw ``losses.png`` from the whole log."""
        plot_log(self.path, self.png, self.panels)
