"""``performer run`` settings: built-in defaults < TOML file (``--config``) < flags.

The TOML file is flat and uses the long flag names with ``_`` (or ``-``) for keys::

    audio = "songs/take3.wav"      # or: input_device = "USB Audio" (name or index)
    osc = ["127.0.0.1:39539", "192.168.1.20:39540"]
    osc_mode = "vmc"
    ws = "0.0.0.0:8765"
    smoothing = 0.3
    offset_ms = 80
    control_osc = "0.0.0.0:9000"   # OSC show control (docs/show.md)
    control_allow = ["192.168.1.0/24"]

Relative paths in the file are taken relative to the file's directory. An unknown
key or a value of the wrong type is a :class:`ConfigError` naming the file and key.

While running, ``performer run`` re-reads the file on SIGHUP and applies the
settings that can change live (:data:`realtime.engine.LIVE_SETTINGS`: ``offset_ms``,
``smoothing``); see :func:`live_changes`.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.errors import ConfigError

DEFAULT_OSC = "127.0.0.1:39539"  # VMC protocol's usual receiver port (VSeeFace, VMC receivers)
DEFAULT_WS = "127.0.0.1:8765"
OSC_MODES = ("vmc", "plain")
#: --style values: "auto" lets the music decide (dance_vq models; models.networks.dance_vq.STYLES)
STYLE_CHOICES = ("auto", "chacha", "rumba", "waltz")
#: Environment variable read for the WebSocket token when neither flag nor file sets one
#: (unlike a flag, it does not show in the process list).
TOKEN_ENV = "PERFORMER_WS_TOKEN"


@dataclass
class RunConfig:
    """Everything ``performer run`` needs; see ``performer run --help`` for each field."""

    audio: Path | None = None
    input_device: str | int | None = None
    sample_rate: int | None = None
    block_size: int = 512
    monitor: bool = False
    loop: bool = False
    fast: bool = False
    duration: float | None = None
    osc: list[str] = field(default_factory=lambda: [DEFAULT_OSC])
    osc_mode: str = "vmc"
    no_osc: bool = False
    ws: str = DEFAULT_WS
    no_ws: bool = False
    checkpoint: Path | None = None
    style: str = "auto"
    seed: int = 0
    record: Path | None = None
    threads: int = 1
    offset_ms: float = 0.0
    smoothing: float = 0.0
    warmup: float = 3.0
    fallback_audio: Path | None = None
    fallback_after: float = 2.0
    ws_token: str | None = None
    ws_viewers_open: bool = False
    ws_max_clients: int = 16
    ws_origin: list[str] = field(default_factory=list)
    control_osc: str | None = None
    control_allow: list[str] = field(default_factory=list)

    def validate(self) -> "RunConfig":
        """Check ranges and combinations; raise ConfigError naming the option."""
        if self.audio is not None and self.input_device is not None:
            raise ConfigError("give either audio (a file) or input_device, not both")
        if self.fast and self.audio is None:
            raise ConfigError("--fast only applies to file replay (--audio FILE)")
        if self.loop and (self.audio is None or self.fast):
            raise ConfigError("--loop replays a file in real time (--audio FILE without --fast)")
        if self.monitor and (self.audio is None or self.fast):
            raise ConfigError("--monitor plays a file replayed in real time (--audio FILE without --fast)")
        if self.style not in STYLE_CHOICES:
            raise ConfigError(f"style must be one of {STYLE_CHOICES}, got {self.style!r}")
        if self.osc_mode not in OSC_MODES:
            raise ConfigError(f"osc_mode must be one of {OSC_MODES}, got {self.osc_mode!r}")
        checks = [
            ("sample_rate", self.sample_rate is None or 4000 <= self.sample_rate <= 192000, "4000..192000 Hz"),
            ("block_size", 16 <= self.block_size <= 65536, "16..65536 samples"),
            ("duration", self.duration is None or 0 < self.duration < 1e9, "> 0 seconds (and finite)"),
            ("threads", 1 <= self.threads <= 64, "1..64"),
            ("offset_ms", -10000 <= self.offset_ms <= 10000, "-10000..10000 ms"),
            ("smoothing", 0.0 <= self.smoothing < 1.0, "[0, 1)"),
            ("warmup", 0.0 <= self.warmup <= 60.0, "0..60 seconds"),
            ("fallback_after", 0.05 <= self.fallback_after <= 3600.0, "0.05..3600 seconds"),
            ("ws_max_clients", 1 <= self.ws_max_clients <= 10000, "1..10000"),
        ]
        for name, ok, what in checks:
            if not ok:
                raise ConfigError(f"{name} must be {what}, got {getattr(self, name)!r}")
        if self.ws_token is not None and not self.ws_token.strip():
            raise ConfigError("ws_token must not be empty")
        if self.ws_viewers_open and self.ws_token is None:
            raise ConfigError(f"--ws-viewers-open needs a token (--ws-token, ws_token or ${TOKEN_ENV}): "
                              "without one every client is a viewer already")
        self.osc_targets()  # raise ConfigError now if an address is malformed
        self.ws_endpoint()
        if self.control_allow and self.control_osc is None:
            raise ConfigError("--control-allow limits the OSC control input: it needs --control-osc [HOST:]PORT")
        self.control_endpoint()
        self.control_networks()
        return self

    def osc_targets(self) -> list[tuple[str, int]]:
        """(host, port) of every OSC destination (empty with no_osc)."""
        return [] if self.no_osc else [parse_endpoint(e, "osc") for e in self.osc]

    def ws_endpoint(self) -> tuple[str, int] | None:
        """(host, port) the WebSocket server binds, or None with no_ws."""
        return None if self.no_ws else parse_endpoint(self.ws, "ws")

    def control_endpoint(self) -> tuple[str, int] | None:
        """(host, port) the OSC control input binds (a bare port: 127.0.0.1), or None (off)."""
        from realtime.osc_control import parse_control_endpoint

        return None if self.control_osc is None else parse_control_endpoint(self.control_osc)

    def control_networks(self) -> list | None:
        """The ``control_allow`` networks (ipaddress objects), or None when none are given (any sender)."""
        from realtime.osc_control import parse_networks

        return parse_networks(self.control_allow) if self.control_allow else None


_FIELDS = {f.name: f for f in dataclasses.fields(RunConfig)}
_PATHS = {"audio", "checkpoint", "record", "fallback_audio"}
_TYPES: dict[str, tuple[type, ...]] = {
    "audio": (str,), "input_device": (str, int), "sample_rate": (int,), "block_size": (int,),
    "monitor": (bool,), "loop": (bool,), "fast": (bool,), "duration": (int, float), "osc": (list, str),
    "osc_mode": (str,), "no_osc": (bool,), "ws": (str,), "no_ws": (bool,), "checkpoint": (str,), "style": (str,), "seed": (int,),
    "record": (str,), "threads": (int,), "offset_ms": (int, float), "smoothing": (int, float),
    "warmup": (int, float), "fallback_audio": (str,), "fallback_after": (int, float), "ws_token": (str,),
    "ws_viewers_open": (bool,), "ws_max_clients": (int,), "ws_origin": (list, str),
    "control_osc": (str, int), "control_allow": (list, str),
}
assert set(_TYPES) == set(_FIELDS)


def parse_endpoint(text: str, what: str = "endpoint") -> tuple[str, int]:
    """``"HOST:PORT"`` (``"[::1]:PORT"`` for IPv6) → (host, port); ConfigError if malformed."""
    host, sep, port = str(text).rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not (port.isascii() and port.isdigit()) or not 1 <= int(port) <= 65535:
        raise ConfigError(f"{what} address must be HOST:PORT with a port in 1..65535, got {text!r}")
    return host, int(port)


def load_run_config(path: str | Path) -> dict[str, Any]:
    """Read a run TOML file into ``{field: value}`` (only the keys it sets), type-checked."""
    p = Path(path)
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError("config file not found", source=p) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config file: {exc}", source=p) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", source=p) from None
    except RecursionError:
        raise ConfigError("invalid TOML: arrays or tables nested too deeply", source=p) from None
    out: dict[str, Any] = {}
    for key, value in raw.items():
        name = key.replace("-", "_")
        if name not in _FIELDS:
            raise ConfigError(f"unknown key {key!r} (known: {', '.join(sorted(_FIELDS))})", source=p)
        types = _TYPES[name]
        if isinstance(value, bool) and bool not in types or not isinstance(value, types):
            want = " or ".join(t.__name__ for t in types)
            raise ConfigError(f"key {key!r} must be {want}, got {type(value).__name__} {value!r}", source=p)
        if name in ("osc", "ws_origin", "control_allow"):
            value = [value] if isinstance(value, str) else value
            if not all(isinstance(v, str) for v in value):
                what = {"osc": '"HOST:PORT"', "ws_origin": "origin", "control_allow": "network"}[name]
                raise ConfigError(f"key {key!r} must be a list of {what} strings", source=p)
        if name in _PATHS:
            value = (p.parent / value) if not Path(value).is_absolute() else Path(value)
        if name == "control_osc":
            value = str(value)
        out[name] = value
    return out


def resolve_run_config(args: argparse.Namespace) -> RunConfig:
    """Defaults, then ``args.config`` (if set), then every flag that was given (not None)."""
    values: dict[str, Any] = {}
    if getattr(args, "config", None):
        values.update(load_run_config(args.config))
    for name in _FIELDS:
        v = getattr(args, name, None)
        if v is not None:
            values[name] = Path(v) if name in _PATHS else v
    device = values.get("input_device")
    if device is not None and str(device).isascii() and str(device).isdigit():
        values["input_device"] = int(values["input_device"])
    # A source given as a flag replaces a source of the other kind set in the file.
    flag_audio = getattr(args, "audio", None) is not None
    flag_device = getattr(args, "input_device", None) is not None
    if flag_audio and not flag_device:
        values.pop("input_device", None)
    if flag_device and not flag_audio:
        values.pop("audio", None)
    if values.get("ws_token") is None and os.environ.get(TOKEN_ENV):
        values["ws_token"] = os.environ[TOKEN_ENV]
    return RunConfig(**values).validate()


def live_changes(old: RunConfig, new: RunConfig) -> tuple[dict[str, float], list[str]]:
    """What a reload changes: ``({live setting: new value}, [other changed fields])``.

    Live settings (``offset_ms``, ``smoothing``) can be applied to a running engine;
    the other fields only take effect at the next start.
    """
    from realtime.engine import LIVE_SETTINGS

    live = {k: float(getattr(new, k)) for k in LIVE_SETTINGS if getattr(new, k) != getattr(old, k)}
    other = [f for f in _FIELDS if f not in LIVE_SETTINGS and getattr(new, f) != getattr(old, f)]
    return live, other
