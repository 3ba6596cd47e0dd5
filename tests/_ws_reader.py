"""A WebSocket client on a thread that keeps the JSON messages of one type, stamped with their arrival."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable


class JsonReader:
    """Reads ``url`` until ``close()``; ``items`` holds (time.monotonic() at arrival, ``keep(message)``)
    for every message whose ``type`` is ``kind``."""

    def __init__(self, url: str, kind: str, keep: Callable[[dict], object] = lambda m: m) -> None:
        self.url, self.kind, self.keep = url, kind, keep
        self.items: list[tuple[float, object]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from websockets.sync.client import connect

        with connect(self.url) as ws:
            while not self._stop.is_set():
                try:
                    msg = json.loads(ws.recv(timeout=0.5))
                except TimeoutError:
                    continue
                except Exception:  # noqa: BLE001 - the server went away
                    return
                if msg.get("type") == self.kind:
                    self.items.append((time.monotonic(), self.keep(msg)))

    def between(self, t0: float, t1: float) -> list:
        """What arrived in [t0, t1)."""
        return [x for t, x in self.items if t0 <= t < t1]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
