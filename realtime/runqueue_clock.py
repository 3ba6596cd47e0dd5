"""The bench's own-time clock: how long this process waited for CPUs other processes held.

``performer bench`` reports each hop's "own" time, its wall time less the run-queue waits of the
process during it (docs/latency.md, "Budgets on a shared machine"); :class:`RunQueueClock` reads
those waits from Linux's schedstat, :func:`hop_wait` books them to a hop. ``performer run`` never
creates one (``EngineConfig.runqueue_wait`` is the bench's). A leaf: no project imports.
"""

from __future__ import annotations

import time


class RunQueueClock:
    """Run-queue waits of this process (Linux, /proc/self/task/*/schedstat: per thread, ns on
    a CPU and ns runnable but waiting for one); (0, 0) where they cannot be read. Create it on
    the thread whose hops it measures (the engine's worker).

    Calling it returns ``(waited, on_cpu)`` in seconds: the waits of every thread of the
    process added up (the worker's own, and those of a thread that holds the interpreter lock
    the worker needs while another process has the CPU), and the calling thread's CPU time.
    ``after=True`` (the read that ends a hop) reads the calling thread's CPU time first, the
    others' waits after, so that neither read's own work is booked to the hop. Every file stays
    open: a read is one ``pread`` each, no open/close (docs/latency.md, input_stage.py).
    """

    _REFRESH_S = 1.0  # how often the thread list is read again

    def __init__(self) -> None:
        import os

        self._os = os
        self._fds: dict[str, int] = {}  # thread id -> its schedstat, open
        self._listed = -1e9
        try:
            self._me: int | None = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
        except OSError:
            self._me = None

    def _relist(self) -> None:
        """Open the schedstat of threads that started, close those of threads that ended."""
        try:
            tids = set(self._os.listdir("/proc/self/task"))
        except OSError:
            tids = set()
        for tid in list(self._fds):
            if tid not in tids:
                self._os.close(self._fds.pop(tid))
        for tid in tids - self._fds.keys():
            try:
                self._fds[tid] = self._os.open(f"/proc/self/task/{tid}/schedstat", self._os.O_RDONLY)
            except OSError:
                pass  # a thread that ended

    def _waits(self) -> int:
        waited = 0
        for tid, fd in list(self._fds.items()):
            try:
                waited += int(self._os.pread(fd, 128, 0).split()[1])
            except (OSError, ValueError, IndexError):  # a thread that ended
                self._os.close(self._fds.pop(tid))
        return waited

    def _own(self) -> int:
        try:
            return int(self._os.pread(self._me, 128, 0).split()[0])
        except (OSError, ValueError, IndexError):
            return 0

    def __call__(self, after: bool = False) -> tuple[float, float]:
        if self._me is None:
            return 0.0, 0.0
        if after:
            on_cpu = self._own()
            return self._waits() * 1e-9, on_cpu * 1e-9
        now = time.monotonic()
        if now - self._listed > self._REFRESH_S:
            self._relist()
            self._listed = now
        waited = self._waits()
        return waited * 1e-9, self._own() * 1e-9

    def __del__(self) -> None:
        for fd in self._fds.values():
            self._os.close(fd)
        self._fds = {}
        if self._me is not None:
            self._os.close(self._me)
            self._me = None


def hop_wait(wall: float, waited: float, on_cpu: float) -> float:
    """The part of a hop's ``wall`` seconds spent waiting for CPUs other processes held: the
    process's run-queue waits during it, never so much that less than the worker's own CPU
    time ``on_cpu`` would be left (another thread's wait need not have held the worker up)."""
    return max(0.0, min(waited, wall - on_cpu))
