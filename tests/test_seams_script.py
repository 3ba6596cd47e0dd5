"""benchmarks/studies/seams.py: the seam ratio table of docs/training.md and its exit status."""

from __future__ import annotations

from pathlib import Path

from models.generate import default_checkpoint_path

from script_loader import load_script

seams = load_script("benchmarks/studies/seams.py")


def _ratios(out: str) -> list[float]:
    row = [line for line in out.splitlines() if line.startswith("| clip.ogg")]
    assert len(row) == 1, out
    return [float(c) for c in row[0].strip().strip("|").split("|")[1:]]


def test_default_on_the_clip_is_measured_at_its_real_handover_and_the_threshold_sets_the_exit(capsys):
    """Centred on the handover (8k + 2, the beat warp's lag) the shipped default's ratio on the
    clip is 1.08 (the quicker movements alone 1.10, the speed matching alone 1.18, neither 1.31;
    see docs/testing.md); the guard is the target, 1.2 (docs/training.md), below the moderate
    seam of the next test."""
    ckpt = str(default_checkpoint_path())
    assert seams.handover_offset() == 2
    assert seams.main(["--checkpoint", ckpt, "--max", "1.2"]) == 0
    (ratio,) = _ratios(capsys.readouterr().out)
    assert 1.0 < ratio <= 1.2
    assert seams.main(["--checkpoint", ckpt, "--max", str(ratio - 0.01)]) == 1
    assert _ratios(capsys.readouterr().out) == [ratio]  # deterministic
    assert seams.main(["--checkpoint", ckpt, "--handover-offset", "2", "--max", "1.2"]) == 0
    assert _ratios(capsys.readouterr().out) == [ratio]


def test_a_moderate_seam_at_the_handover_is_caught(monkeypatch, capsys):
    """A shorter inertialization (3 frames instead of 16: each new movement's offset from the
    last decays within half a movement) leaves a moderate seam: 1.86 at the handover, caught;
    centred on the code step (offset 0) it reads 0.51, smoother than the dance. The speed
    matching is off here: it slows a movement whose bend adds speed, which hides much of a
    short bend's seam from the ratio (3 frames with it: 1.03; 2 frames: 1.42)."""
    import models.networks.player as ds

    ckpt = str(default_checkpoint_path())
    monkeypatch.setattr(ds, "DECAY_FRAMES", 3)
    monkeypatch.setattr(ds, "SPEED_MATCH", 0.0)
    assert seams.main(["--checkpoint", ckpt, "--max", "1.2"]) == 1
    (ratio,) = _ratios(capsys.readouterr().out)
    assert ratio > 1.2
    assert seams.main(["--checkpoint", ckpt, "--max", "1.2", "--handover-offset", "0"]) == 0
    assert _ratios(capsys.readouterr().out)[0] < 1.0


def test_missing_and_offline_checkpoints_are_refused(tmp_path, capsys):
    assert seams.main(["--checkpoint", str(tmp_path / "nope.pt")]) == 2
    assert "nope.pt" in capsys.readouterr().err
    violin = Path(__file__).resolve().parents[1] / "models" / "assets" / "violin.pt"
    assert seams.main(["--checkpoint", str(violin)]) == 2
    assert "only causal checkpoints" in capsys.readouterr().err
