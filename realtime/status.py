"""The live status line of ``performer run`` on stderr.

On a terminal the line is rewritten in place about twice a second; otherwise (a log
file, a pipe) a plain line is printed every ``plain_interval`` seconds. Fields::

    running  1234 frames 30.0 fps | hop p50 1.2 p99 3.4 ms | latency p50 4.0 p99 9.1 ms
    | drops 0 | clients 1 | overruns 0 | nan 0

*hop*: compute time per frame (features + model + blending + send); *latency*: frame
send time minus the release time of the audio block that completed it; *drops*:
frames the outputs dropped (slow peers) plus output errors; *clients*: WebSocket
clients connected; *overruns*: audio blocks that lost samples because the worker fell
behind, plus input overflows the device reported (*underruns*, shown when not 0:
input underflows the device reported). Shown only when they apply: *idle* (the
performer holds its idle pose), *offset* (ms) and *smoothing* when not 0, and with
``--control-osc`` *control N ok M bad* (OSC control messages applied / rejected), plus
*refused* (senders outside ``--control-allow``) and *rate-limited* when not 0. An
ensemble adds *N performers* after the frame count (hop: the whole hop, every performer;
drops, nan: summed over the performers; *idle k/N* when only some are idle; offset and
smoothing when every performer has the same). Last, what an output says of itself
(:meth:`realtime.osc_out.OscSink.notice`), e.g. *no receiver at 127.0.0.1:39539
(connection refused)* while no OSC receiver listens: those frames are not drops.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO


def _sum_key(sinks: dict[str, dict], *keys: str) -> float:
    return sum(float(st.get(k, 0.0)) for st in sinks.values() for k in keys)


def format_status(stats: dict, fps: float | None = None) -> str:
    """One line from :meth:`Engine.stats` (``fps``: measured frames per second, if known)."""
    sinks = stats.get("sinks", {})
    src = stats.get("source", {})
    drops = _sum_key(sinks, "dropped", "drops", "errors") + stats.get("sink_errors", 0)
    overruns = stats.get("overruns", 0) + src.get("input_overflows", 0)
    parts = [
        f"{stats.get('state', '?'):<8} {stats.get('frames', 0):>6} frames"
        + (f" {fps:4.1f} fps" if fps is not None else ""),
    ]
    performers = stats.get("performers") or {}
    if len(performers) > 1:
        parts.append(f"{len(performers)} performers")
        idle = sum(1 for p in performers.values() if p.get("idle"))
        if idle and idle < len(performers):
            parts.append(f"idle {idle}/{len(performers)}")
    if stats.get("idle"):
        parts.append("idle")
    if stats.get("offset_ms"):
        parts.append(f"offset {stats['offset_ms']:g} ms")
    if stats.get("smoothing"):
        parts.append(f"smoothing {stats['smoothing']:g}")
    parts += [
        f"hop p50 {stats.get('compute_ms_p50', float('nan')):.1f} p99 {stats.get('compute_ms_p99', float('nan')):.1f} ms",
        f"latency p50 {stats.get('latency_ms_p50', float('nan')):.1f} p99 {stats.get('latency_ms_p99', float('nan')):.1f} ms",
        f"drops {int(drops)}",
    ]
    if any("clients" in st for st in sinks.values()):
        parts.append(f"clients {int(_sum_key(sinks, 'clients'))}")
    parts.append(f"overruns {int(overruns)}")
    if src.get("input_underflows"):
        parts.append(f"underruns {int(src['input_underflows'])}")
    parts.append(f"nan {int(stats.get('nan_frames', 0))}")
    if stats.get("source_errors"):
        parts.append(f"source errors {int(stats['source_errors'])}")
    control = stats.get("control")
    if control is not None:
        text = f"control {int(control.get('applied', 0))} ok {int(control.get('bad', 0))} bad"
        if control.get("refused"):
            text += f" {int(control['refused'])} refused"
        if control.get("rate_limited"):
            text += f" {int(control['rate_limited'])} rate-limited"
        parts.append(text)
    parts += list(stats.get("notices", ()))
    return " | ".join(parts)


class StatusLine:
    """Prints ``format_status(get_stats())`` periodically from a daemon thread."""

    def __init__(self, get_stats: Callable[[], dict], stream: TextIO | None = None,
                 interval: float = 0.5, plain_interval: float = 2.0) -> None:
        self.get_stats = get_stats
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval if self.tty else plain_interval
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last: tuple[float, int] | None = None

    def line(self) -> str:
        """The current status text (also updates the measured fps)."""
        stats = self.get_stats()
        now, frames = time.monotonic(), int(stats.get("frames", 0))
        fps = None
        if self._last is not None and now > self._last[0]:
            fps = (frames - self._last[1]) / (now - self._last[0])
        self._last = (now, frames)
        return format_status(stats, fps)

    def _print(self, text: str) -> None:
        if self.tty:
            self.stream.write("\r" + text + "\x1b[K")
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self._print(self.line())

    def start(self) -> None:
        self._last = None
        self.line()  # prime the fps measurement
        self._thread = threading.Thread(target=self._run, name="status line", daemon=True)
        self._thread.start()

    def stop(self, final: bool = True) -> None:
        """Stop updating; print a last line (ending the in-place line on a terminal)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if final:
            self._print(self.line())
            if self.tty:
                self.stream.write("\n")
                self.stream.flush()
