"""benchmarks/studies/lead.py: the lead measured as the audience sees it behind a display delay (docs/listening.md, "Lead")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
lb = load_script("benchmarks/studies/lead.py")


def test_a_lead_keeps_the_beat_hits_behind_the_delay_and_lead_0_loses_them():
    """A model whose every movement turns steadily, on a 15-frame pulse: the warp's speed dips
    fall on the beats; seen 4 frames late, lead 133 ms keeps them there, lead 0 does not."""
    import torch

    from models.networks.dance_vq import DanceVQ
    from test_dance_vq import BEAT, beat_music, turning_exemplars

    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    with torch.no_grad():
        m.gate[0] = -50.0
    x = beat_music(900)
    beats = np.arange(0, 900, 15)
    row = lb.measure_song(m, x, beats, (0.0, 133.0), seeds=(0, 1))
    rate = {ms: {k: h / n for k, (h, n) in v.items()} for ms, v in row.items() if ms != "chance"}
    assert rate["0"]["seen"] == rate["0"]["undelayed"] == rate["0"]["no_lead"] > 0.8
    assert 0.3 < row["chance"] < 0.4  # +-2 frames of a beat every 15 frames: 5/15
    assert rate["133"]["seen"] > 0.9 * rate["0"]["seen"]  # on the beat as the audience sees it
    assert rate["133"]["no_lead"] < 0.6 * rate["0"]["seen"]  # without the lead: off it
    assert rate["133"]["undelayed"] < 0.6 * rate["0"]["seen"]  # the lead's own motion is early
    text = lb.table({"A": row, "B": row}, (0.0, 133.0))
    assert text.count("\n") == 3 and "| 133 | 4 |" in text and "| 1.00 |" in text
    songs = lb.song_table({"A": row}, (0.0, 133.0))
    assert songs.count("\n") == 2 and songs.splitlines()[-1].startswith("| A | ")
    assert [lb.lead_frames(ms) for ms in (0, 67, 133, 200)] == [0, 2, 4, 6]


@pytest.mark.parametrize("args, message", [
    (["--data", "x", "--leads", "0", "300"], "--leads must each be in [0, 200] ms"),
    (["--data", "x", "--leads", "67", "133"], "the first 0"),
    (["--data", "x", "--oracle"], "--oracle needs --music"),
    (["--data", "x", "--runner-up-change", "-1"], "--runner-up-change must be in [0, 5] octaves"),
    (["--data", "x", "--checkpoint", "/nonexistent/model.pt"], "lead.py: "),
    (["--data", "x", "--checkpoint", str(REPO / "models" / "assets" / "dtm.pt")], "has no lead control"),
])
def test_bad_input_is_one_line_and_exit_2(args, message, capsys, tmp_path):
    out = tmp_path / "l.json"
    try:
        code = lb.main([*args, "--json", str(out)])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert not out.exists()


def test_music_mode_scores_each_recording_up_to_the_end_of_its_music(tmp_path, capsys):
    """``--music DIR`` (issue 43: the lead on any song): each recording of DIR, cut at --max-s,
    danced at every lead and scored against its own beats; the lead keeps the beat behind the delay.
    ``--spread``: the ratio with its intervals over the seeds and over the recording's 5-s blocks."""
    import re
    import shutil

    shutil.copy(REPO / "models" / "assets" / "clip.ogg", tmp_path / "clip.ogg")
    out = tmp_path / "l.json"
    assert lb.main(["--music", str(tmp_path), "--leads", "0", "133", "--seeds", "0", "1", "--max-s", "15",
                    "--spread", "--json", str(out)]) == 0
    row = json.loads(out.read_text())["clip"]
    assert set(row) == {"0", "133", "chance"}
    hits, beats = row["133"]["seen"]
    assert 20 < beats < 2 * 15 * 5 and hits > row["133"]["no_lead"][0]
    line = capsys.readouterr().out.strip().splitlines()[-3]
    ratio, lo, hi, blo, bhi = map(float, re.fullmatch(r"clip: (\S+) \[(\S+), (\S+)\] / \[(\S+), (\S+)\]", line).groups())
    assert ratio == round((hits / beats) / (row["0"]["undelayed"][0] / row["0"]["undelayed"][1]), 2)
    assert lo <= ratio <= hi and blo <= ratio <= bhi


def test_levels_counts_the_trackers_changes_of_level_and_those_the_forecast_catches(tmp_path, capsys):
    """``--levels``: per recording, nothing danced, the frames whose next lead frames change the
    tracker's level; the period-only forecast catches none of them and forecasts no other level.
    On two pulses nearly an octave apart (every 22 and 12 frames) whose level changes over and
    over, the shipped one (the runner-up's onsets expected too) catches four in five."""
    import shutil

    from models.generate import load_model

    shutil.copy(REPO / "models" / "assets" / "clip.ogg", tmp_path / "clip.ogg")
    assert lb.main(["--music", str(tmp_path), "--levels", "--leads", "0", "133"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[0] == "clip" and int(cells[1]) > 0 and int(cells[2]) >= 0  # the clip's level holds: 0
    assert cells[3].endswith("/ 0") and cells[4].endswith("/ 0")
    lm = load_model(str(REPO / "models" / "assets" / "default.pt"))
    n = np.arange(700)
    x = np.zeros((700, lm.model.config.input_dim), np.float32)
    x[:, lm.model.config.onset_col] = np.maximum((n % 22 == 3) * 1.0, (n % 12 == 7) * 0.6)
    from models.features.context import ContextTracker

    cc = lm.model.config.clarity_col
    x[:, cc - 2: cc + 2] = ContextTracker(1, 0.0, True)(x[:, lm.model.config.onset_col, None].astype(np.float64))
    r = lb.level_changes(lm.model, x, 4)
    assert r["on"]["frames"] == r["off"]["frames"] == 700 - 4 - 180
    assert r["on"]["changes"] == r["off"]["changes"] > 50 and r["off"]["caught"] == r["off"]["wrong"] == 0
    assert r["on"]["caught"] > 0.6 * r["on"]["changes"]  # 114 of 136


def test_the_spread_redraws_seeds_and_blocks():
    """Two blocks, one all hits and one none: redrawing the blocks spans 0x..1x-ish, redrawing
    two identical seeds does not move the ratio at all."""
    mus = np.arange(0, 300, 15)
    blocks = lb.block_hits(np.array([0, 15, 30, 160, 166, 210, 290]), mus, 2)
    assert blocks.tolist() == [[3, 3], [2, 4]]  # 160 and 290 miss (5 frames from a beat)
    d = {"0": [blocks, blocks], "133": [blocks, blocks]}
    r = lb.spread(d, 133.0)
    assert r["ratio"] == r["seeds_lo"] == r["seeds_hi"] == 1.0
    assert r["blocks_lo"] == r["blocks_hi"] == 1.0  # the same blocks for both leads
    d["133"] = [blocks[::-1].copy(), blocks[::-1].copy()]
    assert lb.spread(d, 133.0)["blocks_hi"] > lb.spread(d, 133.0)["blocks_lo"]


@pytest.mark.parametrize("args", [["--data", "x", "--music", "y"], []])
def test_one_source_exactly(args, capsys):
    with pytest.raises(SystemExit) as exc:
        lb.main(args)
    assert exc.value.code == 2 and ("--music" in capsys.readouterr().err)


@pytest.mark.slow
@pytest.mark.data
def test_default_checkpoint_on_one_validation_dance(dwm_root, tmp_path):
    out = tmp_path / "l.json"
    assert lb.main(["--data", str(dwm_root), "--cache", str(REPO / ".cache" / "corpus"), "--songs", "DANCE_W_28",
                    "--seeds", "0", "--json", str(out)]) == 0
    row = json.loads(out.read_text())["DANCE_W_28"]
    rate = {ms: {k: h / n for k, (h, n) in v.items()} for ms, v in row.items() if ms != "chance"}
    assert rate["133"]["seen"] > rate["133"]["no_lead"]  # the lead puts the delayed motion back on the beat
