"""The dance_vq code predictor's live step in NumPy (:class:`NumpyPredictor`, :class:`Prefix`).

:class:`~models.networks.dance_stream.DanceStream` asks the code predictor
(:class:`~models.networks.dance_vq.CodePredictor`, a 3-layer causal Transformer over the
last 16 code steps) for the next code every 8 frames. Through torch that call took
2-4 ms on the 2-core bench machine, most of it per-operation dispatch (the arithmetic is
about 10 M multiply-adds), all of it on one frame in eight: that frame set the live
engine's per-hop p99 (docs/latency.md). This does the same computation with NumPy
arrays, less of it, and most of it before it is needed:

* a token's input embedding (the audio MLP of its 8 feature frames plus the embedding
  of the code before it) does not change while the token stays in the window, so it is
  computed once, when the token arrives (:meth:`NumpyPredictor.embed`), instead of for
  all 16 tokens at every step;
* only the last token's logits are used, so the last layer's attention output,
  feed-forward, the final norm and the 512-way head run for that token alone;
* causal attention: the other 15 tokens' rows do not depend on the newest token, and
  they are known as soon as the previous code is chosen. :class:`Prefix` computes their
  keys and values in seven pieces on the frames between code steps, and the code step
  runs the newest token's row alone (:meth:`NumpyPredictor.logits_after`).

The code step's own work (the token's embedding, the newest row through each layer and
the head) runs as compiled kernels (:mod:`models.networks.dance_jit`): as NumPy calls it
was about 100 dispatches of 5-10 µs each on the live path's cold caches. The pieces
ahead keep NumPy's (BLAS) matrix products; their layer norms and GELUs are compiled
kernels that give NumPy's values bit for bit.

The same numbers come out whichever frame computes them, so the live stream and the
offline pass (which pushes the song through the same stream) stay equal. The torch
module stays the reference: logits agree to float32 rounding (a few 1e-6 on logits of
magnitude ~7; ``tests/test_dance_vq.py``). Rounding can decide a draw: over 2 x 1,230
code draws of the shipped default (5.5 minutes of songs, silence and noise, two seeds)
the codes were those of the torch predictor but for one, whose uniform variate fell
2e-7 from a boundary of the cumulative distribution (docs/latency.md). The weights are
copied once, when the predictor is made: a model trained further afterwards needs a new
one (a new ``DanceStream``).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

import numpy as np
from scipy.special import erf

from models.networks.dance_jit import add_rows, embed_finish, embed_token, gelu_bias, head, layer_norm_rows, row_layer

_SQRT_HALF = np.float32(np.sqrt(0.5))
_BLAS = None  # threadpoolctl's controller of the BLAS libraries, made on first use (about 2 ms)
_HOLD_LOCK = threading.Lock()
_held = 0  # blocks inside hold_single_thread_blas now (any thread); while > 0 BLAS runs one thread
_hold_limit = None  # the threadpoolctl limit the first of them entered (None: none was needed)


def _blas():
    """threadpoolctl's controller of the BLAS libraries (False without threadpoolctl)."""
    global _BLAS
    if _BLAS is None:
        try:
            from threadpoolctl import ThreadpoolController

            _BLAS = ThreadpoolController().select(user_api="blas")
        except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn (librosa)
            _BLAS = False
    return _BLAS


@contextlib.contextmanager
def single_thread_blas() -> Iterator[None]:
    """Run the block with one BLAS thread, then restore the count.

    The predictor's matrix products (15 rows, up to 512 columns; even its one-row products
    are above OpenBLAS's threshold for matrix-vector threading) are split over every core
    by default, and split they cost several times more: on the 2-core bench machine with
    another job running, a 5.5-minute stream took 36 s instead of 7 s. Inside
    :func:`hold_single_thread_blas` (a live engine's worker) this costs nothing; where BLAS
    already runs one thread (OMP_NUM_THREADS=1) two library calls (about 9 µs); else a
    threadpoolctl limit (about 50 µs on the 2-core machine). Without threadpoolctl the block
    runs as it is.
    """
    if _held:
        yield
        return
    blas = _blas()
    if not blas or all(lib.get_num_threads() == 1 for lib in blas.lib_controllers):
        yield
        return
    with blas.limit(limits=1):
        yield


@contextlib.contextmanager
def hold_single_thread_blas() -> Iterator[None]:
    """One BLAS thread for the whole block, so that :func:`single_thread_blas` inside it costs
    nothing: for a thread that runs the live path all its life (``realtime.engine``'s worker, whose
    performers' products are all small). BLAS's thread count is the process's: the first block
    entered sets it to 1, the last one left restores it (nested or on several threads: a count).
    Only the time changes: the bundled clip's features and a performer's poses on them were the
    same bytes held or not (2 BLAS threads otherwise, the 2-core machine).
    """
    global _held, _hold_limit
    with _HOLD_LOCK:
        if _held == 0:
            blas = _blas()
            if blas and not all(lib.get_num_threads() == 1 for lib in blas.lib_controllers):
                _hold_limit = blas.limit(limits=1)
        _held += 1
    try:
        yield
    finally:
        with _HOLD_LOCK:
            _held -= 1
            if _held == 0 and _hold_limit is not None:
                _hold_limit.restore_original_limits()
                _hold_limit = None


def _np(t) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)


def _gelu(x: np.ndarray) -> np.ndarray:
    """Exact (erf) GELU, as torch's ``F.gelu`` default. (Not torch's kernel on the same memory:
    with more than one torch thread it splits even 8,000 values over the threads, 7 ms a
    call on a busy 2-core machine, and the offline pass runs with the caller's threads.)"""
    return 0.5 * x * (1.0 + erf(x * _SQRT_HALF))


def _layer_norm(x: np.ndarray, w: np.ndarray, b: np.ndarray, eps: float) -> np.ndarray:
    """LayerNorm over the last axis; ``np.add.reduce(...) / d`` is ``mean`` without its Python wrapper."""
    d = x.shape[-1]
    xc = x - np.add.reduce(x, -1, keepdims=True) / d
    var = np.add.reduce(xc * xc, -1, keepdims=True) / d
    return xc / np.sqrt(var + eps) * w + b


class _Layer:
    """One ``nn.TransformerEncoderLayer`` (norm_first, GELU, eval mode: no dropout)."""

    def __init__(self, layer, d: int) -> None:
        att = layer.self_attn
        if not (layer.norm_first and att.batch_first and att._qkv_same_embed_dim):
            raise ValueError("NumpyPredictor supports norm_first, batch_first layers with one in-projection")
        self.n1 = (_np(layer.norm1.weight), _np(layer.norm1.bias), float(layer.norm1.eps))
        self.n2 = (_np(layer.norm2.weight), _np(layer.norm2.bias), float(layer.norm2.eps))
        self.w_qkv, self.b_qkv = _np(att.in_proj_weight).T.copy(), _np(att.in_proj_bias)
        self.w_o, self.b_o = _np(att.out_proj.weight).T.copy(), _np(att.out_proj.bias)
        self.w_1, self.b_1 = _np(layer.linear1.weight).T.copy(), _np(layer.linear1.bias)
        self.w_2, self.b_2 = _np(layer.linear2.weight).T.copy(), _np(layer.linear2.bias)
        self.heads = att.num_heads
        self.d = d
        self.scale = np.float32(1.0 / np.sqrt(d // att.num_heads))

    def qkv(self, h: np.ndarray) -> np.ndarray:
        """Rows (n, d) -> their queries, keys and values side by side (n, 3d)."""
        return layer_norm_rows(h, *self.n1) @ self.w_qkv + self.b_qkv

    def attend(self, h: np.ndarray, q: np.ndarray, k: np.ndarray, v: np.ndarray,
               mask: np.ndarray | None) -> np.ndarray:
        """Rows ``h`` (m, d) with queries ``q`` (m, d) over keys and values ``k``, ``v`` (n, d):
        the residual attention and feed-forward blocks -> (m, d). ``mask`` (m, n) or None."""
        n, nh = len(k), self.heads
        return self.attend_heads(h, q, k.reshape(n, nh, -1).transpose(1, 2, 0), v.reshape(n, nh, -1).transpose(1, 0, 2),
                                 mask)

    def attend_heads(self, h: np.ndarray, q: np.ndarray, kh: np.ndarray, vh: np.ndarray,
                     mask: np.ndarray | None, feed_forward: bool = True) -> np.ndarray:
        """:meth:`attend` with the keys and values already split by head: ``kh`` (H, hd, n), ``vh`` (H, n, hd).
        ``feed_forward=False``: the attention block only (then :meth:`feed_forward`)."""
        m, d, nh = len(q), self.d, self.heads
        s = (q.reshape(m, nh, -1).transpose(1, 0, 2) @ kh) * self.scale  # (H, m, n)
        if mask is not None:
            s += mask
        s = np.exp(s - s.max(-1, keepdims=True))
        s /= s.sum(-1, keepdims=True)
        h = h + (s @ vh).transpose(1, 0, 2).reshape(m, d) @ self.w_o + self.b_o
        return self.feed_forward(h) if feed_forward else h

    def feed_forward(self, h: np.ndarray) -> np.ndarray:
        """The residual feed-forward block: (m, d) -> (m, d)."""
        return self.ff_out(h, self.ff_hidden(h))

    def ff_hidden(self, h: np.ndarray) -> np.ndarray:
        """The feed-forward block's first half: rows (m, d) -> GELU hidden rows (m, 4d).
        (Layer norm and GELU compiled, :mod:`models.networks.dance_jit`: the values of
        :func:`_layer_norm` and :func:`_gelu`, bit for bit.)"""
        u = layer_norm_rows(h, *self.n2) @ self.w_1
        gelu_bias(u, self.b_1)
        return u

    def ff_out(self, h: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The feed-forward block's second half: rows ``h`` (m, d) + hidden ``u`` (m, 4d) @ w_2 -> (m, d)."""
        return h + u @ self.w_2 + self.b_2

    def row(self, h: np.ndarray, kh: np.ndarray, vh: np.ndarray, m: int) -> np.ndarray:
        """The newest token's row (d,) through this layer: its key and value go into slot ``m`` of
        ``kh`` (H, hd, m + 1) and ``vh`` (H, m + 1, hd), its query attends to all m + 1.
        One compiled call (:func:`models.networks.dance_jit.row_layer`)."""
        return row_layer(h, kh, vh, m, *self.n1, self.w_qkv, self.b_qkv, self.w_o, self.b_o, *self.n2,
                         self.w_1, self.b_1, self.w_2, self.b_2, self.scale)

    def __call__(self, h: np.ndarray, mask: np.ndarray, last_only: bool) -> np.ndarray:
        """Rows ``h`` (n, d) -> (n, d), or (1, d) for the last row only (``last_only``)."""
        d = self.d
        qkv = self.qkv(h)
        k, v = qkv[:, d: 2 * d], qkv[:, 2 * d:]
        if last_only:  # the last row sees every token: no mask
            return self.attend(h[-1:], qkv[-1:, :d], k, v, None)
        return self.attend(h, qkv[:, :d], k, v, mask)


class Prefix:
    """The part of a predictor step that does not need the newest token, computed ahead in small steps.

    Causal attention: in a window of n tokens, the first n - 1 rows of every layer
    depend on those n - 1 tokens only. Once a code is chosen, the next step's window is
    known but for its last token (the coming 8 frames of audio), so the stream computes
    the keys and values of the next window's other tokens on the frames between code
    steps (a :meth:`step` or two a frame), and the code step runs the one new row
    (:meth:`NumpyPredictor.logits_after`). The pieces: per layer its keys, values and
    attention block, then the feed-forward block's two halves (the hidden layer with its
    GELU, then the output product), and for the last layer only its keys and values: 7
    pieces for 3 layers, spread over the frames between code steps
    (:class:`~models.networks.dance_stream.DanceStream` says which).
    The numbers are those of the whole window at once (:meth:`NumpyPredictor.logits`),
    whichever frames compute them.
    """

    def __init__(self, pred: "NumpyPredictor", tokens, style: int) -> None:
        """``tokens``: the window's tokens but the newest, oldest first ((m, d) array or a list of
        m (d,) arrays, m may be 0), ``style``: the style token they are computed in."""
        self.pred, self.style, self.m = pred, int(style), len(tokens)
        self.h = tokens  # becomes tokens + style + position at the first step (a list is stacked then)
        # per layer: keys (H, hd, m + 1) and values (H, m + 1, hd) by head; the last slot is the new token's
        self.kv: list[tuple[np.ndarray, np.ndarray]] = []
        last = len(pred.layers) - 1
        # (kind, layer): "attn" = keys, values (and, but for the last layer, the attention block)
        self._todo = [(kind, i) for i in range(last + 1)
                      for kind in (("attn", "ff1", "ff2") if i < last and self.m else ("attn",))]
        self._next = 0
        self._u: np.ndarray | None = None  # the feed-forward's hidden rows (m, 4d) between its halves

    @property
    def done(self) -> bool:
        return self._next == len(self._todo)

    @property
    def left(self) -> int:
        """Pieces not computed yet."""
        return len(self._todo) - self._next

    @property
    def pieces(self) -> int:
        """All its pieces, computed or not."""
        return len(self._todo)

    def step(self) -> None:
        """The next piece (see the class docstring)."""
        kind, i = self._todo[self._next]
        self._next += 1
        layer = self.pred.layers[i]
        if kind == "ff1":
            self._u = layer.ff_hidden(self.h)
            return
        if kind == "ff2":
            self.h, self._u = layer.ff_out(self.h, self._u), None
            return
        d, nh, m = layer.d, layer.heads, self.m
        if i == 0:
            tokens = np.stack(self.h) if m else np.zeros((0, d), np.float32)
            self.h = tokens + self.pred.style[self.style] + self.pred.pos[:m]
        qkv = layer.qkv(self.h)
        kh = np.empty((nh, d // nh, m + 1), np.float32)
        vh = np.empty((nh, m + 1, d // nh), np.float32)
        kh[:, :, :m] = qkv[:, d: 2 * d].reshape(m, nh, d // nh).transpose(1, 2, 0)
        vh[:, :m] = qkv[:, 2 * d:].reshape(m, nh, d // nh).transpose(1, 0, 2)
        self.kv.append((kh, vh))
        if i < len(self.pred.layers) - 1 and m:  # the last layer's rows are not needed, only its keys
            self.h = layer.attend_heads(self.h, qkv[:, :d], kh[:, :, :m], vh[:, :m], self.pred.mask[:m, :m],
                                        feed_forward=False)

    def finish(self) -> "Prefix":
        while not self.done:
            self.step()
        return self


class NumpyPredictor:
    """:class:`~models.networks.dance_vq.CodePredictor`'s next-code logits in NumPy (module docstring).

    ``embed(audio_row, prev)`` once per token, then ``logits(tokens, style)`` on the
    window's embedded tokens (oldest first) gives what ``predictor(audio, prev, style)[0, -1]``
    gives for the same window; ``logits_after(Prefix(self, tokens[:-1], style), tokens[-1])``
    the same, with the first tokens' work done ahead (:class:`Prefix`).
    """

    def __init__(self, predictor) -> None:
        lin1, lin2 = predictor.audio[0], predictor.audio[2]
        self.w_a1, self.b_a1 = _np(lin1.weight).T.copy(), _np(lin1.bias)
        self.w_a2, self.b_a2 = _np(lin2.weight).T.copy(), _np(lin2.bias)
        self.code = _np(predictor.code.weight)
        self.style = _np(predictor.style.weight)
        # the tempo input's direction (d,) (DanceVQConfig.tempo_input; None: the predictor does not hear it)
        self.tempo = _np(predictor.tempo.weight)[:, 0].copy() if getattr(predictor, "tempo", None) is not None else None
        self.pos = _np(predictor.pos)
        d = self.pos.shape[1]
        self.layers = [_Layer(layer, d) for layer in predictor.blocks.layers]
        self.norm = (_np(predictor.norm.weight), _np(predictor.norm.bias), float(predictor.norm.eps))
        self.w_head, self.b_head = _np(predictor.head.weight).T.copy(), _np(predictor.head.bias)
        n = len(self.pos)
        self.mask = np.triu(np.full((n, n), -np.inf, np.float32), k=1)
        self.d_model = d
        self.window = n

    def embed(self, audio_row: np.ndarray, prev: int) -> np.ndarray:
        """One token's input (d,): audio MLP of its standardised frames (seg * D,) + the previous code's embedding."""
        a = np.ascontiguousarray(audio_row, np.float32)
        return embed_token(a, self.w_a1, self.b_a1, self.w_a2, self.b_a2, self.code[prev])  # one compiled call

    def embed_start(self) -> np.ndarray:
        """A token's first layer before any of its frames (its bias, a copy): :meth:`embed_frame` adds
        its frames one by one as they arrive, :meth:`embed_last` the newest and finishes the token."""
        return self.b_a1.copy()

    def embed_frame(self, acc: np.ndarray, frame: np.ndarray, r: int) -> None:
        """Add the token's standardised frame ``r`` (D,) to its first layer ``acc``, in place (frames in order)."""
        add_rows(acc, frame, self.w_a1, r * len(frame))

    def embed_last(self, acc: np.ndarray, frame: np.ndarray, prev: int) -> np.ndarray:
        """:meth:`embed` of the token whose first ``seg - 1`` frames ``acc`` holds (:meth:`embed_frame`)
        and whose last is ``frame`` (D,): the same values, bit for bit; ``acc`` is used up."""
        return embed_finish(acc, frame, len(self.w_a1) - len(frame), self.w_a1, self.w_a2, self.b_a2, self.code[prev])

    def with_tempo(self, token: np.ndarray, tempo: float) -> np.ndarray:
        """``token`` (d,) from :meth:`embed` / :meth:`embed_last` with its ln(T / T_ref) ``tempo`` added, in
        place (a predictor that hears the tempo; else ``token`` as it is)."""
        if self.tempo is not None and tempo != 0.0:
            token += np.float32(tempo) * self.tempo
        return token

    def logits(self, tokens: np.ndarray, style: int) -> np.ndarray:
        """Logits (K,) of the next code: ``tokens`` (n, d) from :meth:`embed`, n <= window_codes."""
        n = len(tokens)
        h = tokens + self.style[style] + self.pos[:n]
        mask = self.mask[:n, :n]
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            h = layer(h, mask, last_only=i == last)
        return self._head(h[-1])

    def logits_after(self, prefix: Prefix, token: np.ndarray) -> np.ndarray:
        """Logits (K,) of the window ``prefix``'s tokens + ``token`` (d,), in ``prefix.style``."""
        prefix.finish()
        m = prefix.m
        h = token + self.style[prefix.style] + self.pos[m]  # (d,)
        for layer, (kh, vh) in zip(self.layers, prefix.kv):
            h = layer.row(h, kh, vh, m)  # the last row sees every token: no mask
        return head(h, *self.norm, self.w_head, self.b_head)

    def _head(self, h: np.ndarray) -> np.ndarray:
        return (_layer_norm(h, *self.norm) @ self.w_head + self.b_head).astype(np.float32)
