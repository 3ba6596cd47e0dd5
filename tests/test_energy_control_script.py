"""benchmarks/studies/energy_control.py: the energy control measured against the real dancer (docs/show.md, "Energy")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
ec = load_script("benchmarks/studies/energy_control.py")


def test_measure_song_tracks_the_control_on_a_model_whose_codes_differ_in_speed(tmp_path):
    from models.evaluation.evaluate import positions
    from models.networks.dance_stream import generate
    from test_dance_vq import music, speed_model

    m = speed_model(np.linspace(0.5, 8.0, 16))
    x = music(600)
    real = positions(generate(m, x, seed=1))  # any moving reference: the ratios are relative to it
    traces: dict = {}
    row = ec.measure_song(m, x, real, (0.0, 1.0, 2.0), seed=0, traces=traces)
    assert list(row) == ["0", "1", "2"] and set(traces) == {"0", "1", "2"}
    assert row["0"]["code_energy"] < row["1"]["code_energy"] < row["2"]["code_energy"]
    assert row["0"]["energy_ratio"] < row["2"]["energy_ratio"]
    assert all(0.0 <= v["max_step_deg"] < 180.0 for v in row.values())
    results = {"SONG_A": row, "SONG_B": row}
    text = ec.table(results, (0.0, 1.0, 2.0))
    assert text.count("\n") == 4 and "| 1 (default) |" in text
    png = ec.plot(results, (0.0, 1.0, 2.0), tmp_path / "e.png", "toy", ("SONG_A", traces, real))
    assert png.stat().st_size > 10_000


def test_largest_bone_step():
    from scipy.spatial.transform import Rotation

    poses = np.zeros((3, 7), np.float32)
    poses[:, 3:] = Rotation.from_euler("y", [[0.0], [10.0], [40.0]], degrees=True).as_quat()
    assert ec.largest_bone_step(poses) == pytest.approx(30.0, abs=1e-3)


@pytest.mark.parametrize("args, message", [
    (["--data", "x", "--levels", "0", "3"], "--levels must each be in [0, 2]"),
    (["--data", "x", "--checkpoint", "/nonexistent/model.pt"], "energy_control.py: "),
    (["--data", "x", "--checkpoint", str(REPO / "models" / "assets" / "dtm.pt")], "has no energy control"),
])
def test_bad_input_is_one_line_and_exit_2(args, message, capsys, tmp_path):
    out = tmp_path / "e.json"
    try:
        code = ec.main([*args, "--json", str(out)])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.data
def test_default_checkpoint_on_two_validation_dances(dwm_root, tmp_path):
    out = tmp_path / "e.json"
    assert ec.main(["--data", str(dwm_root), "--cache", str(REPO / ".cache" / "corpus"), "--levels", "0", "1", "2",
                    "--songs", "DANCE_C_2", "DANCE_W_22", "--json", str(out)]) == 0
    songs = json.loads(out.read_text())["songs"]
    assert set(songs) == {"DANCE_C_2", "DANCE_W_22"}
    for row in songs.values():  # the control moves the dance the way it says, on every song
        assert row["0"]["energy_ratio"] < row["1"]["energy_ratio"] < row["2"]["energy_ratio"]
        assert max(v["max_step_deg"] for v in row.values()) < 60.0
