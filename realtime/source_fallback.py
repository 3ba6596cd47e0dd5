"""The engine's audio sources: their rings, failure and restart, and the fallback source.

:class:`SourceFallback` is the part of :class:`realtime.engine.Engine` that keeps one
:class:`SourceState` per source (its ring; reported down, to be restarted, when to retry),
restarts a failed source every ``retry_s`` (:meth:`~SourceFallback._revive`), and switches to
the fallback source and back (:meth:`~SourceFallback._watch_fallback`,
:meth:`~SourceFallback._switch_to`), all on the worker thread. It reads and writes the engine's
``source``, ``fallback_source``, ``config``, ``ring``, ``state``, ``_states``, ``_active``,
``_groups``, ``_chunk``, ``_consumed``, ``_origin``, ``_last_audio``, ``source_errors`` and
``fallbacks``; the engine's ``_loop`` calls it as its own methods.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from models.timebase import HOP, SAMPLE_RATE
from realtime.audio_input import AudioSource, RingBuffer

log = logging.getLogger("realtime.engine")  # the engine's log (tests and operators read it there)


@dataclass
class SourceState:
    """The engine's view of one audio source: its ring and its failure/restart state."""

    ring: RingBuffer
    down: bool = False  # reported failed; being restarted every retry_s until audio flows
    need_start: bool = False  # stopped after a failure; start() not yet successful
    retry_at: float = 0.0


class SourceFallback:
    """The engine's source handling, as methods of :class:`realtime.engine.Engine` (its base class)."""

    def _state(self, source: AudioSource) -> SourceState:
        """The ring and failure state of ``source`` (made on first use, remade if its format changed)."""
        st = self._states.get(id(source))
        if st is None or st.ring.channels != source.channels or st.ring.capacity < self._ring_capacity(source):
            st = SourceState(RingBuffer(self._ring_capacity(source), source.channels))
            self._states[id(source)] = st
        return st

    def _ring_capacity(self, source: AudioSource) -> int:
        return max(int(self.config.ring_seconds * source.sample_rate), 4 * self.config.max_read)

    def _revive(self, src: AudioSource, st: SourceState, now: float) -> None:
        """Report a failed source once, stop it, and try to restart it every ``retry_s``.

        The engine keeps its own ``down`` flag, because a source may clear ``error`` when a
        restart is attempted even if that attempt fails. Cleared when audio arrives.
        """
        if src.error and not st.need_start:
            if not st.down:
                st.down = True
                self.source_errors += 1
                log.warning("audio source %s failed: %s; holding the last pose and retrying every %.1f s",
                            src.name, src.error, self.config.retry_s)
            src.stop()
            st.need_start, st.retry_at = True, now + self.config.retry_s
        elif st.need_start and now >= st.retry_at:
            try:
                src.start(st.ring)
                st.need_start = False
            except Exception as exc:  # noqa: BLE001 - still gone; try again later
                log.debug("restarting %s failed: %s", src.name, exc)
                src.stop()
            st.retry_at = now + self.config.retry_s

    def _watch_fallback(self, now: float) -> None:
        """Switch to the fallback after ``fallback_after_s`` without audio; back when the source returns."""
        main, fallback = self.source, self.fallback_source
        assert fallback is not None
        mst = self._state(main)
        if self._active is main:
            # the ring check matters when one step computed longer than fallback_after_s
            if not main.finished and mst.ring.available == 0 and now - self._last_audio > self.config.fallback_after_s:
                fst = self._states.get(id(fallback))
                if fst is None or now >= fst.retry_at:
                    log.warning("no audio from %s for %.1f s; switching to the fallback %s",
                                main.name, now - self._last_audio, fallback.name)
                    self._switch_to(fallback, now)
            return
        if main.error or mst.down:  # keep trying to bring the main source back
            self._revive(main, mst, now)
        if mst.ring.available > 0 and not main.error:
            log.warning("audio from %s is back; leaving the fallback %s", main.name, fallback.name)
            mst.down = False
            self._switch_to(main, now)

    def _switch_to(self, src: AudioSource, now: float) -> bool:
        """Make ``src`` the active source without resetting the models (frame numbers and
        audio time continue on the 30 fps grid). The fallback is started on a clear ring
        when switched to and stopped when left. False (logged) if it cannot start."""
        st = self._state(src)
        if src is not self.source:
            st.ring.clear()
            try:
                src.start(st.ring)
            except Exception as exc:  # noqa: BLE001 - try again after retry_s
                log.warning("cannot start the fallback %s: %s", src.name, exc)
                src.stop()
                st.retry_at = now + self.config.retry_s
                return False
            self.fallbacks += 1
        else:
            self.fallback_source.stop()  # type: ignore[union-attr]
        for g in self._groups:
            g.time0 += (g.index - g.seg_index0) * HOP / SAMPLE_RATE
            g.seg_index0 = g.index
            g.extractor = g.factory(src.sample_rate)
        self._active, self.ring = src, st.ring
        if self._chunk.shape[1] != src.channels:
            self._chunk = np.zeros((self.config.max_read, src.channels), dtype=np.float32)
        self._consumed = self._origin = st.ring.read_position
        self._last_audio = now
        self.state = "running" if src is self.source else "fallback"
        return True
