"""A local nats-server for the audience tests and benchmark: config, start, kill, restart.

:class:`LocalBroker` writes a nats-server config (client port, WebSocket port without TLS, a
publisher account that may publish on ``performer.>`` and a viewer account that may only
subscribe to it: docs/audience.md) into a folder, starts ``nats-server -c`` and waits until
both ports accept connections. Debian's package installs the binary (``make setup``:
``APT_PKGS``); :func:`find_nats_server` returns None where it is absent.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

#: The accounts of :class:`LocalBroker` (user, password): the performer's and the audience's.
PUBLISHER = ("publisher", "pub-secret")
VIEWER = ("viewer", "viewer")


def find_nats_server() -> str | None:
    """Path of the nats-server binary (PATH, then /usr/sbin), or None."""
    return shutil.which("nats-server") or shutil.which("nats-server", path="/usr/sbin:/usr/local/sbin")


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config_text(port: int, ws_port: int, *, prefix: str = "performer", publisher=PUBLISHER, viewer=VIEWER,
                cluster_port: int | None = None, routes: list[int] | None = None, name: str = "n1") -> str:
    """A nats-server config: clients on ``port``, browsers on ``ws_port`` (no TLS: loopback or behind a
    TLS proxy), the publisher may publish on ``PREFIX.>``, the viewer only subscribe to it; with
    ``cluster_port``, a cluster node routed to the other nodes' ``routes`` ports."""
    text = f"""server_name: {name}
listen: 127.0.0.1:{port}
max_payload: 65536
websocket {{
  listen: "127.0.0.1:{ws_port}"
  no_tls: true
}}
authorization {{
  users = [
    {{user: "{publisher[0]}", password: "{publisher[1]}", permissions: {{publish: "{prefix}.>", subscribe: "_INBOX.>"}}}}
    {{user: "{viewer[0]}", password: "{viewer[1]}", permissions: {{publish: {{deny: ">"}}, subscribe: "{prefix}.>"}}}}
  ]
}}
"""
    if cluster_port is not None:
        urls = ", ".join(f"nats-route://127.0.0.1:{p}" for p in routes or [])
        text += f"cluster {{\n  name: audience\n  listen: 127.0.0.1:{cluster_port}\n  routes: [{urls}]\n}}\n"
    return text


class LocalBroker:
    """One nats-server process on loopback ports, restartable on the same ports.

    Attributes: ``port`` (NATS clients), ``ws_port`` (WebSocket), ``url`` (nats://),
    ``ws_url`` (ws://), ``proc`` (the running process or None).
    """

    def __init__(self, folder: str | Path, port: int | None = None, ws_port: int | None = None, **config) -> None:
        binary = find_nats_server()
        if binary is None:
            raise FileNotFoundError("nats-server is not installed (apt-get install nats-server; make setup)")
        self.binary = binary
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.port = port or free_port()
        self.ws_port = ws_port or free_port()
        self.conf = self.folder / f"nats-{self.port}.conf"
        self.conf.write_text(config_text(self.port, self.ws_port, **config))
        self.log = self.folder / f"nats-{self.port}.log"
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"nats://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.ws_port}"

    def start(self, timeout: float = 10.0) -> "LocalBroker":
        """Start nats-server and wait (at most ``timeout`` s) until both ports accept."""
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen([self.binary, "-c", str(self.conf)], stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + timeout
        for port in (self.port, self.ws_port):
            while True:
                if self.proc.poll() is not None:
                    raise RuntimeError(f"nats-server exited with {self.proc.returncode}: "
                                       f"{self.log.read_text()[-500:]}")
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise TimeoutError(f"nats-server did not listen on {port} within {timeout} s") from None
                    time.sleep(0.02)
        return self

    def kill(self) -> None:
        """SIGKILL: the broker goes away at once, as a crash would."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        self.proc = None

    def pause(self) -> None:
        """SIGSTOP: connections stay open but nothing is read (a broker that hangs)."""
        assert self.proc is not None
        os.kill(self.proc.pid, signal.SIGSTOP)

    def resume(self) -> None:
        assert self.proc is not None
        os.kill(self.proc.pid, signal.SIGCONT)

    def stop(self) -> None:
        """Resume if paused, then SIGTERM and wait (SIGKILL after 5 s)."""
        if self.proc is None or self.proc.poll() is not None:
            self.proc = None
            return
        os.kill(self.proc.pid, signal.SIGCONT)
        self.proc.terminate()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        self.proc = None

    def cpu_rss(self) -> tuple[float, int]:
        """(user + system CPU seconds, resident memory in bytes) of the process, from /proc."""
        assert self.proc is not None
        stat = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        ticks = os.sysconf("SC_CLK_TCK")
        cpu = (int(stat[11]) + int(stat[12])) / ticks
        rss = int(stat[21]) * os.sysconf("SC_PAGE_SIZE")
        return cpu, rss

    def __enter__(self) -> "LocalBroker":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
