"""benchmarks/studies/seed_spread.py: grouping evaluated checkpoints by recipe and their spread."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from script_loader import load_script

seed_spread = load_script("benchmarks/studies/seed_spread.py")


def _write_eval(d: Path, rows: dict[str, tuple[str, float]]) -> Path:
    """A performer-evaluate output directory: row name -> (checkpoint, rot_l1)."""
    d.mkdir()
    results = {name: {"rot_l1": v, "dtw": 2 * v} for name, (_, v) in rows.items()}
    results["real data"] = {"rot_l1": 0.0, "dtw": 0.0}
    per_dance = {name: {"checkpoint": ckpt, "per_dance": {}} for name, (ckpt, _) in rows.items()}
    per_dance["real data"] = {"per_dance": {}}
    per_dance["_run"] = {"dances": []}
    (d / "results.json").write_text(json.dumps({"title": "t", "commands": [], "metrics": {}, "results": results}))
    (d / "per_dance.json").write_text(json.dumps(per_dance))
    return d


def test_groups_by_glob_and_reports_mean_std_min_max(tmp_path, capsys):
    d = _write_eval(tmp_path / "eval", {
        "causal (best.pt)": ("runs/a_s1/best.pt", 0.058),
        "causal (runs/a_s2/best.pt)": ("runs/a_s2/best.pt", 0.060),
        "lstm (best.pt)": ("runs/lstm/best.pt", 0.057),
        "lstm (runs/lstm_s1/best.pt)": ("runs/lstm_s1/best.pt", 0.059),
        "lstm (runs/lstm_s2/best.pt)": ("runs/lstm_s2/best.pt", 0.061),
    })
    rows = seed_spread.load_rows(d)
    assert seed_spread.group_rows(rows, ["runs/lstm/best.pt", "runs/lstm_s*/best.pt"]) == [
        "runs/lstm/best.pt", "runs/lstm_s1/best.pt", "runs/lstm_s2/best.pt"]
    s = seed_spread.spread([0.057, 0.059, 0.061])
    assert s["mean"] == pytest.approx(0.059) and s["std"] == pytest.approx(0.002)
    assert (s["min"], s["max"]) == (0.057, 0.061)
    assert seed_spread.spread([0.05])["std"] == 0.0
    assert seed_spread.main([str(d), "--group", "a=runs/a_*/best.pt", "--group",
                             "lstm=runs/lstm/best.pt,runs/lstm_s*/best.pt", "--metrics", "rot_l1"]) == 0
    out = capsys.readouterr().out
    assert "| a | 2 | 0.059 ± 0.0014 (0.058-0.06) |" in out
    assert "| lstm | 3 | 0.059 ± 0.002 (0.057-0.061) |" in out
    assert "| lstm | runs/lstm_s2/best.pt | 0.061 |" in out


def test_a_group_matching_nothing_or_a_missing_directory_is_a_clear_error(tmp_path, capsys):
    d = _write_eval(tmp_path / "eval", {"lstm (best.pt)": ("runs/lstm/best.pt", 0.057)})
    assert seed_spread.main([str(d), "--group", "x=runs/nope/*.pt"]) == 2
    assert "no evaluated checkpoint matches" in capsys.readouterr().err
    assert seed_spread.main([str(d), "--group", "x=runs/lstm/*", "--metrics", "rot_l2"]) == 2
    assert "unknown key(s) ['rot_l2']" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="not found"):
        seed_spread.main([str(tmp_path / "missing"), "--group", "x=*"])
