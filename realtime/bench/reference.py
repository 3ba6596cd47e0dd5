"""The machine's speed during a benchmark run, and an injected regression to prove the budgets catch one.

:class:`ReferenceProbe` times a fixed workload (:func:`reference_workload`: NumPy spectra,
a mel-like projection and small dense layers, and Python-level packing as the OSC encoder
does: the kinds of work a hop does) once per frame inside the performer process under test,
half-way between two hops, so it runs on the same CPUs, at the same moments and under the
same load as the hops it is compared with, and never overlaps one. Its wall and CPU times
(p50, p99, ms) go into the run's result: the budgets on ``lane_cycle_over_reference`` divide
the costliest point of the performers' cost cycle by its CPU median
(:func:`realtime.bench.suite.lane_cycle_ms`; docs/latency.md, "Budgets on a shared
machine"): a machine that is slower today (a busy sibling core, a slow CPU) slows the
reference too, a slower hop on the same machine does not.

:class:`InjectedWork` is the hidden testing hook: a sink that spins ``ms`` of CPU every
``every``-th frame in one performer's lane (``performer bench ensemble --inject-ms 1
--inject-every 8``), inside the lane's timed part as a slower model or encoder would be.
"""

from __future__ import annotations

import struct
import threading
import time

import numpy as np

from realtime.frame import PoseFrame

#: When the probe runs, after a frame was sent: blocks of 512 samples at 44.1 kHz complete
#: a frame every 23.2 or 34.8 ms, so a workload of ~1 ms started 8 ms after a send ends
#: well before the next hop starts.
PROBE_DELAY_S = 0.008

_RNG = np.random.default_rng(1234)
_SIGNAL = _RNG.standard_normal(4 * 2048).astype(np.float32)
_WINDOW = np.hanning(2048).astype(np.float32)
_MEL = np.abs(_RNG.standard_normal((128, 1025))).astype(np.float32) / 1025.0
_LAYERS = [(_RNG.standard_normal((256, 256)) / 16.0).astype(np.float32) for _ in range(4)]
_POSE = _RNG.standard_normal(3 + 21 * 4).astype(np.float32)
_BONE = struct.Struct(">ffff")


def reference_workload() -> float:
    """One fixed unit of hop-like work (about 1 ms on the 2-core reference machine); returns a
    checksum so that nothing is optimised away. Same inputs every call."""
    frames = _SIGNAL.reshape(4, 2048) * _WINDOW
    spec = np.abs(np.fft.rfft(frames, axis=1)) ** 2  # (4, 1025) power spectra
    mel = np.log1p(spec @ _MEL.T)  # (4, 128)
    x = np.tile(mel, (4, 2))[:16, :256]  # (16, 256): a window of feature frames
    for w in _LAYERS:
        x = np.tanh(x @ w)
    packed = b"".join(_BONE.pack(*map(float, _POSE[3 + 4 * j: 7 + 4 * j])) for j in range(21))
    return float(x.sum()) + len(packed)


class ReferenceProbe:
    """A sink that times :func:`reference_workload` on a thread of its own, ``delay_s`` after
    each frame it is sent (a frame arriving while one is pending is skipped, never queued).

    Put it last in the last lane, so that it fires once per hop after every performer sent.
    ``times_ms()``: the wall time of each run, ms; ``cpu_times_ms()``: its thread's CPU time
    in each run, ms (no time waiting for a CPU or for the interpreter lock).
    """

    name = "reference"

    def __init__(self, delay_s: float = PROBE_DELAY_S) -> None:
        self.delay_s = delay_s
        self._times: list[float] = []
        self._cpu: list[float] = []
        self._go = threading.Event()
        self._stop = False
        reference_workload()  # first call outside the timing: allocations, BLAS start-up
        self._thread = threading.Thread(target=self._run, name="reference probe", daemon=True)
        self._thread.start()

    def send(self, frame: PoseFrame) -> None:
        self._go.set()

    def _run(self) -> None:
        while True:
            self._go.wait()
            if self._stop:
                return
            time.sleep(self.delay_s)
            self._go.clear()
            t, c = time.perf_counter(), time.thread_time()
            reference_workload()
            self._cpu.append((time.thread_time() - c) * 1000.0)
            self._times.append((time.perf_counter() - t) * 1000.0)

    def times_ms(self) -> list[float]:
        return list(self._times)

    def cpu_times_ms(self) -> list[float]:
        return list(self._cpu)

    def close(self) -> None:
        self._stop = True
        self._go.set()
        self._thread.join(timeout=2.0)

    def stats(self) -> dict[str, float]:
        return {"runs": float(len(self._times))}


class InjectedWork:
    """A sink that spins ``ms`` milliseconds of CPU (holding the interpreter, as Python work
    does) on the frames whose index is a multiple of ``every``: a regression planted in one
    lane. With ``every`` = 8, the dance_vq cost cycle, those are the first performer's code-step
    frames (phase 0), the hops that set the p99, as a slower predictor would be."""

    name = "injected-work"

    def __init__(self, ms: float, every: int) -> None:
        if ms <= 0 or every < 1:
            raise ValueError(f"injected work needs ms > 0 and every >= 1, got {ms} ms every {every}")
        self.seconds, self.every, self.frames, self.injected = ms / 1000.0, every, 0, 0

    def send(self, frame: PoseFrame) -> None:
        self.frames += 1
        if frame.index % self.every == 0:
            end = time.perf_counter() + self.seconds
            while time.perf_counter() < end:
                pass
            self.injected += 1

    def close(self) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {"frames": float(self.frames), "injected": float(self.injected)}
