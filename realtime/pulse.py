"""A private PulseAudio server with a null sink: a real, clocked live input for tests and measurements.

``PulseServer()`` starts ``pulseaudio`` as the current user (``-n``: no default config), its
socket in a fresh ``XDG_RUNTIME_DIR``, with one null sink (``perfsink``, 44.1 kHz stereo float32:
the monitor carries the played samples as they are, not rounded to 16 bits and clipped at full
scale as the default s16 sink does, so a live run hears the file's samples) whose monitor is the
default source. :attr:`PulseServer.env` is the environment a client needs: a
``performer run --input-device pulse`` started with it captures the monitor through PortAudio
(ALSA's ``pulse`` plugin, Debian's libasound2-plugins), and :meth:`PulseServer.play` plays audio
into the sink in real time through ``pacat``. Nothing outside that runtime directory sees the
server (other programs keep their own sound setup). Debian packages: pulseaudio,
pulseaudio-utils, libasound2-plugins (the Makefile's APT_PKGS).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from models.errors import AudioError

SINK = "perfsink"
RATE = 44100


class PulseServer:
    """A running private PulseAudio server (see the module docstring); ``close()`` stops it."""

    def __init__(self, timeout: float = 10.0) -> None:
        missing = [p for p in ("pulseaudio", "pactl", "pacat") if shutil.which(p) is None]
        if missing:
            raise AudioError(f"{', '.join(missing)} not installed (Debian: apt-get install pulseaudio pulseaudio-utils)")
        self.dir = Path(tempfile.mkdtemp(prefix="performer-pulse-"))
        self.env = {**os.environ, "XDG_RUNTIME_DIR": str(self.dir), "PULSE_SOURCE": f"{SINK}.monitor",
                    "PULSE_SINK": SINK, "HOME": str(self.dir)}
        self.log = self.dir / "pulseaudio.log"
        self.proc = subprocess.Popen(
            ["pulseaudio", "-n", "--daemon=no", "--exit-idle-time=-1", "--use-pid-file=no", "--disallow-exit",
             f"--load=module-null-sink sink_name={SINK} format=float32le rate={RATE} channels=2",
             "--load=module-native-protocol-unix", "--log-target=stderr"],
            env=self.env, stdout=subprocess.DEVNULL, stderr=open(self.log, "w"))
        deadline = time.monotonic() + timeout
        while subprocess.run(["pactl", "info"], env=self.env, capture_output=True).returncode != 0:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                tail = self.log.read_text()[-300:] if self.log.exists() else ""
                raise AudioError(f"PulseAudio did not start: {tail.strip() or 'no output'}")
            time.sleep(0.1)
        subprocess.run(["pactl", "set-default-source", f"{SINK}.monitor"], env=self.env, capture_output=True)

    def play(self, audio: np.ndarray, rate: int = RATE, latency_ms: int = 20) -> subprocess.Popen:
        """Start playing ``audio`` (samples, channels) float32 into the sink in real time; returns the
        ``pacat`` process (it exits when the audio has been played). ``latency_ms``: pacat's buffer; on
        a busy machine a short one underruns, and the sink plays silence in the gaps (the song then
        arrives longer than it is: benchmarks/studies/live_input.py measures that drift)."""
        x = np.ascontiguousarray(audio, np.float32)
        if x.ndim == 1:
            x = x[:, None]
        proc = subprocess.Popen(["pacat", "--playback", f"--device={SINK}", "--format=float32le", f"--rate={rate}",
                                 f"--channels={x.shape[1]}", f"--latency-msec={int(latency_ms)}"],
                                env=self.env, stdin=subprocess.PIPE, stderr=subprocess.DEVNULL)

        def feed() -> None:  # pacat takes it in real time: from a thread, so play() returns at once
            try:
                proc.stdin.write(x.tobytes())  # type: ignore[union-attr]
                proc.stdin.close()  # type: ignore[union-attr]
            except (BrokenPipeError, ValueError):
                pass

        threading.Thread(target=feed, name="pacat feed", daemon=True).start()
        return proc

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> "PulseServer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
