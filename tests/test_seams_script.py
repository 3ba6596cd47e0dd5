"""benchmarks/studies/seams.py: the seam ratio table of docs/training.md and its exit status."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from models.generate import default_checkpoint_path

_path = Path(__file__).resolve().parents[1] / "benchmarks" / "studies" / "seams.py"
_spec = importlib.util.spec_from_file_location("seams", _path)
seams = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(seams)


def _ratios(out: str) -> list[float]:
    row = [line for line in out.splitlines() if line.startswith("| clip.ogg")]
    assert len(row) == 1, out
    return [float(c) for c in row[0].strip().strip("|").split("|")[1:]]


def test_default_on_the_clip_has_invisible_seams_and_the_threshold_sets_the_exit(capsys):
    ckpt = str(default_checkpoint_path())
    assert seams.main(["--checkpoint", ckpt]) == 0
    (ratio,) = _ratios(capsys.readouterr().out)
    assert 0.5 < ratio <= 1.2
    assert seams.main(["--checkpoint", ckpt, "--max", str(ratio - 0.01)]) == 1
    assert _ratios(capsys.readouterr().out) == [ratio]  # deterministic


def test_missing_and_offline_checkpoints_are_refused(tmp_path, capsys):
    assert seams.main(["--checkpoint", str(tmp_path / "nope.pt")]) == 2
    assert "nope.pt" in capsys.readouterr().err
    violin = Path(__file__).resolve().parents[1] / "models" / "assets" / "violin.pt"
    assert seams.main(["--checkpoint", str(violin)]) == 2
    assert "only causal checkpoints" in capsys.readouterr().err
