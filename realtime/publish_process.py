"""The broker output in a process of its own, so publishing never takes the engine's interpreter lock.

:class:`BrokerProcess` (what ``performer run --publish`` opens) starts ``python -m
realtime.publish_process`` with the read end of a pipe; the child runs a
:class:`realtime.publish.BrokerPublisher` (the NATS connection, its drop-oldest queue,
reconnection). In the engine's process there is no publishing thread at all: a thread there
(as in :class:`realtime.publish.BrokerPublisher` alone) holds the interpreter lock while it
publishes, and on a busy machine one preempted while holding it stalls the worker (measured:
the per-hop p99 of its own time 1.15-3.3x with 100-1,000 subscribers on two loaded cores,
docs/audience.md).

:meth:`ProcessRoute.send` encodes the frame and writes one record to the pipe with one
non-blocking ``os.write`` (records are at most PIPE_BUF bytes, so each is written whole or not
at all): about 0.03-0.05 ms of CPU. The write wakes nobody: the child polls the pipe
(:data:`POLL_S`). A full pipe (64 KiB: the child has fallen 150 frames behind) drops that
frame, counted as ``drops``. Records: ``<IBB`` (payload length, kind, route id) then the
payload: kind 0 a binary frame, 1 a route (JSON: performer, subject, hello), 2 a state message.
The child's counters come back through a small shared file (:data:`COUNTERS`, int64 each);
credentials reach it in its environment, never its command line.

Where the child runs (:mod:`realtime.sched`): under ``SCHED_BATCH`` (its wake-ups never preempt
the worker mid-hop), and on the CPUs ``cpus`` names; ``performer run`` gives it the CPUs the
performer is not pinned to (``publish_cpus = "auto"``), so a performer pinned to a core keeps it.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import mmap
import os
import select
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from models.errors import ConfigError, NetworkError
from realtime.frame import PoseFrame
from realtime import sched
from realtime.publish import (PASSWORD_ENV, TOKEN_ENV, USER_ENV, BrokerPublisher, Credentials, OwnerBase,
                              RouteBase, check_broker_url, check_subject, load_credentials)
from realtime.wire import encode_frame, hello_message, rest_offsets

log = logging.getLogger(__name__)

_RECORD = struct.Struct("<IBB")
FRAME, ROUTE, STATE = 0, 1, 2
#: The child's counters, in this order, int64 each in the shared file.
COUNTERS = ("published", "drops", "drops_down", "errors", "disconnects", "reconnects", "connected", "queued")
_COUNTS = struct.Struct(f"<{len(COUNTERS)}q")
#: The child looks at the pipe every POLL_S seconds instead of sleeping in ``read`` on it: a
#: reader asleep on the pipe is woken by the worker's ``os.write``, and the kernel ran it on the
#: worker's CPU before the write returned (0.35 ms of the worker's wall time per frame at the
#: median, 5.8 ms at p99, for 0.03 ms of CPU; docs/audience.md). Polling adds at most POLL_S
#: to publish-to-receive and about 250 cheap wake-ups a second to the child.
POLL_S = 0.004


class ProcessRoute(RouteBase):
    """One performer on a :class:`BrokerProcess` (a :class:`realtime.frame.Sink`)."""

    def __init__(self, owner: "BrokerProcess", rid: int, performer: str, subject: str) -> None:
        super().__init__(owner)
        self.rid, self.performer, self.subject = rid, performer, subject
        self.name = f"publish:{owner.display}/{subject}"

    def send(self, frame: PoseFrame) -> None:
        """Encode one frame and write it to the publisher process; never waits (a full pipe drops it, counted)."""
        if not np.isfinite(frame.pose).all():
            self.skipped += 1
            return
        self.frames += 1
        self.owner._write(FRAME, self.rid, encode_frame(frame.index, frame.audio_time, time.time(), frame.pose))

    def set_state(self, state: dict) -> None:
        """The performer's stage and facing, as a ``state`` message on its meta subject."""
        self.owner._write(STATE, self.rid, json.dumps({"type": "state", **state}).encode())


class BrokerProcess(OwnerBase):
    """The parent's side: starts the publisher process, routes performers to it, reads its counters.

    Args as :class:`realtime.publish.BrokerPublisher` (``url``, ``credentials``, ``tls_ca``,
    ``offsets`` for the hello, ``connect_wait``); ``cpus``: the CPUs the child runs on (None: as
    this process; a warning if the kernel refuses them, unless ``cpus_quiet``: auto's guess);
    ``batch``: the child under ``SCHED_BATCH`` (False only to measure without).
    :attr:`cpus` is where it runs, read back. A broker that refuses the login or whose
    certificate is not trusted is a NetworkError here; one that is not there yet is retried in
    the background.
    """

    def __init__(self, url: str, *, credentials: Credentials | None = None, tls_ca: str | Path | None = None,
                 offsets: np.ndarray | None = None, connect_wait: float = 2.0, cpus: set[int] | None = None,
                 batch: bool = True, cpus_quiet: bool = False) -> None:
        check_broker_url(url)
        self.url, self.display = url, url.split("@")[-1]
        if tls_ca is not None and not Path(tls_ca).is_file():
            raise ConfigError(f"publish_tls_ca {str(tls_ca)!r} is not a file")
        self._hello = hello_message(rest_offsets(offsets))
        self._routes: list[ProcessRoute] = []
        self._open_routes = 0
        self._closed = False
        self.pipe_drops = 0
        self._lost = False
        self.final: dict = {}
        self.cpus: list[int] = []
        self._pin_warned = cpus_quiet
        fd, path = tempfile.mkstemp(prefix="performer-publish-")
        os.write(fd, b"\0" * _COUNTS.size)
        self._counts = mmap.mmap(fd, _COUNTS.size)
        os.close(fd)
        self._counts_path = path
        c = credentials or Credentials()
        env = {k: v for k, v in os.environ.items() if k not in (TOKEN_ENV, USER_ENV, PASSWORD_ENV)}
        env.update({k: v for k, v in ((TOKEN_ENV, c.token), (USER_ENV, c.user), (PASSWORD_ENV, c.password)) if v})
        r, self._w = os.pipe()
        args = [sys.executable, "-m", "realtime.publish_process", url, str(r), path, str(connect_wait)]
        if tls_ca is not None:
            args.append(str(tls_ca))
        self._proc = subprocess.Popen(args, pass_fds=(r,), env=env, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL,
                                      cwd=Path(__file__).resolve().parents[1])
        os.close(r)
        self._place(cpus, batch)  # before the child's imports start threads (they inherit it)
        ready, _, _ = select.select([self._proc.stdout], [], [], connect_wait + 30)  # the child's imports, then connect
        line = self._proc.stdout.readline().decode(errors="replace").strip() if ready else ""
        if not line.startswith("ok"):
            self._proc.kill()
            self._proc.wait()
            self._cleanup()
            why = line.removeprefix("fatal: ") or "the publisher process did not start"
            raise NetworkError(f"broker {self.display} refused the publisher: {why}" if line else why)
        self._place(cpus, batch)  # every thread it has now, in case one started first
        if line != "ok connected":
            log.warning("broker %s not reachable yet; publishing starts when it is", self.display)
        fcntl.fcntl(self._w, fcntl.F_SETFL, fcntl.fcntl(self._w, fcntl.F_GETFL) | os.O_NONBLOCK)

    def _place(self, cpus: set[int] | None, batch: bool) -> None:
        pid = self._proc.pid
        if batch:
            sched.batch_process(pid)
        if cpus is not None and not sched.pin(pid, cpus) and not self._pin_warned:
            self._pin_warned = True
            log.warning("cannot run the publisher process on CPUs %s; it runs where the performer does",
                        ",".join(map(str, sorted(cpus))))
        try:
            self.cpus = sorted(os.sched_getaffinity(pid))
        except (AttributeError, OSError):
            self.cpus = []

    def route(self, performer: str, subject: str) -> ProcessRoute:
        """Add a performer publishing on ``subject``.frames / .meta."""
        subject = check_subject(subject)
        if any(r.subject == subject for r in self._routes):
            raise ConfigError(f"publish subject {subject!r} is given twice; give each performer its own")
        route = ProcessRoute(self, len(self._routes), performer, subject)
        hello = json.dumps({**self._hello, "performer": performer, "subject": subject})
        self._write(ROUTE, route.rid, json.dumps({"performer": performer, "subject": subject, "hello": hello}).encode(),
                    wait=True)
        self._routes.append(route)
        self._open_routes += 1
        return route

    def _write(self, kind: int, rid: int, payload: bytes, wait: bool = False) -> None:
        if self._closed:
            return
        record = _RECORD.pack(len(payload), kind, rid) + payload
        while True:
            try:
                if len(record) <= select.PIPE_BUF or not wait:
                    os.write(self._w, record)  # whole or not at all (at most PIPE_BUF)
                    return
                n = os.write(self._w, record)  # a route's hello (setup, not the worker): in pieces
                record = record[n:]
                if not record:
                    return
            except BlockingIOError:
                if not wait:
                    self.pipe_drops += 1
                    if self.pipe_drops == 1:
                        log.warning("the publisher process fell behind; dropping frames (counted as drops)")
                    return
                select.select([], [self._w], [], 1.0)
            except (BrokenPipeError, OSError):
                if not self._lost:
                    self._lost = True
                    log.warning("the publisher process ended (exit %s); frames are no longer published",
                                self._proc.poll())
                self.pipe_drops += 1
                return

    def stats(self) -> dict[str, float]:
        if self._counts.closed:  # after close: the child's last counters
            return dict(self.final)
        counts = dict(zip(COUNTERS, _COUNTS.unpack_from(self._counts)))
        counts["drops"] += self.pipe_drops
        return counts

    def notice(self) -> str | None:
        if self._lost:
            return "the publisher process ended"
        s = self.stats()
        lost = s.get("drops", 0) + s.get("drops_down", 0)
        return None if s.get("connected") else f"broker {self.display} away ({lost} frames not published)"

    def close(self) -> None:
        """End of the pipe: the child publishes what it holds (at most 2 s) and exits."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            os.close(self._w)
        try:
            self._proc.wait(5)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._cleanup()

    def _cleanup(self) -> None:
        self.final = self.stats()
        self._counts.close()
        with contextlib.suppress(OSError):
            os.unlink(self._counts_path)
        if self._proc.stdout is not None:
            self._proc.stdout.close()


# ---- the child ---------------------------------------------------------------------------------


def _child(url: str, fd: int, counts_path: str, connect_wait: float, tls_ca: str | None) -> int:
    # Ctrl-C at a terminal reaches the whole process group: the parent stops, then closes the
    # pipe, and the end of the pipe ends this process (after publishing what it holds).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    logging.basicConfig(level=logging.WARNING, format="performer run: %(message)s", stream=sys.stderr)
    try:
        pub = BrokerPublisher(url, credentials=load_credentials(), tls_ca=tls_ca, connect_wait=connect_wait, hello={})
    except (NetworkError, ConfigError) as exc:
        print(f"fatal: {str(exc).split('refused the publisher: ')[-1]}", flush=True)
        return 3
    print("ok connected" if pub.connected else "ok waiting", flush=True)
    sys.stdout.close()
    with open(counts_path, "r+b") as f:
        counts = mmap.mmap(f.fileno(), _COUNTS.size)
    stop = threading.Event()

    def report() -> None:
        while not stop.wait(0.1):
            s = pub.stats()
            _COUNTS.pack_into(counts, 0, *(int(s[k]) for k in COUNTERS))

    reporter = threading.Thread(target=report, daemon=True)
    reporter.start()
    routes: dict[int, object] = {}
    buf = b""
    os.set_blocking(fd, False)
    while True:
        try:
            data = os.read(fd, 1 << 16)
        except BlockingIOError:  # nothing yet: look again later, never sleep on the pipe
            time.sleep(POLL_S)
            continue
        if not data:
            break
        buf += data
        while len(buf) >= _RECORD.size:
            n, kind, rid = _RECORD.unpack_from(buf)
            if len(buf) < _RECORD.size + n:
                break
            payload, buf = buf[_RECORD.size:_RECORD.size + n], buf[_RECORD.size + n:]
            if kind == FRAME and rid in routes:
                pub._hand_over(routes[rid].frames_subject, payload)
            elif kind == ROUTE:
                spec = json.loads(payload)
                routes[rid] = pub.route(spec["performer"], spec["subject"], hello=spec["hello"])
            elif kind == STATE and rid in routes:
                routes[rid].state = payload.decode()
                pub._meta_changed()
    pub.close()
    stop.set()
    reporter.join()
    s = pub.stats()
    _COUNTS.pack_into(counts, 0, *(int(s[k]) for k in COUNTERS))
    return 0


def open_routes(cfg, names: list[str]) -> list[ProcessRoute]:
    """One route per performer name on one publisher process for ``performer run``'s config
    (``publish``, ``publish_subject``, ``publish_credentials``, ``publish_tls_ca``,
    ``publish_cpus``); [] when ``publish`` is unset."""
    if getattr(cfg, "publish", None) is None:
        return []
    prefix = check_subject(cfg.publish_subject)
    spec = getattr(cfg, "publish_cpus", sched.AUTO)
    owner = BrokerProcess(cfg.publish, credentials=load_credentials(cfg.publish_credentials), tls_ca=cfg.publish_tls_ca,
                          cpus=sched.publisher_cpus(spec), cpus_quiet=spec == sched.AUTO)
    try:
        return [owner.route(name, f"{prefix}.{name}") for name in names]
    except BaseException:
        owner.close()
        raise


if __name__ == "__main__":
    a = sys.argv[1:]
    sys.exit(_child(a[0], int(a[1]), a[2], float(a[3]), a[4] if len(a) > 4 else None))
