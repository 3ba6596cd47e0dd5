"""Budgets for the latency suite: ``benchmarks/budgets.toml`` and the readable diff of ``performer bench check``.

File format (TOML): one table per result kind, one entry per metric of that kind's
``metrics`` (see :func:`realtime.bench.suite.latency_metrics`, and ``sustained_streams``
for the sweep), each ``{ max = X }`` (measured must be <= X) or ``{ min = X }``::

    [latency]
    per_hop_ms_p99 = { max = 5.0 }
    [streams]
    sustained_streams = { min = 8 }
    [quiet]
    others_busy_percent = 10.0
    [ensemble]
    lane_cycle_over_reference_4 = { max = 2.1 }
    per_hop_ms_p99_own_4 = { max = 5.0, quiet = true }

Budgets for a quiet machine: an entry with ``quiet = true`` (an absolute wall-clock target)
applies only to a result whose ``others_busy_percent`` (the share of the machine's CPUs that
processes other than the benchmark's held during the run) is at most the ``[quiet]`` table's
figure; on a busier machine its verdict is n/a, with the share measured, neither a pass nor
a failure. Regressions are caught on any machine by the budgets on ratios of figures
measured in the same run (``lane_cycle_over_reference_N``, docs/latency.md).
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
    quiet: bool = False  # applies only when other processes left the machine quiet ([quiet])


@dataclass(frozen=True)
class Verdict:
    """One budget applied to one result."""

    label: str
    budget: Budget
    measured: float | None  # None: the result does not have this metric
    not_applicable: str | None = None  # why the metric does not apply to this result's model (then ok)

    @property
    def limit(self) -> float:
        return self.budget.limit

    @property
    def ok(self) -> bool:
        if self.not_applicable is not None:
            return True
        m = self.measured
        if m is None or not math.isfinite(m):
            return False
        return m <= self.limit if self.budget.op == "max" else m >= self.limit

    @property
    def over(self) -> float:
        """How far past the limit applied (positive = exceeded), in the metric's unit."""
        if self.measured is None or not math.isfinite(self.measured):
            return math.inf
        d = self.measured - self.limit
        return d if self.budget.op == "max" else -d


def _number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


class BudgetList(list):
    """The budgets of a file (a list of :class:`Budget`) with its ``[quiet]`` figure: the most
    other processes may hold of the CPUs, percent (or None)."""

    quiet_percent: float | None = None


def load_budgets(path: str | Path) -> BudgetList:
    """Parse a budgets file; ConfigError naming the file and the entry when malformed."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError("budgets file not found", source=path) from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read budgets: {exc}", source=path) from None
    out = BudgetList()
    quiet = data.pop("quiet", None)
    if quiet is not None:
        share = quiet.get("others_busy_percent") if isinstance(quiet, dict) and len(quiet) == 1 else None
        if not (_number(share) and 0 <= share <= 100):
            raise ConfigError(f"[quiet]: expected others_busy_percent = a percentage (0-100) only, got {quiet!r}",
                              source=path)
        out.quiet_percent = float(share)
    for kind, table in data.items():
        if kind not in KINDS or not isinstance(table, dict):
            raise ConfigError(f"unknown budget table [{kind}]; use [quiet], "
                              f"{', '.join(f'[{k}]' for k in KINDS)}", source=path)
        for metric, spec in table.items():
            keys = set(spec) if isinstance(spec, dict) else set()
            ops = keys & {"max", "min"}
            if len(ops) != 1 or keys - ops - {"quiet"}:
                raise ConfigError(f"[{kind}] {metric}: expected {{ max = X }} or {{ min = X }} "
                                  f"(either may have quiet = true), got {spec!r}", source=path)
            op = ops.pop()
            limit = spec[op]
            if not _number(limit):
                raise ConfigError(f"[{kind}] {metric}: {op} must be a number, got {limit!r}", source=path)
            quiet = spec.get("quiet", False)
            if not isinstance(quiet, bool):
                raise ConfigError(f"[{kind}] {metric}: quiet must be true or false, got {quiet!r}", source=path)
            if quiet and out.quiet_percent is None:
                raise ConfigError(f"[{kind}] {metric}: quiet = true needs a [quiet] table "
                                  "(others_busy_percent) before it", source=path)
            out.append(Budget(kind, metric, op, float(limit), quiet))
    return out


def check(results: list[dict], budgets: list[Budget]) -> list[Verdict]:
    """Every budget of each result's kind applied to that result's ``metrics``.

    A metric the result lacks fails its budget ("not measured"), unless the result names
    it under ``not_applicable`` with the reason (a figure its model does not have, e.g. the
    naive-recompute ratio of a dance_vq model): that verdict is "n/a", neither a pass nor a
    failure. A quiet
    budget is n/a, with the share measured, for a result whose ``others_busy_percent`` is
    over the ``[quiet]`` figure (a result without that figure is checked).
    """
    quiet_percent = getattr(budgets, "quiet_percent", None)
    verdicts = []
    for r in results:
        na = r.get("not_applicable") or {}
        metrics = r.get("metrics", {})
        for b in budgets:
            if b.kind == r.get("kind"):
                v = metrics.get(b.metric)
                reason = na.get(b.metric) if v is None else None
                busy = metrics.get("others_busy_percent")
                if b.quiet and quiet_percent is not None and busy is not None and busy > quiet_percent:
                    reason = (f"other processes held {busy:.0f}% of the CPUs during the run (> {quiet_percent:g}%): "
                              "an absolute wall-clock target needs a quiet machine")
                verdicts.append(Verdict(r.get("label", "?"), b, None if v is None else float(v),
                                        None if reason is None else str(reason)))
    return verdicts


def tally(verdicts: list[Verdict]) -> str:
    """``"N of M budget checks within budget, K n/a, J over budget"``: n/a counted apart from passes."""
    na = sum(v.not_applicable is not None for v in verdicts)
    over = sum(not v.ok for v in verdicts)
    applied = len(verdicts) - na
    return (f"{applied - over} of {applied} budget checks within budget, {over} over budget"
            + (f"; {na} not applicable (not counted)" if na else ""))


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
            shown = "n/a" if v.measured is None else _fmt(v.measured)  # a quiet budget's figure, still shown
            rows.append((v.label, v.budget.metric, f"{sign} {v.budget.limit:g}", shown, "-", "n/a"))
            continue
        if v.ok:
            over = "-"
        elif v.measured is None or not math.isfinite(v.measured):
            over = "n/a"
        else:
            pct = f" ({100 * v.over / abs(v.limit):+.0f}%)" if v.limit else ""
            over = f"{v.over:.3g}{pct}"
        rows.append((v.label, v.budget.metric, f"{sign} {v.limit:.3g}", _fmt(v.measured), over,
                     "ok" if v.ok else "OVER BUDGET"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    table = "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)
    reasons = [] if only_failures else sorted({(v.budget.metric, v.not_applicable) for v in verdicts
                                               if v.not_applicable is not None})
    return table + "".join(f"\nn/a {metric}: {why}" for metric, why in reasons)
