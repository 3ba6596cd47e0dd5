"""The engine's worker hands a frame to the publisher process without waking it: a wake-up on
the worker's CPU ran the publisher inside the worker's ``os.write`` (docs/audience.md)."""

from __future__ import annotations

import os
import sys
import time

import numpy as np
import pytest

from models.rig.motion import POSE_DIM
from realtime.frame import PoseFrame
from realtime.nats_server import free_port
from realtime.publish_process import BrokerProcess

pytestmark = [pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs Linux (/proc, sched_setaffinity)"),
              pytest.mark.serial]  # which CPU a thread runs on, timed: the serial pass of make test


def _preemptions() -> int:
    """This thread's involuntary context switches so far (/proc)."""
    for line in open("/proc/thread-self/status"):
        if line.startswith("nonvoluntary_ctxt_switches:"):
            return int(line.split()[1])
    return 0


def test_sending_a_frame_does_not_run_the_publisher_on_the_workers_cpu() -> None:
    """The worker and the publisher process share one CPU (a performer pinned to a core); the
    worker sends 200 frames, each between two stretches of its own work. Counted: sends
    during which the worker was preempted. A publisher that the write wakes runs at once and
    preempts nearly every send (190 of 200); one that polls the pipe, or one woken under
    SCHED_BATCH, preempts none (others' programs on the machine may take a few: 2 and 13)."""
    cpu = min(os.sched_getaffinity(0))
    every = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cpu})
    # no broker at the port: the child still reads every frame from the pipe
    pub = BrokerProcess(f"nats://127.0.0.1:{free_port()}", connect_wait=0.1, offsets=np.zeros((21, 3)))
    try:
        for tid in os.listdir(f"/proc/{pub._proc.pid}/task"):
            os.sched_setaffinity(int(tid), {cpu})
        route = pub.route("main", "performer.main")
        pose = np.zeros(POSE_DIM, np.float32)
        preempted = 0
        for i in range(200):
            t = time.thread_time()
            while time.thread_time() - t < 0.0005:  # the worker's own work before the send
                pass
            before = _preemptions()
            route.send(PoseFrame(index=i, audio_sample=0, audio_time=0.0, wall_time=0.0, pose=pose))
            preempted += _preemptions() > before
            time.sleep(0.005)
        time.sleep(0.3)
        assert route.frames == 200
    finally:
        pub.close()
        os.sched_setaffinity(0, every)
    print(f"\nsends preempted by the publisher: {preempted} of 200")
    assert preempted < 40, f"{preempted} of 200 sends were preempted"


def _policies(pid: int) -> set[int]:
    return {os.sched_getscheduler(int(tid)) for tid in os.listdir(f"/proc/{pid}/task")}


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_a_pinned_performers_publisher_runs_on_the_other_cpus_under_sched_batch() -> None:
    """``performer run`` pinned to one CPU (taskset): its publisher process goes to the CPUs the
    performer does not use (publish_cpus = "auto"), every thread of it under SCHED_BATCH;
    publish_cpus names the CPUs otherwise (here the performer's own)."""
    from realtime.config import RunConfig
    from realtime.publish_process import open_routes

    every = os.sched_getaffinity(0)
    cpu = min(every)
    url = f"nats://127.0.0.1:{free_port()}"  # no broker: the process starts and waits for one
    os.sched_setaffinity(0, {cpu})
    try:
        for spec, want in (("auto", every - {cpu}), (str(cpu), {cpu})):
            cfg = RunConfig(publish=url, publish_cpus=spec, no_osc=True, no_ws=True).validate()
            (route,) = open_routes(cfg, ["main"])
            try:
                pid = route.owner._proc.pid
                time.sleep(0.3)  # its connection thread is up
                assert set(route.owner.cpus) == want, spec
                assert all(os.sched_getaffinity(int(t)) == want for t in os.listdir(f"/proc/{pid}/task")), spec
                assert _policies(pid) == {os.SCHED_BATCH}, spec
            finally:
                route.close()
    finally:
        os.sched_setaffinity(0, every)


@pytest.mark.parametrize("spec", ["x", "1-0", "-1", ""])
def test_a_bad_publish_cpus_is_one_line_naming_it(spec: str) -> None:
    from models.errors import ConfigError
    from realtime.config import RunConfig

    with pytest.raises(ConfigError, match="publish_cpus") as info:
        RunConfig(publish_cpus=spec).validate()
    assert "\n" not in str(info.value)
