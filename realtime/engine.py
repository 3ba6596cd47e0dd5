"""The real-time engine: audio source → streaming features → causal pose model(s) → sinks.

One worker thread reads the source's :class:`~realtime.audio_input.RingBuffer`,
mixes down to mono, pushes the samples through a streaming feature extractor (30
frames per second of audio, any input rate) and a streaming pose model, checks and
optionally smooths each pose, stamps it as a :class:`~realtime.frame.PoseFrame` and
hands it to every sink. Nothing on this thread waits on the network or the disk:
sinks queue or drop.

An ensemble (several :class:`Performer` on one input) splits that work into one *input
stage* (mixdown, sanitising, one extractor per distinct feature configuration) and one
*lane* per performer (model, guard, smoothing, idle fade, offset, sinks), run one after
the other on the same worker thread; the lanes' expensive frames are staggered
(:attr:`Performer.phase`).

Time stamps of frame ``i`` (counted from the last :meth:`Engine.start` /
:meth:`Engine.reset`, whose stream position is the *origin*):

* ``audio_time = origin / input_rate + (i + 1) * HOP / SAMPLE_RATE + offset_ms / 1000``
  — the end of the audio the pose represents (frame ``i`` covers audio up to
  ``(i + 1) * HOP`` samples at 22050 Hz), shifted by the stage offset;
* ``audio_sample`` — index, at the input rate, of the input sample whose arrival
  completed the frame (never shifted);
* ``wall_time`` — ``time.monotonic()`` when the frame was handed to the sinks.

``wall_time`` minus the release time of ``audio_sample``'s block is the end-to-end
latency inside the process; the engine keeps it (and the per-hop compute time) in
bounded buffers for p50/p99.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Sequence

import numpy as np

from models.errors import ConfigError, short_repr
from models.networks.dance_numpy import hold_single_thread_blas
from models.rig.motion import POSE_DIM
from models.timebase import HOP, SAMPLE_RATE
from realtime.audio_input import AudioSource
from realtime.contracts import ExtractorFactory, FeatureStream, PoseModel
from realtime.controls import applied, apply_control, publish_state
from realtime.engine_config import EngineConfig, check_live_setting
from realtime.frame import PoseFrame, Sink
from realtime.lanes import FeatureGroup, Lane
from realtime.performer import Performer, cycle_frames
from realtime.pose_filters import PoseSmoother
from realtime.rolling_stats import RollingStats
from realtime.runqueue_clock import RunQueueClock, hop_wait
from realtime.source_fallback import SourceFallback, SourceState

log = logging.getLogger(__name__)

#: Seconds of noise the warm-up runs before its silence (:meth:`Engine._warm_up`): the live
#: path's kernels that only sound reaches get compiled (or loaded) before the first frame.
KERNEL_NOISE_S: float = 1.0


#: Input samples beyond +-MAX_SAMPLE (full scale = 1; 12 dB of headroom) are treated like NaN
#: (replaced by 0) before the features: no converter delivers them, a broken driver's garbage does.
MAX_SAMPLE: float = 4.0


class Engine(SourceFallback):
    """Runs one audio source through features and one or more pose models to their sinks.

    One performer: ``Engine(source, extractor_factory, model, sinks, config)``. An
    ensemble: ``Engine(source, config=config, performers=[Performer(...), ...])``: one
    *input stage* (the source, its ring, mixdown, sanitising, and one streaming feature
    extractor per distinct ``feature_key``) feeds one *lane* per performer (its model,
    NaN guard, smoothing, idle fade, offset, sinks and counters), all on the one worker
    thread, lanes in the order given. The lanes' expensive frames are staggered
    (:attr:`Performer.phase`). One performer is today's engine exactly.

    ``start()`` warms the pipeline up on silence, clears state and starts the source
    and the worker thread; ``stop()`` stops both (restartable: a file source resumes,
    frame indices restart at 0); ``reset()`` clears the streaming state at the next
    worker step without stopping; ``close()`` stops and closes every sink. ``wait()``
    blocks until a finite source has been fully processed (or ``duration_s`` reached).

    Failures: a sink that raises is counted and logged once, and keeps being called;
    a model that outputs NaN/inf gets that frame replaced by the last good pose
    (counted in ``nan_frames``); a source that reports an error is stopped and
    restarted every ``retry_s`` while the last pose stays on the receivers (no frames
    are sent until audio comes back); with a ``fallback_source``, after
    ``fallback_after_s`` without audio the engine switches to it (state ``fallback``)
    and back to the main source as soon as that delivers audio again, keeping the
    model's state, frame numbering and audio time running (a new extractor is built
    for the other sample rate); before the extractor, input samples that are NaN, inf or
    beyond ``MAX_SAMPLE`` become 0 (counted in ``bad_samples``, logged once); an exception
    in the extractor or model stops the engine and is kept in ``error`` (re-raised by
    :meth:`wait`). Each performer's sinks, counters and settings are its own: a failing
    or slow output of one performer never holds up another.
    """

    def __init__(
        self,
        source: AudioSource,
        extractor_factory: ExtractorFactory | None = None,
        model: PoseModel | None = None,
        sinks: Sequence[Sink] = (),
        config: EngineConfig | None = None,
        *,
        fallback_source: AudioSource | None = None,
        performers: Sequence[Performer] | None = None,
    ) -> None:
        self.source = source
        self.fallback_source = fallback_source
        self.config = config or EngineConfig()
        if self.config.offset_ms is None or not math.isfinite(self.config.offset_ms):
            raise ValueError(f"offset_ms must be a finite number, got {self.config.offset_ms}")
        if not 0.0 < self.config.idle_fade_s <= 60.0:
            raise ValueError(f"idle_fade_s must be in (0, 60] seconds, got {self.config.idle_fade_s}")
        if performers is None:
            if extractor_factory is None or model is None:
                raise TypeError("Engine needs an extractor_factory and a model, or performers")
            specs = [Performer("performer", model, extractor_factory, list(sinks), phase=0)]
        else:
            if extractor_factory is not None or model is not None or len(sinks):
                raise TypeError("give Engine either performers or extractor_factory, model and sinks")
            specs = list(performers)
            if not specs:
                raise ConfigError("an engine needs at least one performer")
        n = len(specs)
        self._lanes = [Lane(s, self.config, s.phase if s.phase is not None else i * cycle_frames(s.model) // n)
                       for i, s in enumerate(specs)]
        self._by_name: dict[str, Lane] = {}
        for lane in self._lanes:
            if lane.name in self._by_name:
                raise ConfigError(f"performer names must differ: {lane.name!r} is given twice")
            self._by_name[lane.name] = lane
        self._groups: list[FeatureGroup] = []
        keyed: dict[object, FeatureGroup] = {}
        for lane, spec in zip(self._lanes, specs):
            group = keyed.get(spec.feature_key) if spec.feature_key is not None else None
            if group is None:
                group = FeatureGroup(spec.extractor_factory, spec.feature_key)
                self._groups.append(group)
                if spec.feature_key is not None:
                    keyed[spec.feature_key] = group
            group.lanes.append(lane)
            lane.group = group
        self._states: dict[int, SourceState] = {}
        self._active: AudioSource = source
        self.ring = self._state(source).ring
        self.compute_ms = RollingStats(self.config.stats_size)  # the whole hop, every performer
        self.features_ms = RollingStats(self.config.stats_size)  # the input stage's share of it
        self.compute_wait_ms = RollingStats(self.config.stats_size)  # of the hop: run-queue wait (runqueue_wait)
        self.compute_cpu_ms = RollingStats(self.config.stats_size)  # of the hop: the worker's CPU time (runqueue_wait)
        self.latency_ms = RollingStats(self.config.stats_size)  # every performer's frames
        self.error: BaseException | None = None
        self.state = "idle"
        self.warmup_seconds = 0.0
        self._chunk = np.zeros((self.config.max_read, source.channels), dtype=np.float32)
        self._mono = np.zeros(self.config.max_read, dtype=np.float32)
        self._settings_lock = threading.Lock()
        self._pending: list[tuple[str | None, str, float]] = []
        self._stop = threading.Event()
        self._done = threading.Event()
        self._reset_requested = threading.Event()
        self._lane_reset_requested = threading.Event()
        self._thread: threading.Thread | None = None
        self._hop_sinks: list[Sink] = []
        self._zero_counters()

    # -- the performers (the first one's for the single-performer attributes) -----------
    @property
    def performers(self) -> list[str]:
        """The performers' names, in lane order."""
        return [lane.name for lane in self._lanes]

    @property
    def model(self) -> PoseModel:
        return self._lanes[0].model

    @property
    def sinks(self) -> list[Sink]:
        """The first performer's sinks (a list the caller may append to before ``start``)."""
        return self._lanes[0].sinks

    @property
    def smoother(self) -> PoseSmoother:
        return self._lanes[0].smoother

    @property
    def extractor(self) -> FeatureStream | None:
        return self._groups[0].extractor

    @property
    def extractor_factory(self) -> ExtractorFactory:
        return self._groups[0].factory

    @property
    def extractors(self) -> list[FeatureStream | None]:
        """The input stage's feature extractors, one per distinct feature configuration."""
        return [g.extractor for g in self._groups]

    @property
    def frames_out(self) -> int:
        """Frames sent by the first performer (every performer sends one per frame)."""
        return self._lanes[0].frames_out

    @property
    def nan_frames(self) -> int:
        return sum(lane.nan_frames for lane in self._lanes)

    @property
    def last_frame(self) -> PoseFrame | None:
        return self._lanes[0].last_frame

    @property
    def idle(self) -> bool:
        """True when every performer was sent to its idle pose (``control("idle", 1)``)."""
        return all(lane.idle for lane in self._lanes)

    @property
    def phases(self) -> dict[str, int]:
        """Each performer's stagger: silence frames its model hears after a reset (see :class:`Performer`)."""
        return {lane.name: lane.phase for lane in self._lanes}

    def performer_compute_ms(self, name: str) -> RollingStats:
        """One performer's own part of each hop (its model, guard, smoothing, stamps and sends),
        ms per frame; ``compute_ms`` is the whole hop."""
        return self._lane(name).compute_ms

    def performer_compute_cpu_ms(self, name: str) -> RollingStats:
        """The worker thread's CPU time in each of :meth:`performer_compute_ms`'s parts, ms per
        frame: no time spent waiting for a CPU or for the interpreter lock."""
        return self._lane(name).compute_cpu_ms

    @property
    def _time0(self) -> float:
        return self._groups[0].time0

    def _zero_counters(self) -> None:
        self.bad_samples = 0
        self.source_errors = 0
        self.stalls = 0
        self.resets = 0
        self.fallbacks = 0
        for lane in self._lanes:
            lane.zero()
        for g in self._groups:
            g.index = g.seg_index0 = 0
            g.time0 = 0.0
        self._origin = 0  # ring position where the current extractor segment began
        self._consumed = 0
        self._started_at = time.monotonic()
        for st in self._states.values():
            st.down = st.need_start = False

    # -- control -----------------------------------------------------------------------
    def start(self) -> None:
        """Warm up on the worker thread, clear state, start the source; returns once audio flows.

        The warm-up runs on the worker thread itself, so per-thread first-call costs (torch,
        allocators) are paid before the first real block. No-op while running; after the
        input ended (``wait()`` returned) it starts anew. Raises what the warm-up or the
        source's ``start`` raised.
        """
        if self._thread is not None:
            if self._thread.is_alive():
                return
            self.stop()
        if self.config.threads:
            import torch

            torch.set_num_threads(int(self.config.threads))
        self._active = self.source
        self.ring = self._state(self.source).ring
        if self._chunk.shape[1] != self.source.channels:
            self._chunk = np.zeros((self.config.max_read, self.source.channels), dtype=np.float32)
        for g in self._groups:
            g.extractor = g.factory(self.source.sample_rate)
        # sinks that hold their thread hand-offs while the hop's performers run (Sink's begin_hop / end_hop)
        self._hop_sinks = [s for lane in self._lanes for s in lane.sinks if hasattr(s, "begin_hop")]
        for lane in self._lanes:
            publish_state(lane)  # the viewer draws the stage
        self.error = None
        self._stop.clear()
        self._done.clear()
        warmed, go = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._worker, args=(warmed, go), name="engine worker", daemon=True)
        self._thread.start()
        warmed.wait()
        try:
            if self.error is not None:
                raise self.error
            self.ring.clear()
            self._zero_counters()
            for lane in self._lanes:
                lane.smoother.reset()
                lane.delayed.clear()
            self._reset_requested.clear()
            self.source.start(self.ring)
        except BaseException:
            self._stop.set()
            go.set()
            self._thread.join()
            self._thread = None
            raise
        self.state = "running"
        self._last_audio = time.monotonic()
        go.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the worker, then the source; frames still held back by ``offset_ms`` are dropped."""
        self._stop.set()
        self.ring.wake()
        if self._thread is not None:
            self._thread.join(timeout)  # first, so the worker is not restarting a failed source
            self._thread = None
        self.source.stop()
        if self.fallback_source is not None:
            self.fallback_source.stop()
        if self.state in ("running", "stalled", "source error", "fallback"):
            self.state = "stopped"

    def close(self) -> None:
        """Stop, then close every performer's sinks (a recorder writes its file here)."""
        self.stop()
        closed: set[int] = set()
        for lane in self._lanes:
            for sink in lane.sinks:
                if id(sink) in closed:
                    continue
                closed.add(id(sink))
                try:
                    sink.close()
                except Exception as exc:  # noqa: BLE001 - one bad sink must not keep others open
                    log.warning("closing output %s failed: %s", getattr(sink, "name", sink), exc)

    def reset(self) -> None:
        """Clear extractor, model and smoothing state; frame indices restart at 0.

        Every performer. Thread-safe: while running, the worker does it before its next step.
        """
        if self._thread is not None:
            self._reset_requested.set()
            self.ring.wake()
        else:
            self._do_reset()

    def reset_performer(self, name: str) -> None:
        """Restart one performer's dance: its model and smoothing state (the shared input stage,
        the frame numbering and the other performers go on; its stagger is kept). Thread-safe."""
        lane = self._lane(name)
        if len(self._lanes) == 1:
            self.reset()
        elif self._thread is not None:
            lane.reset_requested.set()
            self._lane_reset_requested.set()
            self.ring.wake()
        else:
            self._reset_lane(lane)

    def update(self, performer: str | None = None, **settings: float) -> None:
        """Change live settings (``offset_ms``, ``smoothing``) without stopping, of every
        performer (``performer`` None or ``"*"``) or of the one named.

        Validated here (:class:`ConfigError` naming the setting, nothing applied); applied
        on the worker thread before its next step. Smoothing keeps its state. A new
        offset applies to frames made from then on; frames already held back keep their
        send time, and no frame overtakes another. Thread-safe.
        """
        who = self._lane(performer).name if self._named(performer) else None
        if len(self._lanes) == 1:
            who = None  # one performer: its settings are the engine's
        checked = [(who, name, check_live_setting(name, value)) for name, value in settings.items()]
        with self._settings_lock:
            self._pending.extend(checked)
        if self._thread is None or not self._thread.is_alive():
            self._apply_settings()
        else:
            self.ring.wake()

    def control(self, action: str, value: object = None, performer: str | None = None) -> None:
        """One control command, as the WebSocket and OSC control inputs send them.

        Actions (:data:`CONTROL_ACTIONS`): ``reset``; ``set_offset`` (ms) and
        ``set_smoothing`` (through :meth:`update`); ``idle`` (0/1, see :meth:`set_idle`);
        ``style`` (a name), ``energy`` and ``lead`` (numbers; the lead in ms), ``stage`` ("WxD"
        metres or 0) and ``facing`` (free, audience), passed to the pose model's ``set_style`` /
        ``set_energy`` / ``set_lead`` / ``set_stage`` / ``set_facing`` when it has them, and
        ``home`` (no value) to its ``home``, and refused otherwise (models/networks/stage.py). ``performer``: None or ``"*"`` acts on every performer (``reset``: the whole engine, as
        :meth:`reset`), a name on that one (``reset``: :meth:`reset_performer`). Every value
        is checked, against every performer it goes to, before anything changes; a bad one,
        an unknown action or performer, or a control a model does not offer raises
        :class:`ConfigError` (one line) and changes nothing. Thread-safe; never waits on the worker.
        """
        apply_control(self, action, value, performer)  # realtime/controls.py: one dispatch for every input

    def set_idle(self, idle: bool, performer: str | None = None) -> None:
        """Settle into the idle pose and hold it (True), or dance again (False), without a jump;
        every performer, or the one named.

        A pose model with ``set_idle`` does it itself; otherwise the engine crossfades its
        output over ``idle_fade_s`` (1 s) towards :func:`idle_pose` and holds that while
        idle, and crossfades back to the live dance afterwards (:class:`IdleFader`; the
        model keeps listening meanwhile, so it comes back in time with the music). The
        state survives :meth:`reset`. Thread-safe.
        """
        for lane in [self._lane(performer)] if self._named(performer) else self._lanes:
            self._set_lane_idle(lane, bool(idle))

    def _set_lane_idle(self, lane: Lane, idle: bool) -> None:
        set_model_idle = getattr(lane.model, "set_idle", None)
        if callable(set_model_idle):
            set_model_idle(bool(idle))
        else:
            lane.fader.idle = bool(idle)
        if lane.idle != bool(idle):
            log.info("%sidle %s", self._who(lane), "on" if idle else "off")
        lane.idle = bool(idle)

    @staticmethod
    def _named(performer: object) -> bool:
        return performer is not None and performer != "*"

    def _lane(self, name: object) -> Lane:
        lane = self._by_name.get(name) if isinstance(name, str) else None
        if lane is None:
            raise ConfigError(f"unknown performer {short_repr(name)} (performers: {', '.join(self._by_name)})")
        return lane

    def _who(self, lane: Lane) -> str:
        """``"performer NAME: "`` in an ensemble, ``""`` for a single performer (log prefixes)."""
        return f"performer {lane.name}: " if len(self._lanes) > 1 else ""

    def applied(self) -> dict[str, dict]:
        """What each performer runs with now, by name (:func:`realtime.controls.applied`). Thread-safe reads."""
        return {lane.name: applied(lane) for lane in self._lanes}

    @property
    def models(self) -> dict[str, PoseModel]:
        """Each performer's pose model, by name (read its state; steer it through :meth:`control`)."""
        return {lane.name: lane.model for lane in self._lanes}

    @property
    def active_source(self) -> AudioSource:
        """The source audio is read from now (``source``, or ``fallback_source`` in state ``fallback``)."""
        return self._active

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the source's audio was all processed; True if so. Re-raises a worker error."""
        done = self._done.wait(timeout)
        if self.error is not None:
            raise self.error
        return done

    @property
    def running(self) -> bool:
        return self._thread is not None and not self._done.is_set()

    # -- statistics --------------------------------------------------------------------
    def stats(self) -> dict:
        """Counters for the status line: frames, idle, the live settings (offset_ms, smoothing),
        compute/latency p50/p99 (ms), faults, sinks, the sinks' notices; and per performer under
        ``performers`` (its frames, settings, stagger, compute and latency, faults and sinks)."""
        per: dict[str, dict] = {}
        sinks: dict[str, dict] = {}
        notices: list[str] = []
        for lane in self._lanes:
            notices += [n for n in lane.sink_notices() if n not in notices]
            lane_sinks = lane.sink_stats()
            sinks.update(lane_sinks if len(self._lanes) == 1 else
                         {f"{lane.name}/{k}": v for k, v in lane_sinks.items()})
            per[lane.name] = lane.stats(lane_sinks)
        src = {}
        try:
            src = dict(self.source.stats())
        except Exception:  # noqa: BLE001
            pass
        return {
            "state": self.state,
            "frames": self.frames_out,
            "idle": self.idle,
            "offset_ms": self._common("offset_ms"),
            "smoothing": self._common("smoothing"),
            "audio_seconds": self._time0 + (self._consumed - self._origin) / self._active.sample_rate,
            "uptime_s": time.monotonic() - self._started_at,
            "compute_ms_p50": self.compute_ms.percentile(50),
            "compute_ms_p99": self.compute_ms.percentile(99),
            "features_ms_p50": self.features_ms.percentile(50),
            "features_ms_p99": self.features_ms.percentile(99),
            "latency_ms_p50": self.latency_ms.percentile(50),
            "latency_ms_p99": self.latency_ms.percentile(99),
            "nan_frames": self.nan_frames,
            "bad_samples": self.bad_samples,
            "fallbacks": self.fallbacks,
            "input": self._active.name,
            "sink_errors": sum(p["sink_errors"] for p in per.values()),
            "overruns": self.ring.overruns,
            "dropped_samples": self.ring.dropped_samples,
            "source_errors": self.source_errors,
            "stalls": self.stalls,
            "warmup_s": self.warmup_seconds,
            "extractors": len(self._groups),
            "source": src,
            "sinks": sinks,
            "notices": notices,
            "performers": per,
        }

    def _common(self, setting: str) -> float | None:
        """A live setting every performer shares (the engine's, for one performer), else None."""
        values = {lane.offset_ms if setting == "offset_ms" else lane.smoother.alpha for lane in self._lanes}
        return values.pop() if len(values) == 1 else None

    # -- internals ---------------------------------------------------------------------
    def _warm_up(self) -> None:
        """Run :data:`KERNEL_NOISE_S` of noise, then ``warmup_s`` of silence, through the extractors,
        every model and the pose guard, then reset them (``warmup_s`` 0: no warm-up at all).

        The noise takes the paths only sound takes (the dance_vq music gate), in device-sized
        blocks and in large ones (pushes of one frame and of several), so that every numba kernel
        of the live path is compiled, or loaded from numba's cache, here and not inside the
        first streamed frames (:mod:`realtime.kernels`)."""
        t0 = time.perf_counter()
        rate = self.source.sample_rate
        if self.config.warmup_s > 0:
            noise = (0.1 * np.random.default_rng(0).standard_normal(int(KERNEL_NOISE_S * rate))).astype(np.float32)
            half = len(noise) // 2
            for step, lo, hi in ((512, 0, half), (self.config.max_read, half, len(noise))):
                for i in range(lo, hi, step):
                    self._warm_block(noise[i : min(i + step, hi)])
        n = int(self.config.warmup_s * rate)
        block = np.zeros(min(self.config.max_read, max(n, 1)), dtype=np.float32)
        done = 0
        while done < n:
            k = min(len(block), n - done)
            self._warm_block(block[:k])
            done += k
        self._do_reset()
        self.warmup_seconds = time.perf_counter() - t0

    def _warm_block(self, block: np.ndarray) -> None:
        """One warm-up block (n,) float32 through every extractor, model and pose guard; nothing sent."""
        for g in self._groups:
            feats = g.extractor.push(block)
            if len(feats):
                for lane in g.lanes:
                    poses = lane.model.push(feats)
                    pose = np.empty(POSE_DIM, np.float32)
                    for row in np.asarray(poses, dtype=np.float32):
                        if row.shape == pose.shape:  # a non-finite row is skipped, as the guard skips it
                            lane.smoother.smooth_into(row, pose)

    def _do_reset(self) -> None:
        self._reset_requested.clear()
        for g in self._groups:
            if g.extractor is not None:
                g.extractor.reset()
            g.time0 += (self._consumed - self._origin) / self._active.sample_rate
            g.index = g.seg_index0 = 0
        for lane in self._lanes:
            lane.reset_requested.clear()
            self._reset_lane(lane)
        self._origin = self._consumed
        self.resets += 1

    def _reset_lane(self, lane: Lane) -> None:
        """Restart one lane's model and smoothing; then its stagger: as many silence feature frames
        as put its cycle at ``phase`` frames ahead of the group's frame numbering."""
        lane.model.reset()
        lane.smoother.reset()
        lead = (lane.phase + lane.group.index) % lane.cycle
        if lead:
            row = lane.group.silence_row()
            if row is not None:
                lane.model.push(np.repeat(row[None], lead, axis=0))

    def _reset_lanes(self) -> None:
        self._lane_reset_requested.clear()
        for lane in self._lanes:
            if lane.reset_requested.is_set():
                lane.reset_requested.clear()
                self._reset_lane(lane)
                lane.resets += 1
                log.info("%sreset", self._who(lane))

    def _apply_settings(self) -> None:
        with self._settings_lock:
            pending, self._pending = self._pending, []
        for who, name, value in pending:
            if who is None:
                old = getattr(self.config, name)
                setattr(self.config, name, value)
                if old != value:
                    log.info("%s changed from %g to %g", name, old, value)
            for lane in self._lanes if who is None else [self._by_name[who]]:
                old = lane.smoother.alpha if name == "smoothing" else lane.offset_ms
                if name == "smoothing":
                    lane.smoother.alpha = value
                else:
                    lane.offset_ms = value
                if who is not None and old != value:
                    log.info("performer %s: %s changed from %g to %g", who, name, old, value)

    def _worker(self, warmed: threading.Event, go: threading.Event) -> None:
        # With one torch thread (config.threads, the default) BLAS is held to one thread too for the
        # worker's life: its products are small, and a dance_vq performer then skips its per-frame
        # limit (models/networks/dance_numpy.py, single_thread_blas: up to 50 µs a frame each)
        hold = hold_single_thread_blas() if self.config.threads == 1 else contextlib.nullcontext()
        try:
            with hold:
                try:
                    self._warm_up()
                except BaseException as exc:  # noqa: BLE001 - for start(), before it reads it (re-raised below)
                    self.error = exc
                    raise
                finally:
                    warmed.set()
                go.wait()
                if not self._stop.is_set():
                    self._loop()
        except BaseException as exc:  # noqa: BLE001 - kept and re-raised by start() / wait()
            self.error = exc
            self.state = "failed"
            log.error("engine stopped: %s: %s", type(exc).__name__, exc)
        finally:
            self._done.set()

    def _next_release(self) -> float | None:
        """The earliest send instant of a frame held back by an offset, or None."""
        due = [lane.delayed[0][0] for lane in self._lanes if lane.delayed]
        return min(due) if due else None

    def _loop(self) -> None:
        cfg = self.config
        acc = 0.0  # compute seconds since the last emitted frame
        acc_in = 0.0  # of which the input stage (mixdown, sanitising, features)
        acc_wait = 0.0  # of which runnable but not running (runqueue_wait)
        acc_cpu = 0.0  # the worker's CPU time in it (runqueue_wait)
        waited = RunQueueClock() if cfg.runqueue_wait else None
        while not self._stop.is_set():
            if self._reset_requested.is_set():
                self._do_reset()
            if self._lane_reset_requested.is_set():
                self._reset_lanes()
            if self._pending:
                self._apply_settings()
            now = time.monotonic()
            self._release_delayed(now)
            if self.fallback_source is not None:
                self._watch_fallback(now)
            src, st = self._active, self._states[id(self._active)]
            want = len(self._chunk)
            if cfg.duration_s is not None:  # audio left before duration_s, in this source's samples
                left = round((cfg.duration_s - self._time0) * src.sample_rate) + self._origin - self._consumed
                want = min(want, left)
            n = self.ring.read_into(self._chunk[:want]) if want > 0 else 0
            if n == 0:
                if want <= 0 or (src is self.source and src.finished and self.ring.available == 0):
                    self._finish()
                    return
                if src.error or st.down:
                    self._revive(src, st, now)
                    self.state = "source error"
                elif self.state in ("running", "fallback") and now - self._last_audio > cfg.stall_timeout_s:
                    self.state = "stalled"
                    self.stalls += 1
                    log.warning("no audio from %s for %.1f s; holding the last pose", src.name,
                                now - self._last_audio)
                timeout = 0.05
                due = self._next_release()
                if due is not None:
                    timeout = min(timeout, max(0.0, due - now))
                self.ring.wait(timeout)
                continue
            live = "running" if src is self.source else "fallback"
            if self.state != live:
                if self.state in ("stalled", "source error"):
                    log.warning("audio from %s is back; resuming", src.name)
                self.state = live
            st.down = False
            self._last_audio = now
            w0, c0 = waited() if waited is not None else (0.0, 0.0)  # the clock's reads: outside the hop
            t0 = time.perf_counter()
            block = self._sanitize(self._mixdown(n))
            p0 = self._consumed
            self._consumed += n
            ready = []
            for g in self._groups:
                feats = g.extractor.push(block)
                if len(feats):
                    ready.append((g, feats))
            t_in = time.perf_counter() - t0
            if not ready:
                acc += t_in
                acc_in += t_in
                if waited is not None:
                    w1, c1 = waited(after=True)
                    acc_wait += hop_wait(t_in, w1 - w0, c1 - c0)
                    acc_cpu += c1 - c0
                continue
            frames = max(len(feats) for _, feats in ready)
            self._run_lanes(ready, p0)
            hop = time.perf_counter() - t0
            per_frame_ms = (acc + hop) * 1000.0 / frames
            in_ms = (acc_in + t_in) * 1000.0 / frames
            wait_ms = cpu_ms = 0.0
            if waited is not None:
                w1, c1 = waited(after=True)
                wait_ms = (acc_wait + hop_wait(hop, w1 - w0, c1 - c0)) * 1000.0 / frames
                cpu_ms = (acc_cpu + c1 - c0) * 1000.0 / frames
            for _ in range(frames):
                self.compute_ms.add(per_frame_ms)
                self.features_ms.add(in_ms)
                if waited is not None:
                    self.compute_wait_ms.add(wait_ms)
                    self.compute_cpu_ms.add(cpu_ms)
            acc = acc_in = acc_wait = acc_cpu = 0.0

    def _sanitize(self, block: np.ndarray) -> np.ndarray:
        """In place: samples that are NaN, inf or beyond +-MAX_SAMPLE become 0 (a dropout),
        counted in ``bad_samples`` and logged once.

        The common case costs a max and a min and no allocation: both are NaN when any
        sample is (NumPy's reductions propagate NaN, and NaN fails every comparison), and an
        infinite sample is beyond +-MAX_SAMPLE.
        """
        if -MAX_SAMPLE <= block.min() and block.max() <= MAX_SAMPLE:
            return block
        bad = ~(np.abs(block) <= MAX_SAMPLE)  # NaN compares False: bad too
        if self.bad_samples == 0:
            log.warning("audio from %s holds NaN/inf samples or samples beyond +-%g full scale; replacing them "
                        "by silence (counted in bad_samples)", self._active.name, MAX_SAMPLE)
        self.bad_samples += int(bad.sum())
        block[bad] = 0.0
        return block

    def _mixdown(self, n: int) -> np.ndarray:
        """Mono view of the first ``n`` samples read (mean over channels; no copy for mono)."""
        if self._chunk.shape[1] == 1:
            return self._chunk[:n, 0]
        np.mean(self._chunk[:n], axis=1, out=self._mono[:n])
        return self._mono[:n]

    def _frame_samples(self, g: FeatureGroup, count: int, p0: int) -> list[int]:
        """The completing input sample of the group's next ``count`` frames (this step read
        samples ``p0`` up to ``_consumed``)."""
        sr = self._active.sample_rate
        needed = getattr(g.extractor, "samples_needed", None)
        lat = int(getattr(g.extractor, "latency_samples", 0) or 0)
        out = []
        for k in range(count):
            j = g.index + k - g.seg_index0  # frame number within the current extractor segment
            if needed is not None:
                need = self._origin + int(needed(j))
            else:
                need = self._origin + math.ceil((j + 1) * HOP * sr / SAMPLE_RATE) + lat
            out.append(min(max(need, p0 + 1), self._consumed) - 1)
        return out

    def _run_lanes(self, ready: list[tuple[FeatureGroup, np.ndarray]], p0: int) -> None:
        """Every lane of every group that has frames: model, then guard, smoothing, stamps and sends."""
        plans = [(g, feats, self._frame_samples(g, len(feats), p0)) for g, feats in ready]
        if len(plans) == 1:
            released = {s: self.ring.release_time(s) for s in plans[0][2]}
        else:  # the ring's lookup only walks forward: ask in sample order across the groups
            released = {s: self.ring.release_time(s) for s in sorted({s for *_, ss in plans for s in ss})}
        for sink in self._hop_sinks:
            sink.begin_hop()
        try:
            self._run_groups(plans, released)
        finally:
            for sink in self._hop_sinks:
                sink.end_hop()

    def _run_groups(self, plans: list[tuple[FeatureGroup, np.ndarray, list[int]]], released: dict[int, float]) -> None:
        """Each group's lanes on its frames ``plans`` (group, features (k, D), completing samples)."""
        for g, feats, samples in plans:
            rel = [released[s] for s in samples]
            for lane in g.lanes:
                t, c = time.perf_counter(), time.thread_time()
                poses = np.asarray(lane.model.push(feats), dtype=np.float32)
                if len(poses) != len(feats):
                    raise ValueError(f"{self._who(lane)}the pose model returned {len(poses)} poses for "
                                     f"{len(feats)} feature frames")
                self._emit(lane, g, poses, samples, rel)
                lane_ms = (time.perf_counter() - t) * 1000.0 / len(poses)
                cpu_ms = (time.thread_time() - c) * 1000.0 / len(poses)
                for _ in range(len(poses)):
                    lane.compute_ms.add(lane_ms)
                    lane.compute_cpu_ms.add(cpu_ms)
            g.index += len(feats)

    def _emit(self, lane: Lane, g: FeatureGroup, poses: np.ndarray, samples: list[int],
              released: list[float]) -> None:
        """Guard, smooth, stamp and send (or hold back) one lane's poses from one push."""
        offset_s = lane.offset_ms / 1000.0
        for k, row in enumerate(poses):
            pose = np.empty(POSE_DIM, np.float32)
            if row.shape != (POSE_DIM,) or not lane.smoother.smooth_into(row, pose):  # guard and smoothing: one call
                lane.nan_frames += 1
                if lane.nan_frames == 1:
                    log.warning("%smodel produced a non-finite pose; sending the last good pose instead",
                                self._who(lane))
                pose = lane.last_good.copy()
            else:
                lane.last_good[:] = pose
            if lane.fader.active:  # after last_good: smoothing and the NaN guard keep the dance
                pose = lane.fader(pose)
            i = g.index + k
            j = i - g.seg_index0  # frame number within the current extractor segment
            audio_time = g.time0 + (j + 1) * HOP / SAMPLE_RATE + offset_s
            frame = PoseFrame(index=i, audio_sample=samples[k], audio_time=audio_time, wall_time=0.0, pose=pose)
            if offset_s > 0 or lane.delayed:  # after an offset decrease, frames still queue: order is kept
                send_at = time.monotonic() + max(offset_s, 0.0)
                if lane.delayed:
                    send_at = max(send_at, lane.delayed[-1][0])
                lane.delayed.append((send_at, frame, released[k]))
            else:
                self._send(lane, frame, released[k])

    def _release_delayed(self, now: float) -> None:
        for lane in self._lanes:
            while lane.delayed and lane.delayed[0][0] <= now:
                _, frame, released = lane.delayed.popleft()
                self._send(lane, frame, released)

    def _send(self, lane: Lane, frame: PoseFrame, released: float) -> None:
        frame.wall_time = time.monotonic()
        frame.released = released
        for sink in lane.sinks:
            try:
                sink.send(frame)
            except Exception as exc:  # noqa: BLE001 - an output fault never stops the engine
                name = getattr(sink, "name", repr(sink))
                n = lane.sink_errors.get(name, 0) + 1
                lane.sink_errors[name] = n
                if n == 1:
                    log.warning("%soutput %s failed (%s: %s); counting further failures silently",
                                self._who(lane), name, type(exc).__name__, exc)
        lane.frames_out += 1
        lane.last_frame = frame
        if released == released:  # not NaN
            ms = (frame.wall_time - released) * 1000.0
            lane.latency_ms.add(ms)
            self.latency_ms.add(ms)

    def _finish(self) -> None:
        """End of input: send what ``offset_ms`` still holds back, then mark done."""
        while not self._stop.is_set():
            due = self._next_release()
            if due is None:
                break
            wait = due - time.monotonic()
            if wait > 0:
                self._stop.wait(wait)
            self._release_delayed(time.monotonic())
        self.state = "finished"


__all__ = ["Engine", "KERNEL_NOISE_S", "MAX_SAMPLE"]
