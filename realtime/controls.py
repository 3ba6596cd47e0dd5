"""Show controls: the one dispatch every control input goes through, and what each control applied.

:meth:`realtime.engine.Engine.control` calls :func:`apply_control`; the OSC control input
(:mod:`realtime.osc_control`), the WebSocket control channel and the show desk
(:mod:`realtime.desk`) all reach it through ``Engine.control``, so a control does the same
from each. Every value is checked, against every performer it goes to, before anything
changes; a bad one raises :class:`~models.errors.ConfigError` (one line).

:func:`applied` reads back what a performer runs with now (its pose model's own
attributes and the engine's idle, offset and smoothing): the show desk shows these, not
the value a desk sent. This module is the engine's control half: it uses the engine's
lanes (``engine._lane``, ``engine._lanes``) and imports nothing of :mod:`realtime.engine`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from models.errors import ConfigError, short_repr

log = logging.getLogger("realtime.engine")

#: Actions of :meth:`Engine.control` (the WebSocket, OSC and desk control inputs use these).
CONTROL_ACTIONS: tuple[str, ...] = ("reset", "set_offset", "set_smoothing", "idle", "style", "energy", "lead", "stage",
                                    "facing", "home")

#: Longest style name :meth:`Engine.control` passes to a model, characters.
MAX_STYLE_CHARS: int = 64


def check_finite(name: str, value: object) -> float:
    """A finite real number (not a bool) as a float; :class:`ConfigError` naming ``name`` otherwise."""
    try:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise OverflowError
    except OverflowError:  # also an int too large for a float
        raise ConfigError(f"{name} must be a finite number, got {short_repr(value)}") from None
    return float(value)


def check_switch(name: str, value: object) -> bool:
    """An on/off control value: ``True``/``False``, or a number equal to 0 or 1 (an OSC
    ``i`` 0/1, or a TouchOSC toggle's ``f`` 0.0/1.0). :class:`ConfigError` naming ``name`` otherwise."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, float)) and value in (0, 1):  # NaN is neither
        return bool(value)
    raise ConfigError(f"{name} must be 0 or 1, got {short_repr(value)}")


def check_style_name(value: object) -> str:
    """A style name: a non-empty string of at most :data:`MAX_STYLE_CHARS` printable characters."""
    if not isinstance(value, str) or not value or len(value) > MAX_STYLE_CHARS or not value.isprintable():
        raise ConfigError(f"style must be a style name (1..{MAX_STYLE_CHARS} printable characters), "
                          f"got {short_repr(value)}")
    return value


def model_control(engine, lane, method: str, what: str) -> Callable:
    """The lane's pose model's ``method``, or :class:`ConfigError` "this model offers no ``what`` control"."""
    fn = getattr(lane.model, method, None)
    if not callable(fn):
        raise ConfigError(f"{engine._who(lane)}this model offers no {what} control")
    return fn


def publish_state(lane) -> None:
    """Tell the lane's sinks that show a stage (``set_state``: the WebSocket viewer's) the
    model's stage and facing (models/networks/stage.py), if it has one."""
    stage = getattr(lane.model, "stage", None)
    if stage is None or not hasattr(stage, "width"):
        return
    state = stage.state() if callable(getattr(stage, "state", None)) else {  # an ensemble's: with its spot
        "stage": [float(stage.width), float(stage.depth)], "facing": str(stage.facing)}
    for sink in lane.sinks:
        set_state = getattr(sink, "set_state", None)
        if callable(set_state):
            set_state(state)


def apply_control(engine, action: str, value: object = None, performer: str | None = None) -> None:
    """One control command on ``engine`` (:meth:`realtime.engine.Engine.control` documents the actions)."""
    named = engine._named(performer)
    lanes = [engine._lane(performer)] if named else engine._lanes
    if action == "reset":
        if named:
            engine.reset_performer(lanes[0].name)
        else:
            engine.reset()
    elif action == "set_offset":
        engine.update(performer, offset_ms=value)
    elif action == "set_smoothing":
        engine.update(performer, smoothing=value)
    elif action == "idle":
        idle = check_switch("idle", value)
        for lane in lanes:
            engine._set_lane_idle(lane, idle)
    elif action == "style":
        fns = [model_control(engine, lane, "set_style", "style") for lane in lanes]
        style = check_style_name(value)
        for fn in fns:
            fn(style)
    elif action in ("energy", "lead"):
        fns = [model_control(engine, lane, f"set_{action}", action) for lane in lanes]
        number = check_finite(action, value)
        for fn in fns:
            fn(number)
    elif action in ("stage", "facing"):
        from models.networks.stage import check_facing, parse_stage

        fns = [model_control(engine, lane, f"set_{action}", action) for lane in lanes]
        setting = parse_stage(value) if action == "stage" else check_facing(value)
        for fn in fns:
            fn(setting)
        for lane in lanes:
            publish_state(lane)
    elif action == "home":
        for fn in [model_control(engine, lane, "home", "home") for lane in lanes]:
            fn()
    else:
        raise ConfigError(f"unknown control action {short_repr(action)}; use {', '.join(CONTROL_ACTIONS)}")


def applied(lane) -> dict:
    """What one performer runs with now, read back from the engine and its pose model: ``idle``
    (bool), ``offset_ms``, ``smoothing``, and where the model offers them ``style`` (a name,
    ``"auto"``), ``energy`` (0..2), ``lead_ms``, ``stage`` ([W, D] metres, or 0: in place) and
    ``facing``; a control the model lacks is None."""
    from models.networks.dance_vq import STYLES

    model = lane.model
    style = getattr(model, "style", None)
    if isinstance(style, int) and not isinstance(style, bool):
        style = STYLES[style - 1] if 0 < style <= len(STYLES) else "auto"
    stage = getattr(model, "stage", None)
    has_stage = stage is not None and hasattr(stage, "width")
    return {
        "idle": bool(lane.idle),
        "offset_ms": float(lane.offset_ms),
        "smoothing": float(lane.smoother.alpha),
        "style": style if callable(getattr(model, "set_style", None)) else None,
        "energy": _number(model, "energy", "set_energy"),
        "lead_ms": _number(model, "lead_ms", "set_lead"),
        "stage": ([float(stage.width), float(stage.depth)] if stage.active else 0) if has_stage else None,
        "facing": str(stage.facing) if has_stage else None,
    }


def _number(model, attr: str, setter: str) -> float | None:
    value = getattr(model, attr, None)
    return float(value) if callable(getattr(model, setter, None)) and isinstance(value, (int, float)) else None


__all__ = ["CONTROL_ACTIONS", "MAX_STYLE_CHARS", "check_finite", "check_switch", "check_style_name", "model_control",
           "publish_state", "apply_control", "applied"]
