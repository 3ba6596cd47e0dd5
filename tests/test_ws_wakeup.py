"""The engine's worker hands a frame to the WebSocket server's thread without being preempted by
it: ``call_soon_threadsafe`` wakes the loop's thread, and the kernel ran that thread at once on
the worker's CPU (a wake-up preemption) until it ran under SCHED_BATCH (realtime/sched.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from test_publish_wakeup import _preemptions

from models.rig.motion import POSE_DIM
from realtime.frame import PoseFrame
from realtime.ws_server import WebSocketSink

pytestmark = [pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs Linux (/proc, sched_setaffinity)"),
              pytest.mark.serial]  # which CPU a thread runs on, timed: the serial pass of make test


def _spin(seconds: float) -> None:
    t = time.thread_time()
    while time.thread_time() - t < seconds:
        pass


_VIEWER = """
import sys
from websockets.sync.client import connect
n = 0
with connect(sys.argv[1]) as ws:
    ws.recv(timeout=10)  # the hello
    print("ready", flush=True)
    try:
        while True:
            ws.recv(timeout=5)
            n += 1
    except Exception:
        pass
print(n, flush=True)
"""


def test_handing_a_frame_to_the_ws_thread_does_not_preempt_the_worker() -> None:
    """The worker and the server's thread share one CPU (a performer pinned to a core); a viewer
    (a process of its own, on another CPU where there is one) takes every frame. The worker
    hands over 400 frames as the engine does (begin_hop, send, end_hop) between stretches of
    its own work; counted: hand-offs during which the worker was preempted. In blocks of 20,
    taken in turns, the server thread runs as shipped or as a normal (SCHED_OTHER) thread, so
    the machine's load (others' programs) falls on both alike. As a normal thread it preempted
    about 3 in 4 hand-offs; under SCHED_BATCH about 1 in 10 (others' programs)."""
    cpu = min(os.sched_getaffinity(0))
    every = os.sched_getaffinity(0)
    others = every - {cpu}
    os.sched_setaffinity(0, {cpu})
    sink = WebSocketSink("127.0.0.1", 0, offsets=np.zeros((21, 3)))
    tid = sink._thread.native_id
    counts = {"shipped": 0, "normal": 0}
    viewer = None
    try:
        os.sched_setaffinity(tid, {cpu})
        shipped = os.sched_getscheduler(tid)  # SCHED_BATCH (realtime/sched.py)
        viewer = subprocess.Popen([sys.executable, "-c", _VIEWER, sink.ws_url], stdout=subprocess.PIPE, text=True)
        if others:
            os.sched_setaffinity(viewer.pid, others)
        assert viewer.stdout.readline().strip() == "ready"
        time.sleep(0.2)
        pose = np.zeros(POSE_DIM, np.float32)
        for i in range(400):
            mode = "shipped" if (i // 20) % 2 == 0 else "normal"
            if i % 20 == 0:
                os.sched_setscheduler(tid, shipped if mode == "shipped" else os.SCHED_OTHER, os.sched_param(0))
                time.sleep(0.01)
            _spin(0.0005)  # the worker's own work before the hand-off
            before = _preemptions()
            sink.begin_hop()
            sink.send(PoseFrame(index=i, audio_sample=0, audio_time=0.0, wall_time=0.0, pose=pose))
            sink.end_hop()
            _spin(0.0002)  # the rest of the hop
            counts[mode] += _preemptions() > before
            time.sleep(0.005)
    finally:
        sink.close()
        os.sched_setaffinity(0, every)
    got = int(viewer.communicate(timeout=30)[0].strip().splitlines()[-1])
    print(f"\nhand-offs preempted, of 200 each: {counts['shipped']} as shipped, {counts['normal']} as a normal thread")
    assert got == 400, f"the viewer got {got} of 400 frames"
    assert counts["shipped"] < max(20, counts["normal"] / 2), counts
