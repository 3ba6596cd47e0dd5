"""A real live input: a private PulseAudio server (realtime/pulse.py) with a null sink, a shared song
played into it in real time, and ``performer run --input-device pulse`` capturing the sink's monitor
through PortAudio (ALSA's pulse plugin). The show desk's status (ws://.../desk) is read as the song
plays: its level meter against the song's RMS, the performer dancing to it, and idle when it stops.

Skips with the reason when PulseAudio (Debian pulseaudio, pulseaudio-utils, libasound2-plugins:
the Makefile's APT_PKGS) is missing or cannot start, or the shared songs are absent.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from test_desk import start_engine, stop_engine
from test_run_cli import free_port
from _ws_reader import JsonReader

from models.errors import AudioError

pytestmark = pytest.mark.serial  # a real-time PulseAudio input, read in real time: the serial pass of make test

SONG, SONG_BPM = "DANCE_C_2", 129.0  # a validation cha-cha (librosa: 129 bpm, docs/listening.md)
START_S, SECONDS = 30.0, 16.0  # the stretch of it played


@pytest.fixture(scope="module")
def pulse():
    from realtime.pulse import PulseServer

    try:
        server = PulseServer()
    except AudioError as exc:
        pytest.skip(f"no PulseAudio server for a live input: {exc}")
    yield server
    server.close()


@pytest.fixture(scope="module")
def song(dwm_root) -> np.ndarray:
    """(samples, 2) float32 at 44.1 kHz: SECONDS of the shared song from START_S."""
    import soundfile as sf

    path = dwm_root / SONG / "audio.mp3"
    if not path.is_file():
        pytest.skip(f"shared song {path} not found")
    x, rate = sf.read(str(path), dtype="float32", always_2d=True, start=int(START_S * 44100),
                      frames=int(SECONDS * 44100))
    assert rate == 44100
    return x


class Desk(JsonReader):
    """``/desk`` status messages read on a thread: (time.monotonic(), status)."""

    def __init__(self, port: int) -> None:
        super().__init__(f"ws://127.0.0.1:{port}/desk?format=json", "status")

    @property
    def statuses(self) -> list:
        return self.items


@pytest.fixture(scope="module")
def live(pulse, song, tmp_path_factory):
    """``performer run --input-device pulse`` on the server, its desk feed read; then the song played:
    yields (desk, the song's start and end, time.monotonic())."""
    port = free_port()
    log = tmp_path_factory.mktemp("live") / "engine.log"
    proc = start_engine(["--input-device", "pulse", "--no-osc", "--ws-viewers-open", "--warmup", "0.5", "--quiet"],
                        port, log, env=pulse.env)
    desk = Desk(port)
    deadline = time.monotonic() + 30
    while len(desk.statuses) < 10 and time.monotonic() < deadline:  # 2 s of silence heard first
        time.sleep(0.1)
    t0 = time.monotonic()
    player = pulse.play(song)
    player.wait(timeout=SECONDS + 20)
    t1 = time.monotonic()
    time.sleep(6.0)  # and silence after it
    yield desk, t0, t1
    desk.close()
    stop_engine(proc)


def test_live_input_is_captured_through_portaudio(live):
    desk, t0, t1 = live
    status = desk.between(t0, t1)[-1]
    assert status["input"] == "device:pulse" and status["state"] == "running"
    assert status["overruns"] == 0


def test_desk_level_matches_the_songs_rms_within_3_db(live, song):
    desk, t0, t1 = live
    mono = song.astype(np.float64).mean(axis=1)
    song_db = 10 * np.log10(np.mean(mono ** 2))
    levels = [s["level_dbfs"] for s in desk.between(t0 + 1.0, t1 - 0.5)]  # the meter's 0.3-s windows, inside the song
    desk_db = 10 * np.log10(np.mean(10 ** (np.asarray(levels) / 10)))  # their power mean
    assert len(levels) > 20
    print(f"desk level {desk_db:.2f} dBFS, the song's RMS {song_db:.2f} dBFS")  # shown with -s (docs/show.md)
    assert abs(desk_db - song_db) < 3.0, (desk_db, song_db)
    before = [s["level_dbfs"] for s in desk.between(t0 - 1.5, t0)]
    assert max(before) < -90  # the null sink's monitor is silent before the song


def test_performer_dances_to_the_live_song_and_idles_when_it_stops(live):
    desk, t0, t1 = live
    during = desk.between(t0, t1)
    started = next(t for t, s in desk.statuses if t >= t0 and s["performers"][0]["music"])
    print(f"music light {started - t0:.2f} s after the song's start")
    assert started - t0 < 2.0  # the music light within 2 s of the song's start
    dancing = [s["performers"][0] for s in desk.between(t0 + 3.0, t1)]
    assert all(p["music"] and p["idle_weight"] == 0 for p in dancing)
    tempi = np.array([s["performers"][0]["tempo_bpm"] for s in desk.between(t1 - 2.0, t1)])
    print(f"tempo {np.median(tempi):.1f} bpm in the song's last 2 s")
    # the song's tempo or half of it, each status of the song's last 2 s: the follower starts this song
    # at half time and moves to its tempo 7-14 s in, from the file as from the live input
    # (benchmarks/studies/live_input.py, docs/latency.md), so before its end the desk may show either
    # or a reading between them
    near = np.minimum(np.abs(tempi / SONG_BPM - 1), np.abs(2 * tempi / SONG_BPM - 1)) < 0.05
    assert len(tempi) > 3 and near.all(), tempi
    after = [s["performers"][0] for s in desk.between(t1 + 4.5, t1 + 6.0)]
    assert after and all(not p["music"] and p["idle_weight"] == 1 for p in after), after  # idle 2.9 s after silence
    # the engine keeps up with the live input, over the whole song: one status's "fps" counts the frames
    # of its own 0.2-s window, which the capture's block cadence on a loaded 2-core machine swings (24.9
    # once in CI); the mean of consecutive windows is the song's frames over its time
    fps = np.array([s["fps"] for s in desk.between(t0 + 1.0, t1)])
    print(f"fps mean {fps.mean():.2f}, least window {fps.min():.1f}")
    assert len(fps) > 20 and fps.mean() > 28.5, fps
