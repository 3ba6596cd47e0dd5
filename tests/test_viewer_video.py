"""benchmarks/studies/viewer_video.py: a 1-s, tiny side-by-side recording of the real web viewer.

Needs Debian's chromium, the playwright package, the built viewer (clients/web/dist)
and the shared dataset; skips with the reason when one is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.generate import default_checkpoint_path

from script_loader import load_script

REPO = Path(__file__).resolve().parents[1]
vv = load_script("benchmarks/studies/viewer_video.py")


@pytest.fixture
def can_record():
    if not vv.CHROMIUM.is_file():
        pytest.skip(f"{vv.CHROMIUM} not installed (apt-get install chromium; 'make test' does it)")
    try:
        import playwright  # noqa: F401
    except ImportError:
        pytest.skip("the playwright Python package is not installed (pip install -e '.[dev]')")
    if not (REPO / "clients" / "web" / "dist" / "index.html").is_file():
        pytest.skip("clients/web/dist is not built ('make web')")


@pytest.mark.slow
@pytest.mark.data
def test_one_second_clip_has_every_picture_and_both_performers_move(can_record, dwm_root, tmp_path, capsys):
    from PIL import Image

    size, fps = (160, 120), 10
    out = tmp_path / "clip.gif"
    rc = vv.main(["--checkpoint", str(default_checkpoint_path()), "--data", str(dwm_root), "--dance", "DANCE_C_2",
                  "--start-s", "30", "--seconds", "1", "--fps", str(fps), "--size", f"{size[0]}x{size[1]}",
                  "--out", str(out), "--cache", str(REPO / ".cache" / "corpus"), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    top, bottom, _ = vv.bands(size)
    with Image.open(out) as gif:
        assert gif.n_frames == fps  # 1 s at 10 pictures per second
        assert gif.size == (2 * size[0], top + size[1] + bottom)
        frames, total_ms = [], 0
        for i in range(gif.n_frames):
            gif.seek(i)
            total_ms += gif.info["duration"]
            frames.append(np.asarray(gif.convert("RGB"), dtype=np.int16)[top : top + size[1]])  # the viewers only
    assert total_ms == 1000
    for name, half in (("real", slice(0, size[0])), ("generated", slice(size[0], 2 * size[0]))):
        pictures = [f[:, half] for f in frames]
        changed = [np.any(a != b) for a, b in zip(pictures, pictures[1:])]
        # Each performer moves: its viewer's picture changes from picture to picture.
        assert sum(changed) >= len(changed) - 1, f"{name} side static in {changed.count(False)} of {len(changed)} steps"
        assert np.abs(pictures[0] - pictures[-1]).sum() > 0, f"{name} side did not move in 1 s"
    # The two sides show different performers.
    assert np.any(frames[0][:, : size[0]] != frames[0][:, size[0] :])


def test_tempo_sides_start_at_the_same_moment_of_the_song_and_keep_its_beats(tmp_path):
    """--tempo: frame ``start`` of both sides is song time --start-s; a beat of the song falls on
    the same song time on both sides (each side's frames count stretched time)."""
    import soundfile as sf

    from models.features.audio_io import bundled_clip_path, load_audio

    song, sr = load_audio(bundled_clip_path(), 22050)
    sf.write(tmp_path / "song.wav", song[: 16 * sr], sr)
    a = vv.parse_args(["--tempo", "0.8,1.25", "--audio", str(tmp_path / "song.wav"), "--start-s", "6",
                       "--seconds", "6", "--checkpoint", str(default_checkpoint_path()), "--out", str(tmp_path / "t.gif")])
    tr = vv.load_tempo_tracks(a)
    assert tr.rates == (0.8, 1.25) and tr.start == int(round(6 / 1.25 * 30)) - 1
    assert len(tr.real) >= tr.start + tr.frames and len(tr.generated) >= tr.start + tr.frames
    song_s = [tr.tempo_start_s + (b[(b >= tr.start) & (b < tr.start + tr.frames)] - tr.start) / 30 * r
              for b, r in zip(tr.side_beats, tr.rates)]
    both = song_s[0][song_s[0] < 6 + 6 * 0.8 - 0.5]  # the song the slower side heard
    assert len(both) >= 6  # 120 bpm: a beat every 0.5 s of song
    nearest = np.min(np.abs(both[:, None] - song_s[1][None, :]), axis=1)
    assert np.median(nearest) < 0.07  # the same beats, within two frames
    assert not np.allclose(tr.real[tr.start], tr.generated[tr.start])  # two performances


def test_bad_options_are_refused(capsys):
    for argv in (["--fps", "60"], ["--seconds", "0"], ["--size", "big"], ["--out", "x.mp4"], ["--tempo", "0.8"],
                 ["--tempo", "0.8,x"], ["--audio", "a.ogg"], ["--stage", "6y5"], ["--stage", "3x2", "--tempo", "1,2"]):
        with pytest.raises(SystemExit) as exc:
            vv.parse_args(argv)
        assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--out must be a .gif" in err and "--tempo takes two rates" in err and "--audio works with --tempo" in err
    assert "--stage: stage must be WxD" in err and "--stage works without --tempo" in err


def test_on_a_stage_both_dancers_travel_and_the_real_one_as_recorded(dwm_root, tmp_path):
    """--stage: the performer's poses travel on the stage, the real dancer's keep the recorded travel
    (centred on the span), and the stage goes to both pages."""
    a = vv.parse_args(["--checkpoint", str(default_checkpoint_path()), "--data", str(dwm_root), "--dance", "DANCE_C_2",
                       "--start-s", "30", "--seconds", "4", "--stage", "6x5", "--cache", str(REPO / ".cache" / "corpus")])
    t = vv.load_tracks(a)
    assert t.stage == (6.0, 5.0)
    span = slice(t.start, t.start + t.frames)
    for poses in (t.real, t.generated):
        xz = poses[span][:, [0, 2]]
        assert np.ptp(xz, axis=0).max() > 0.2  # both travel
    np.testing.assert_allclose(t.real[span][:, [0, 2]].mean(0), 0.0, atol=1e-5)
    assert np.abs(t.generated[:, [0, 2]]).max(0).tolist() <= [3.0, 2.5]  # inside the stage
