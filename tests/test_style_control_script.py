"""benchmarks/studies/style_control.py: style control measured with the evaluation's style classifier (issue 18)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
sc = load_script("benchmarks/studies/style_control.py")


def _motion(freq: float, frames: int = 256) -> np.ndarray:
    """FK-shaped positions (T, 30, 3): every point swings along x at ``freq`` Hz (a toy 'style')."""
    t = np.arange(frames) / 30.0
    pos = np.zeros((frames, 30, 3), np.float32)
    pos[:, :, 1] = np.linspace(0.0, 1.7, 30)
    pos[:, 1:, 0] += 0.3 * np.sin(2 * np.pi * freq * t)[:, None]
    return pos


@pytest.fixture(scope="module")
def toy_classifier():
    """A real StyleClassifier told apart slow (C) from fast (W) swinging, via the evaluation's own windows."""
    from models.evaluation.classifier import train_style_classifier
    from models.evaluation.evaluate import classifier_windows

    slow, fast = classifier_windows([_motion(0.5)]), classifier_windows([_motion(3.0)])
    x = np.concatenate([slow, fast])
    y = np.concatenate([np.zeros(len(slow), np.int64), np.full(len(fast), 2, np.int64)])
    return train_style_classifier(x, y, epochs=8, seed=0, class_names=["C", "R", "W"])


def test_shares_follow_the_requested_style(toy_classifier):
    freq = {None: 3.0, "chacha": 0.5, "rumba": 0.5, "waltz": 3.0}  # rumba is 'not controlled' here
    songs = [("DANCE_C_1", "C", _motion(0.5)), ("DANCE_W_1", "W", _motion(3.0))]
    calls = []

    def generate(name, style):
        calls.append((name, style))
        return _motion(freq[style])

    res = sc.measure(toy_classifier, songs, generate)
    assert calls == [(n, r) for n, _, _ in songs for r in sc.REQUESTS]
    for row in res.values():
        assert set(row) == {"style", "real", "auto", "chacha", "rumba", "waltz"}
        for col in ("real", "auto", "chacha", "rumba", "waltz"):
            assert sum(row[col].values()) == pytest.approx(1.0)
    assert res["DANCE_C_1"]["chacha"]["C"] == 1.0 and res["DANCE_W_1"]["waltz"]["W"] == 1.0
    s = sc.summary(res)
    assert s["real"]["songs_clear"] == 2 and s["chacha"]["songs_clear"] == 2 and s["waltz"]["songs_clear"] == 2
    assert s["rumba"]["songs_clear"] == 0 and s["rumba"]["min_margin"] == -1.0
    assert s["auto"]["songs_clear"] == 1  # the C song's auto dance came out fast (W)
    text = sc.table(res)
    assert "| DANCE_C_1 (C) | 1.00 (+1.00) |" in text and "| songs won by >= 0.2 | 2/2 | 1/2 | 2/2 | 0/2 | 2/2 |" in text


def test_several_seeds_pool_every_song_seed_as_a_row():
    row = {"style": "C", "real": {"C": 1.0, "R": 0.0, "W": 0.0}}
    runs = {0: {"DANCE_C_2": {**row, "chacha": {"C": 0.9, "R": 0.1, "W": 0.0}}},
            1: {"DANCE_C_2": {**row, "chacha": {"C": 0.4, "R": 0.5, "W": 0.1}}}}
    pooled = sc.pool(runs)
    assert list(pooled) == ["DANCE_C_2 seed 0", "DANCE_C_2 seed 1"]
    s = sc.summary(pooled, requests=("chacha",))["chacha"]
    assert s["songs"] == 2 and s["songs_clear"] == 1 and s["mean_share"] == pytest.approx(0.65)
    text = sc.seeds_table(runs, requests=("chacha",))
    assert "| 0 | 1.000 (1/1) | 0.900 (1/1) |" in text and "| all | 1.000 (2/2) | 0.650 (1/2) |" in text


def test_style_letters_and_margin():
    assert [sc.style_letter(s) for s in ("chacha", "rumba", "waltz")] == ["C", "R", "W"]
    assert sc.margin({"C": 0.5, "R": 0.3, "W": 0.2}, "C") == pytest.approx(0.2)
    assert sc.margin({"C": 0.5, "R": 0.3, "W": 0.2}, "W") == pytest.approx(-0.3)


def test_a_margin_of_exactly_the_threshold_counts():
    """42 of 70 windows against 28 is a margin of 0.2 (0.19999999999999996 in floats): the song is won."""
    row = {"style": "C", "real": {"C": 1.0, "R": 0.0, "W": 0.0}, "chacha": {"C": 42 / 70, "R": 28 / 70, "W": 0.0}}
    assert sc.summary({"DANCE_C_2": row}, requests=("chacha",))["chacha"]["songs_clear"] == 1


def test_too_short_a_dance_is_a_data_error(toy_classifier):
    from models.errors import DataError

    with pytest.raises(DataError, match="shorter than one"):
        sc.window_shares(toy_classifier, _motion(1.0, frames=40))


@pytest.mark.parametrize("args, message", [
    (["--data", "x", "--margin", "1.5"], "--margin must be in [0, 1)"),
    (["--data", "x", "--threads", "0"], "--threads must be >= 1"),
    (["--data", "x", "--guidance", "0"], "--guidance must be > 0"),
    (["--data", "x", "--styles", "tango"], "invalid choice: 'tango'"),
    (["--data", "x", "--checkpoint", "/nonexistent/model.pt"], "style_control.py: "),
    (["--data", "x", "--checkpoint", str(REPO / "models" / "assets" / "dtm.pt")], "takes no style"),
])
def test_bad_input_is_one_line_and_exit_2(args, message, capsys, tmp_path):
    out = tmp_path / "s.json"
    try:
        code = sc.main([*args, "--json", str(out)])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.data
def test_default_checkpoint_wins_its_styles_on_the_validation_split(dwm_root, tmp_path):
    """The shipped default danced in each style to the 6 validation songs (seed 0): waltz and
    rumba win every song by the documented margin (0.2; docs/training.md, "Style"), and
    cha-cha wins at least 3 songs by 0.15 (docs/testing.md has the measured margins). With
    the guidance and the prior off (``STYLE_GUIDANCE = 1.0``, ``STYLE_PRIOR = 0.0``) waltz
    loses the cha-cha and rumba songs, rumba the waltz songs, and cha-cha wins by 0.15 on
    one song."""
    out = tmp_path / "s.json"
    assert sc.main(["--data", str(dwm_root), "--cache", str(REPO / ".cache" / "corpus"), "--json", str(out)]) == 0
    import json

    d = json.loads(out.read_text())["runs"]["0"]
    assert len(d["songs"]) == 6 and set(d["summary"]) == {"real", "auto", "chacha", "rumba", "waltz"}
    s = d["summary"]
    won = {k: f"{v['songs_clear']}/{v['songs']} (smallest margin {v['min_margin']:+.2f})" for k, v in s.items()}
    assert s["waltz"]["songs_clear"] == 6 and s["rumba"]["songs_clear"] == 6, won
    chacha = [sc.margin(row["chacha"], "C") for row in d["songs"].values()]
    assert sum(m >= 0.15 for m in chacha) >= 3, f"cha-cha margins {np.round(chacha, 2)}"
    assert s["real"]["songs_clear"] == 6, won  # the judge reads the real dancers right


@pytest.mark.slow
@pytest.mark.data
def test_the_guidance_makes_cha_cha_win_more_songs(dwm_root, tmp_path):
    """Cha-cha requested on the 6 validation songs with seeds 0-4 (30 song-seeds), with the
    shipped classifier-free guidance and without it (``--guidance 1``; the style prior and the
    style's own dancers on in both): with it the cha-cha share is at least 0.02 higher and more
    songs are won by 0.2 (0.622 against 0.578, 15 against 11; docs/training.md, "Style"). Fails
    when ``STYLE_GUIDANCE`` is 1.0: the two runs are then the same."""
    import json

    argv = ["--data", str(dwm_root), "--cache", str(REPO / ".cache" / "corpus"), "--styles", "chacha",
            "--seed", "0", "1", "2", "3", "4"]
    chacha = {}
    for name, extra in (("guided", []), ("unguided", ["--guidance", "1"])):
        out = tmp_path / f"{name}.json"
        assert sc.main([*argv, *extra, "--json", str(out)]) == 0
        chacha[name] = json.loads(out.read_text())["summary"]["chacha"]
    with_, without = chacha["guided"], chacha["unguided"]
    assert with_["songs"] == without["songs"] == 30
    assert with_["mean_share"] >= without["mean_share"] + 0.02, chacha
    assert with_["songs_clear"] > without["songs_clear"], chacha
