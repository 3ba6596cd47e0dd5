"""Report writer: JSON, Markdown table with units and arrows, bar chart."""

from __future__ import annotations

import json

import pytest

from models.errors import DataError
from models.evaluation.report import markdown_table, write_report

RESULTS = {
    "real": {"beat_hit_rate": 0.52, "energy_ratio": 1.0, "jerk": 210.0},
    "lstm": {"dtw": 0.081, "pck@0.1": 0.4, "beat_hit_rate": 0.31, "energy_ratio": 0.2, "jerk": float("nan")},
    "transformer": {"dtw": 0.062, "pck@0.1": 0.55, "beat_hit_rate": 0.44, "energy_ratio": 0.9, "custom": 3},
}


def test_markdown_table_layout():
    lines = markdown_table(RESULTS).splitlines()
    header = lines[0]
    # known metrics first, in registry order, with units and better-direction arrows
    assert header.startswith("| model | DTW (m) ↓ | PCK@0.1 ↑ | Beat hit rate ↑ | Energy ratio →1 | Jerk (m/s³) ≈real |")
    assert header.endswith("| custom |")
    assert lines[1].count("---:") == 6
    rows = {line.split("|")[1].strip(): line for line in lines[2:]}
    assert set(rows) == {"real", "lstm", "transformer"}
    assert "| 0.062 |" in rows["transformer"]
    assert "n/a" in rows["lstm"]  # NaN jerk
    assert rows["real"].count("–") == 3  # dtw, pck, custom missing


def test_write_report_files(tmp_path):
    cmd = "performer evaluate --checkpoint runs/x.pt --out reports/x"
    paths = write_report(RESULTS, tmp_path / "out", "Validation split", [cmd])
    assert set(paths) == {"json", "md", "png"}
    doc = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert doc["title"] == "Validation split" and doc["commands"] == [cmd]
    assert doc["results"]["lstm"]["jerk"] is None  # NaN -> null, still valid JSON
    assert doc["results"]["transformer"]["custom"] == 3.0
    assert doc["metrics"]["dtw"] == {"label": "DTW", "unit": "m", "better": "lower", "source": "Chen et al., IEEE TVCG 2021"}
    md = paths["md"].read_text(encoding="utf-8")
    assert md.startswith("# Validation split")
    assert cmd in md and "results.png" in md
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_no_chart_without_chart_metrics(tmp_path):
    paths = write_report({"m": {"custom": 1.0}}, tmp_path, "t", [])
    assert "png" not in paths and not (tmp_path / "results.png").exists()


@pytest.mark.parametrize("bad", [{}, {"m": 1.0}, {"m": {"dtw": "abc"}}])
def test_bad_results_are_data_errors(tmp_path, bad):
    with pytest.raises(DataError, match="results"):
        write_report(bad, tmp_path, "t", [])


def test_band_columns_show_their_targets(tmp_path):
    header = markdown_table({"m": {"jerk": 1.0, "band_amp": 0.16, "jitter": 3.9}}).splitlines()[0]
    assert header == "| model | Jerk (m/s³) ≈real | Dance amp 0.25-3 Hz →1 | Jitter >6 Hz ≤1.5 |"
    md = write_report({"m": {"band_amp": 0.16, "jitter": 3.9}}, tmp_path, "t", [])["md"].read_text(encoding="utf-8")
    assert "≤1.5 at most 1.5 is the target" in md
