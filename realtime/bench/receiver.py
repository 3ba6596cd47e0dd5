"""Loopback receiver process: one UDP (VMC) socket and one WebSocket client per performer.

``python -m realtime.bench.receiver N`` (started by :mod:`realtime.bench.harness`) binds
N UDP sockets on 127.0.0.1, prints ``{"udp_ports": [...]}`` and then follows stdin lines:

* ``{"connect": [ws_port, ...]}`` — opens one WebSocket client per performer (binary
  frames) at ``/ws``, waits for every hello message, prints ``{"connected": true}``; an
  entry may be ``[ws_port, path]`` instead (an ensemble's performers share one port);
* ``{"stop": OUT}`` — writes OUT (JSON: per stream, ``osc`` and ``ws`` lists of
  ``[frame_index, receipt_time]``), prints ``{"done": OUT}`` and exits.

A receipt time is ``time.monotonic()`` when the asyncio loop handed the datagram
(the VMC datagram carrying ``/VMC/Ext/T``, a frame's last) or the binary WebSocket
message to this code. The process imports no torch, so it starts in well under a second.
"""

from __future__ import annotations

import asyncio
import json
import resource
import socket
import sys
import threading
import time

from websockets.asyncio.client import connect

from realtime.bench.measure import vmc_frame_index, ws_frame_index

_RCVBUF = 4 << 20  # bytes; loopback bursts must never overflow the socket buffer


class _VmcLog(asyncio.DatagramProtocol):
    def __init__(self, log: list) -> None:
        self.log = log

    def datagram_received(self, data: bytes, addr) -> None:
        t = time.monotonic()
        i = vmc_frame_index(data)
        if i is not None:
            self.log.append((i, t))


async def _ws_client(port: int, path: str, log: list, hello: asyncio.Event) -> None:
    async with connect(f"ws://127.0.0.1:{port}{path}", compression=None, max_size=1 << 20) as ws:
        await ws.recv()  # the hello message
        hello.set()
        async for message in ws:
            t = time.monotonic()
            i = ws_frame_index(message)
            if i is not None:
                log.append((i, t))


class Receiver:
    """N loopback receivers on an asyncio loop in a background thread."""

    def __init__(self, n: int) -> None:
        self.osc: list[list] = [[] for _ in range(n)]
        self.ws: list[list] = [[] for _ in range(n)]
        self.errors: list[str] = []
        self.loop = asyncio.new_event_loop()
        self.socks = []
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
            s.bind(("127.0.0.1", 0))
            self.socks.append(s)
        self.ports = [s.getsockname()[1] for s in self.socks]
        self._tasks: list[asyncio.Task] = []
        self._thread = threading.Thread(target=self.loop.run_forever, name="receiver loop", daemon=True)
        self._thread.start()
        self._call(self._listen())

    def _call(self, coro, timeout: float = 30.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    async def _listen(self) -> None:
        for s, log in zip(self.socks, self.osc):
            await self.loop.create_datagram_endpoint(lambda log=log: _VmcLog(log), sock=s)

    async def _connect(self, ports: list) -> None:
        hellos = [asyncio.Event() for _ in ports]
        for port, log, ev in zip(ports, self.ws, hellos):
            port, path = (port, "/ws") if isinstance(port, int) else (int(port[0]), str(port[1]))
            task = asyncio.create_task(_ws_client(port, path, log, ev))
            task.add_done_callback(self._done)
            self._tasks.append(task)
        await asyncio.wait_for(asyncio.gather(*(e.wait() for e in hellos)), 20)

    def _done(self, task: asyncio.Task) -> None:
        if not task.cancelled() and task.exception() is not None:
            self.errors.append(f"{type(task.exception()).__name__}: {task.exception()}")

    def connect(self, ports: list) -> None:
        self._call(self._connect(ports))

    def dump(self) -> dict:
        ru = resource.getrusage(resource.RUSAGE_SELF)
        return {"osc": self.osc, "ws": self.ws, "errors": self.errors, "cpu_s": ru.ru_utime + ru.ru_stime}


def _say(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    rx = Receiver(int(argv[0]))
    _say({"udp_ports": rx.ports})
    for line in sys.stdin:
        msg = json.loads(line)
        if "connect" in msg:
            rx.connect([p if isinstance(p, list) else int(p) for p in msg["connect"]])
            _say({"connected": True})
        elif "stop" in msg:
            time.sleep(0.2)  # let the last datagrams in flight land
            data = rx.dump()
            with open(msg["stop"], "w") as f:
                json.dump(data, f)
            _say({"done": msg["stop"]})
            break
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
