"""benchmarks/studies/joint_heights.py: the joint-height figure of issue 18 and its errors."""

from __future__ import annotations


import numpy as np
import pytest

from script_loader import load_script

jh = load_script("benchmarks/studies/joint_heights.py")


def test_plot_writes_one_panel_per_joint(tmp_path):
    t = np.arange(900) / 30
    heights = {"real": np.stack([1.3 + 0.2 * np.sin(t), 1.5 + 0.1 * np.cos(t), 1.5 + 0.0 * t], axis=1),
               "runs/x/best.pt": np.full((900, 3), 1.4)}
    out = tmp_path / "img" / "h.png"
    jh.plot(heights, 5.0, 20.0, "test", out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(jh.JOINTS) == 3


@pytest.mark.parametrize("args, message", [
    (["--data", "/nonexistent/dwm"], "joint_heights.py: "),
    (["--data", "x", "--seconds", "0"], "--seconds must be > 0"),
])
def test_bad_input_is_one_line_and_exit_2(args, message, capsys, tmp_path):
    try:
        code = jh.main([*args, "--out", str(tmp_path / "h.png")])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert not (tmp_path / "h.png").exists()
