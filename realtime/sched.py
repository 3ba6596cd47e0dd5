"""Keeping helper threads and processes off the engine worker's back (Linux scheduling).

A thread the worker wakes mid-hop (the WebSocket server's loop, woken by
``call_soon_threadsafe``; the publisher process) was run by the kernel on the worker's CPU at
once, preempting the worker inside its hand-off (docs/audience.md). Under ``SCHED_BATCH`` a
woken thread never preempts a running one (it waits for the next tick or for the CPU to free
up); it keeps its fair share of the CPU. :func:`batch` puts a thread there;
:func:`publisher_cpus` says where the publisher process goes. Where the calls do not exist
(not Linux) they do nothing.
"""

from __future__ import annotations

import os

from models.errors import ConfigError

#: ``publish_cpus`` default: off the CPUs the performer is pinned to, if it is pinned.
AUTO = "auto"


def batch(tid: int = 0) -> bool:
    """``SCHED_BATCH`` for thread ``tid`` (0: the calling thread; threads it starts inherit it).
    False where it cannot be set (not Linux, or refused)."""
    try:
        os.sched_setscheduler(tid, os.SCHED_BATCH, os.sched_param(0))
    except (AttributeError, OSError):
        return False
    return True


def batch_process(pid: int) -> bool:
    """``SCHED_BATCH`` for every thread of process ``pid`` (threads it starts later inherit it)."""
    return all([batch(tid) for tid in _threads(pid)])


def is_batch(tid: int = 0) -> bool:
    """Whether thread ``tid`` (0: the calling one) runs under ``SCHED_BATCH``."""
    try:
        return os.sched_getscheduler(tid) == os.SCHED_BATCH
    except (AttributeError, OSError):
        return False


def parse_cpus(text: str) -> set[int]:
    """``"1"``, ``"1,3"`` or ``"2-3"`` -> the CPU numbers; ValueError on anything else."""
    out: set[int] = set()
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        a, b = int(lo), int(hi or lo)
        if a < 0 or b < a:
            raise ValueError(text)
        out.update(range(a, b + 1))
    return out


def check_publish_cpus(text: str) -> str:
    """The ``publish_cpus`` setting, stripped: ``auto`` or a CPU list; ConfigError otherwise."""
    text = str(text).strip()
    if text != AUTO:
        try:
            parse_cpus(text)
        except ValueError:
            raise ConfigError(f"publish_cpus {text!r}: give auto or CPU numbers such as 1, 2-3 or 1,3") from None
    return text


def publisher_cpus(spec: str | None) -> set[int] | None:
    """Where the publisher process runs: the CPUs of ``spec`` (``parse_cpus``), or for ``auto``
    (None) the machine's CPUs this process is not pinned to when it is pinned to some (a
    performer on CPU 0 of 2: CPU 1); None: wherever the performer may run (not pinned). Auto
    counts the machine's CPUs (``os.cpu_count``): in a container limited to some of them the
    kernel keeps those it allows, or refuses all and the child stays with the performer."""
    if spec is not None and spec != AUTO:
        return parse_cpus(spec)
    try:
        mine = os.sched_getaffinity(0)
    except AttributeError:
        return None
    others = set(range(os.cpu_count() or 1)) - mine
    return others or None


def pin(pid: int, cpus: set[int]) -> bool:
    """Every thread of process ``pid`` (threads it starts later inherit it) onto ``cpus``; False
    where the kernel refuses (a CPU this container may not use) or cannot (not Linux)."""
    ok = True
    for tid in _threads(pid):
        try:
            os.sched_setaffinity(tid, cpus)
        except ProcessLookupError:
            pass  # a thread that ended
        except (AttributeError, OSError):
            ok = False
    return ok


def _threads(pid: int) -> list[int]:
    try:
        return [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        return [pid]
