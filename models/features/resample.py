"""Streaming polyphase resampler, shared by the offline and the live audio paths.

The filter is the one :func:`scipy.signal.resample_poly` designs (Kaiser window,
beta 5.0, ``10 * max(up, down)`` taps each side of the centre, cutoff at the lower
Nyquist rate) and the output is aligned the same way: output sample ``m`` sits at
input time ``m * down / up`` samples, zero phase. On a whole signal followed by
:meth:`StreamingResampler.flush`, the result equals ``resample_poly(x, up, down)``
(with its default zero padding) to float64 rounding.

Zero phase needs look-ahead: output ``m`` depends on input samples up to index
``(m * down + half_len) // up``, i.e. at most ``half_len / up`` input samples after
its own time (20 samples = 0.45 ms at 44.1 kHz, 21.8 = 0.45 ms at 48 kHz).
:meth:`inputs_needed` gives the exact count; the feature latency builds on it.

Why not ``scipy.signal.upfirdn`` per block: it has no carried state, so every block
would need an overlap buffer and index bookkeeping of the same size as this code;
the gather + row-dot below computes only the outputs whose inputs have arrived and
is exact across any block boundaries.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.signal import firwin

from models.errors import AudioError

MIN_RATE: int = 4000
MAX_RATE: int = 192000
_CHUNK: int = 8192  # outputs computed per gather; bounds memory on long signals


def check_rate(sr: int, *, source: str | None = None) -> int:
    """Return ``sr`` as int if it is a supported sample rate (Hz), else raise AudioError."""
    if isinstance(sr, bool) or not float(sr).is_integer() or not MIN_RATE <= sr <= MAX_RATE:
        raise AudioError(
            f"unsupported sample rate {sr!r} Hz (supported: whole numbers {MIN_RATE}..{MAX_RATE} Hz)",
            source=source,
        )
    return int(sr)


@functools.lru_cache(maxsize=16)
def design_filter(up: int, down: int) -> tuple[np.ndarray, int]:
    """Polyphase low-pass filter for rational ratio ``up/down`` (coprime).

    Returns ``(phases, half_len)``: ``phases`` is a read-only float64 array of shape
    (up, L) with ``phases[p, L - 1 - j] = h[p + j * up]`` (h zero-padded to ``up * L``
    taps, gain ``up``): row p dotted with the L inputs ending at the newest one an
    output of phase p needs, oldest first, gives that output. ``half_len`` is the
    centre tap index of h, as in resample_poly.
    """
    max_rate = max(up, down)
    half_len = 10 * max_rate
    h = firwin(2 * half_len + 1, 1.0 / max_rate, window=("kaiser", 5.0)) * up
    n_taps = math.ceil(h.size / up)
    h = np.concatenate([h, np.zeros(n_taps * up - h.size)])
    phases = np.ascontiguousarray(h.reshape(n_taps, up).T[:, ::-1])
    phases.flags.writeable = False
    return phases, half_len


class StreamingResampler:
    """Stateful resampler from ``input_sr`` to ``output_sr`` for mono float blocks.

    ``process(block)`` returns every output sample whose inputs (including the
    filter's look-ahead) have arrived; ``flush()`` ends the stream by feeding the
    zeros resample_poly would pad with and returns the remaining outputs, so that
    the total output length is ``ceil(n_in * up / down)``. Outputs are float64.
    """

    def __init__(self, input_sr: int, output_sr: int) -> None:
        self.input_sr = check_rate(input_sr, source="input")
        self.output_sr = check_rate(output_sr, source="output")
        g = math.gcd(self.input_sr, self.output_sr)
        self.up, self.down = self.output_sr // g, self.input_sr // g
        self.identity = self.up == self.down
        if not self.identity:
            self._phases, self.half_len = design_filter(self.up, self.down)
            self._taps = self._phases.shape[1]
        else:
            self.half_len, self._taps = 0, 1
        self.reset()

    def reset(self) -> None:
        """Forget all input: the next sample pushed is input sample 0."""
        self._n_in = 0  # input samples received
        self._n_out = 0  # output samples returned
        # _buf[k] holds input sample (_buf_start + k); history before 0 is zeros.
        self._buf_start = -(self._taps - 1)
        self._buf = np.zeros(self._taps - 1)

    @property
    def samples_in(self) -> int:
        """Input samples received since the last reset."""
        return self._n_in

    @property
    def samples_out(self) -> int:
        """Output samples returned since the last reset."""
        return self._n_out

    def inputs_needed(self, m: int | np.ndarray) -> int | np.ndarray:
        """Input samples that must have arrived for output sample ``m`` (0-based) to exist."""
        if self.identity:
            return m + 1
        return (m * self.down + self.half_len) // self.up + 1

    def _available_outputs(self) -> int:
        """Outputs computable from the inputs received so far (total, since reset)."""
        if self.identity:
            return self._n_in
        return max(0, (self._n_in * self.up - 1 - self.half_len) // self.down + 1)

    def process(self, block: np.ndarray) -> np.ndarray:
        """Feed a 1-D block of input samples; return the new output samples (float64)."""
        block = np.asarray(block, dtype=np.float64).reshape(-1)
        self._n_in += block.size
        if self.identity:
            self._n_out += block.size
            return block.copy()
        self._buf = np.concatenate([self._buf, block]) if block.size else self._buf
        return self._emit(self._available_outputs())

    def flush(self) -> np.ndarray:
        """End the stream: return the remaining outputs (zero input beyond the end).

        After a flush the total output is ``ceil(n_in * up / down)`` samples, exactly
        resample_poly's length. Call :meth:`reset` before reusing the resampler.
        """
        if self.identity:
            return np.zeros(0)
        total = -(-self._n_in * self.up // self.down)
        if total <= self._n_out:
            return np.zeros(0)
        needed = int(self.inputs_needed(total - 1))
        pad = max(0, needed - (self._buf_start + self._buf.size))
        self._buf = np.concatenate([self._buf, np.zeros(pad)])
        return self._emit(total)

    def _emit(self, end: int) -> np.ndarray:
        """Compute outputs ``_n_out .. end-1`` from the buffer and drop used history."""
        if end <= self._n_out:
            return np.zeros(0)
        if self.up == 1:  # integer decimation (44.1 -> 22.05 kHz): one phase, see _decimate
            out = self._decimate(end)
        else:
            out = self._gather(end)
        self._n_out = end
        keep_from = int(self.inputs_needed(self._n_out)) - self._taps  # oldest input still needed
        drop = max(0, keep_from - self._buf_start)
        if drop:
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return out

    def _decimate(self, end: int) -> np.ndarray:
        """Outputs ``_n_out .. end-1`` when ``up == 1``: one correlation over the inputs they
        need, every ``down``-th value kept.

        With one phase every output applies the same taps, so ``np.correlate`` computes them
        in one C loop; the general gather below first builds a (k, taps) copy of the inputs
        and one of the taps. On the engine's live path (44.1 kHz, 512-sample blocks) this cut
        the features from 507-577 to 319-355 us per frame (docs/latency.md, interleaved A/B).
        The sums are the same up to float64 rounding order.
        """
        out = np.empty(end - self._n_out)
        for lo in range(self._n_out, end, _CHUNK):  # chunks bound memory on long signals
            hi = min(end, lo + _CHUNK)
            newest0 = lo * self.down + self.half_len  # newest input of output lo
            newest1 = (hi - 1) * self.down + self.half_len
            span = self._buf[newest0 - self._buf_start - (self._taps - 1) : newest1 - self._buf_start + 1]
            out[lo - self._n_out : hi - self._n_out] = np.correlate(span, self._phases[0], "valid")[:: self.down]
        return out

    def _gather(self, end: int) -> np.ndarray:
        """Outputs ``_n_out .. end-1`` for any ratio: per output, its input window dotted with its phase's taps."""
        out = np.empty(end - self._n_out)
        for lo in range(self._n_out, end, _CHUNK):
            newest, phase = np.divmod(np.arange(lo, min(end, lo + _CHUNK)) * self.down + self.half_len, self.up)
            # Windows over just this chunk's inputs: np.take would copy a whole-buffer view.
            first = newest[0] - self._buf_start - (self._taps - 1)
            span = self._buf[first : newest[-1] - self._buf_start + 1]
            windows = np.lib.stride_tricks.sliding_window_view(span, self._taps)  # row i ends at span[i + L - 1]
            rows = np.take(windows, newest - newest[0], axis=0)  # (k, L), oldest .. newest input
            taps = np.take(self._phases, phase, axis=0)  # (k, L)
            out[lo - self._n_out : lo - self._n_out + rows.shape[0]] = np.einsum("kl,kl->k", rows, taps)
        return out


def resample(x: np.ndarray, input_sr: int, output_sr: int) -> np.ndarray:
    """Resample a whole 1-D signal (offline) with the streaming resampler's exact code.

    Returns float32 of length ``ceil(len(x) * output_sr / input_sr)`` (reduced ratio),
    equal to ``scipy.signal.resample_poly`` with the same rates.
    """
    rs = StreamingResampler(input_sr, output_sr)
    y = np.concatenate([rs.process(x), rs.flush()])
    return y.astype(np.float32)
