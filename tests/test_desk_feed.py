"""The show desk's feed without a browser (realtime/desk.py): the level meter on the audio ring, the
outputs' states, and the status message of a real engine with a real WebSocket server."""

from __future__ import annotations

import json
import math
import time

import numpy as np
from _ws_reader import JsonReader
from test_run_cli import clip  # noqa: F401 - fixture

from realtime.audio_input import RingBuffer
from realtime.desk import FLOOR_DBFS, receiver_state, ring_level


def test_level_meter_reads_the_newest_samples_across_the_rings_wrap():
    ring = RingBuffer(1000, channels=2)
    assert ring_level(ring, 0.1, 1000) == (FLOOR_DBFS, FLOOR_DBFS)  # nothing yet
    ring.write(np.full((900, 2), 0.9, np.float32))  # loud, then read away
    ring.read_into(np.zeros((900, 2), np.float32))
    t = np.arange(300) / 1000.0
    sine = (0.5 * np.sin(2 * math.pi * 50 * t)).astype(np.float32)
    ring.write(np.stack([sine, sine], axis=1))  # wraps: 100 at the end, 200 at the start
    rms, peak = ring_level(ring, 0.3, 1000)
    assert abs(rms - 20 * math.log10(0.5 / math.sqrt(2))) < 0.05  # -9.03 dBFS, the sine only
    assert abs(peak - 20 * math.log10(0.5)) < 0.05
    ring.write(np.stack([sine, -sine], axis=1)[:100])  # channels in antiphase: the mono mix is silent
    assert ring_level(ring, 0.1, 1000)[0] == FLOOR_DBFS


def test_outputs_are_named_by_their_state():
    assert receiver_state("osc:127.0.0.1:39539", {"no_receiver": 1.0}) == "no receiver"
    assert receiver_state("osc:127.0.0.1:39539", {"no_receiver": 0.0, "sent": 10}) == "sending"
    assert receiver_state("ws:127.0.0.1:8765", {"clients": 1}) == "1 client"
    assert receiver_state("ws:127.0.0.1:8765/ws/bob", {"clients": 3}) == "3 clients"


def test_a_desk_gets_status_and_no_frames_and_the_engine_sends_nothing_without_one(clip):  # noqa: F811
    from realtime.audio_input import FileSource
    from realtime.desk import start_desk
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    pipe = build_pipeline(None, seed=0)
    sink = WebSocketSink("127.0.0.1", 0)
    engine = Engine(FileSource.open(clip, realtime=True, loop=True), pipe.extractor_factory, pipe.model, [sink],
                    EngineConfig(warmup_s=0.2))
    engine.start()
    feed = start_desk(engine, [sink])
    try:
        time.sleep(1.0)
        assert feed.sent == 0  # no desk open: nothing built or sent
        desk = JsonReader(f"ws://127.0.0.1:{sink.port}/desk?format=json", "status")
        frames = JsonReader(f"ws://127.0.0.1:{sink.port}/desk?format=json", "frame")
        time.sleep(2.0)
        statuses = [s for _, s in desk.items]
        assert 6 <= len(statuses) <= 14 and not frames.items  # 5 a second, and never a pose frame
        last = statuses[-1]
        json.dumps(last, allow_nan=False)
        p = last["performers"][0]
        assert p["name"] == "performer" and p["energy"] == 1.0 and p["style"] == "auto" and p["stage"] is not None
        assert last["level_dbfs"] > -40 and p["receivers"][0]["state"] == "2 clients"
        # about 30 frames a second: the mean of the statuses' 0.2-s windows (one window alone swings with the
        # source's block cadence on a busy machine)
        fps = [s["fps"] for s in statuses if s["fps"] is not None]
        assert len(fps) >= 5 and sum(fps) / len(fps) > 24, fps
        desk.close()
        frames.close()
    finally:
        feed.close()
        engine.close()
