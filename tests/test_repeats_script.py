"""benchmarks/studies/repeats.py: runs of one code, the dancers' against the performer's (docs/training.md, "How it dances")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
rs = load_script("benchmarks/studies/repeats.py")


def test_runs_are_counted_in_order_and_summarised_as_shares_of_movements():
    runs = rs.run_lengths([5, 5, 5, 2, 7, 7, 5])
    assert runs.tolist() == [3, 1, 2, 1]
    assert rs.run_lengths([]).size == 0
    s = rs.run_summary(np.array([12, 1, 4, 3]))
    assert s["longest"] == 12 and s["movements"] == 20
    assert s["share_ge_4"] == 16 / 20 and s["share_ge_8"] == 12 / 20 and s["share_ge_12"] == 12 / 20


def test_the_performer_on_the_bundled_clip_counts_every_movement_and_shuffles_little():
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model

    lm = load_model(None)
    y = load_audio("models/assets/clip.ogg")[0][: 20 * 22050]
    frames = len(extract_features(y, lm.features))
    got = rs.perform(lm, y, seed=1)
    assert int(got["runs"].sum()) == -(-frames // lm.model.config.seg)  # a code every 8 frames
    assert 0.8 * frames < got["dancing"] <= frames  # music all the way: dancing after the fade-in
    assert got["shuffle"] <= 0.05 * got["dancing"]


def test_a_missing_checkpoint_is_a_clear_error(capsys):
    assert rs.main(["--data", str(REPO), "--checkpoint", "/nonexistent/model.pt"]) == 2
    assert "repeats: " in capsys.readouterr().err
