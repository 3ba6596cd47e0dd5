"""Budgets for the latency suite: ``benchmarks/budgets.toml`` and the readable diff of ``performer bench check``.

File format (TOML): one table per result kind, one entry per metric of that kind's
``metrics`` (see :func:`realtime.bench.suite.latency_metrics`, and ``sustained_streams``
for the sweep), each ``{ max = X }`` (measured must be <= X) or ``{ min = X }``::

    [latency]
    per_hop_ms_p99 = { max = 5.0 }
    [streams]
    sustained_streams = { min = 8 }
    [ensemble]
    per_hop_ms_p99_4 = { max = 5.0 }
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from models.errors import ConfigError

KINDS: tuple[str, ...] = ("latency", "streams", "ensemble")


@dataclass(frozen=True)
class Budget:
    """``metric`` of results of ``kind`` must stay ``<= limit`` (op "max") or ``>= limit`` (op "min")."""

    kind: str
    metric: str
    op: str
    limit: float


@dataclass(frozen=True)
class Verdict:
    """One budget applied to one result."""

    label: str
    budget: Budget
    measured: float | None  # None: the result does not have this metric
    not_applicable: str | None = None  # why the metric does not apply to this result's model (then ok)

    @property
    def ok(self) -> bool:
        if self.not_applicable is not None:
            return True
        m = self.measured
        if m is None or not math.isfinite(m):
            return False
        return m <= self.budget.limit if self.budget.op == "max" else m >= self.budget.limit

    @property
    def over(self) -> float:
        """How far past the limit (positive = exceeded), in the metric's unit."""
        if self.measured is None or not math.isfinite(self.measured):
            return math.inf
        d = self.measured - self.budget.limit
        return d if self.budget.op == "max" else -d


def load_budgets(path: str | Path) -> list[Budget]:
    """Parse a budgets file; ConfigError naming the file and the entry when malformed."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError("budgets file not found", source=path) from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read budgets: {exc}", source=path) from None
    out = []
    for kind, table in data.items():
        if kind not in KINDS or not isinstance(table, dict):
            raise ConfigError(f"unknown budget table [{kind}]; use {', '.join(f'[{k}]' for k in KINDS)}", source=path)
        for metric, spec in table.items():
            if not (isinstance(spec, dict) and len(spec) == 1 and next(iter(spec)) in ("max", "min")):
                raise ConfigError(f"[{kind}] {metric}: expected {{ max = X }} or {{ min = X }}, got {spec!r}",
                                  source=path)
            op, limit = next(iter(spec.items()))
            if isinstance(limit, bool) or not isinstance(limit, (int, float)):
                raise ConfigError(f"[{kind}] {metric}: {op} must be a number, got {limit!r}", source=path)
            out.append(Budget(kind, metric, op, float(limit)))
    return out


def check(results: list[dict], budgets: list[Budget]) -> list[Verdict]:
    """Every budget of each result's kind applied to that result's ``metrics``.

    A metric the result lacks fails its budget ("not measured"), unless the result names
    it under ``not_applicable`` with the reason (a figure its model does not have, e.g. the
    naive-recompute ratio of a dance_vq model): that verdict is "n/a" and passes.
    """
    verdicts = []
    for r in results:
        na = r.get("not_applicable") or {}
        for b in budgets:
            if b.kind == r.get("kind"):
                v = r.get("metrics", {}).get(b.metric)
                reason = na.get(b.metric) if v is None else None
                verdicts.append(Verdict(r.get("label", "?"), b, None if v is None else float(v),
                                        None if reason is None else str(reason)))
    return verdicts


def _fmt(x: float | None) -> str:
    if x is None:
        return "not measured"
    return f"{x:.3g}" if math.isfinite(x) else str(x)


def format_verdicts(verdicts: list[Verdict], only_failures: bool = False) -> str:
    """A fixed-width table: result, metric, budget, measured, how far over, status."""
    rows = [("result", "metric", "budget", "measured", "over by", "")]
    for v in verdicts:
        if only_failures and v.ok:
            continue
        sign = "<=" if v.budget.op == "max" else ">="
        if v.not_applicable is not None:
            rows.append((v.label, v.budget.metric, f"{sign} {v.budget.limit:g}", "n/a", "-", "n/a"))
            continue
        if v.ok:
            over = "-"
        elif v.measured is None or not math.isfinite(v.measured):
            over = "n/a"
        else:
            pct = f" ({100 * v.over / abs(v.budget.limit):+.0f}%)" if v.budget.limit else ""
            over = f"{v.over:.3g}{pct}"
        rows.append((v.label, v.budget.metric, f"{sign} {v.budget.limit:g}", _fmt(v.measured), over,
                     "ok" if v.ok else "OVER BUDGET"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    table = "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)
    reasons = [] if only_failures else sorted({(v.budget.metric, v.not_applicable) for v in verdicts
                                               if v.not_applicable is not None})
    return table + "".join(f"\nn/a {metric}: {why}" for metric, why in reasons)
