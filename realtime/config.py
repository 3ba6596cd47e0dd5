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

An ensemble (several performers on the one audio input, docs/show.md) is a list of
``[[performer]]`` tables (or repeated ``--performer name=...,style=...`` flags), each with
the keys of :class:`PerformerConfig`; what a performer does not set it takes from the top
level::

    [[performer]]
    name = "alice"
    style = "waltz"
    [[performer]]
    name = "bob"
    seed = 7
    osc = "127.0.0.1:39600"

While running, ``performer run`` re-reads the file on SIGHUP and applies the
settings that can change live (:data:`realtime.engine_config.LIVE_SETTINGS`: ``offset_ms``,
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
from realtime.endpoints import parse_control_endpoint, parse_endpoint, parse_networks

DEFAULT_OSC = "127.0.0.1:39539"  # VMC protocol's usual receiver port (VSeeFace, VMC receivers)
DEFAULT_WS = "127.0.0.1:8765"
OSC_MODES = ("vmc", "plain")
#: --style values: "auto" lets the music decide (dance_vq models; models.networks.dance_vq.STYLES)
STYLE_CHOICES = ("auto", "chacha", "rumba", "waltz")
#: --energy range (dance_vq models; models.networks.dance_stream.ENERGY_RANGE, held equal by
#: tests/test_ensemble.py): 1 dances as the music asks, 0 calmest, 2 liveliest
ENERGY_RANGE = (0.0, 2.0)
#: --lead range, ms (dance_vq models; models.networks.dance_stream.LEAD_RANGE_MS, held equal by
#: tests/test_ensemble.py): the poses go out this far ahead of the audio, for a display chain's delay
LEAD_RANGE_MS = (0.0, 200.0)
#: Environment variable read for the WebSocket token when neither flag nor file sets one
#: (unlike a flag, it does not show in the process list).
TOKEN_ENV = "PERFORMER_WS_TOKEN"


#: Keys of one performer of an ensemble ([[performer]] in TOML, --performer on the command line).
PERFORMER_KEYS: tuple[str, ...] = ("name", "checkpoint", "style", "energy", "lead", "seed", "osc", "ws_path",
                                   "smoothing", "offset_ms", "record", "phase")
_PERFORMER_TYPES: dict[str, tuple[type, ...]] = {
    "name": (str,), "checkpoint": (str,), "style": (str,), "energy": (int, float), "lead": (int, float),
    "seed": (int,), "osc": (list, str), "ws_path": (str,),
    "smoothing": (int, float), "offset_ms": (int, float), "record": (str,), "phase": (int,),
}
#: Most performers in one process.
MAX_PERFORMERS: int = 64


@dataclass
class PerformerConfig:
    """One performer of an ensemble as given; None takes the top-level setting (see
    :meth:`RunConfig.performer_specs` for the defaults of ``osc``, ``ws_path`` and ``record``)."""

    name: str | None = None
    checkpoint: Path | None = None
    style: str | None = None
    energy: float | None = None
    lead: float | None = None
    seed: int | None = None
    osc: list[str] | None = None
    ws_path: str | None = None
    smoothing: float | None = None
    offset_ms: float | None = None
    record: Path | None = None
    phase: int | None = None


@dataclass
class PerformerSpec:
    """One performer with every setting resolved (:meth:`RunConfig.performer_specs`)."""

    name: str
    checkpoint: Path | None
    style: str
    seed: int
    osc: list[tuple[str, int]]
    ws_path: str
    smoothing: float
    offset_ms: float
    record: Path | None
    phase: int | None
    energy: float = 1.0
    lead: float = 0.0


def parse_performer(text: str) -> PerformerConfig:
    """One ``--performer`` value: ``NAME`` or ``name=NAME``, then ``,key=value`` pairs of
    :data:`PERFORMER_KEYS` (``osc`` may repeat: one target each), e.g.
    ``alice,style=waltz,seed=3,osc=127.0.0.1:39540``. ConfigError naming the bad part."""
    values: dict[str, Any] = {}
    for k, part in enumerate(str(text).split(",")):
        key, sep, value = part.partition("=")
        key, value = key.strip().replace("-", "_"), value.strip()
        if not sep and k == 0:
            key, value = "name", key
        if key not in PERFORMER_KEYS or not sep and k > 0:
            raise ConfigError(f"--performer {text!r}: {part!r} is not KEY=VALUE with a key of "
                              f"{', '.join(PERFORMER_KEYS)}")
        if key != "osc" and key in values:
            raise ConfigError(f"--performer {text!r}: {key} is given twice")
        try:
            if key in ("seed", "phase"):
                values[key] = int(value)
            elif key in ("smoothing", "offset_ms", "energy", "lead"):
                values[key] = float(value)
            elif key in ("checkpoint", "record"):
                values[key] = Path(value)
            elif key == "osc":
                values.setdefault("osc", []).append(value)
            else:
                values[key] = value
        except ValueError:
            raise ConfigError(f"--performer {text!r}: {key} must be a number, got {value!r}") from None
    return PerformerConfig(**values)


def _performer_from_toml(i: int, entry: object, p: Path) -> PerformerConfig:
    if not isinstance(entry, dict):
        raise ConfigError(f"performer must be a list of tables ([[performer]]), got {type(entry).__name__}", source=p)
    values: dict[str, Any] = {}
    for key, value in entry.items():
        name = _checked_key(key, value, _PERFORMER_TYPES, PERFORMER_KEYS, p, f"performer {i + 1}: ")
        if name == "osc":
            value = _string_list(key, value, '"HOST:PORT"', p, f"performer {i + 1}: ")
        if name in ("checkpoint", "record"):
            value = (p.parent / value) if not Path(value).is_absolute() else Path(value)
        values[name] = value
    if "name" not in values:
        raise ConfigError(f"performer {i + 1} has no name (name = \"...\")", source=p)
    return PerformerConfig(**values)


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
    vmc_root: str = "world"
    no_osc: bool = False
    ws: str = DEFAULT_WS
    no_ws: bool = False
    checkpoint: Path | None = None
    library: Path | None = None  # a motion library danced instead of (or with: mix) the checkpoint's memory
    mix: bool = False
    style: str = "auto"
    energy: float = 1.0
    lead: float = 0.0
    stage: str | None = None
    facing: str = "free"
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
    publish: str | None = None
    publish_subject: str = "performer"
    publish_credentials: Path | None = None
    publish_tls_ca: Path | None = None
    publish_cpus: str = "auto"
    control_osc: str | None = None
    control_allow: list[str] = field(default_factory=list)
    performer: list[PerformerConfig] = field(default_factory=list)

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
        if self.style not in STYLE_CHOICES and self.library is None:  # a library's folders: checked when it loads
            raise ConfigError(f"style must be one of {STYLE_CHOICES} (or a folder of --library), got {self.style!r}")
        if self.mix and self.library is None:
            raise ConfigError("mix plays the checkpoint's memory together with a library: give library = FILE.npz")
        if self.osc_mode not in OSC_MODES:
            raise ConfigError(f"osc_mode must be one of {OSC_MODES}, got {self.osc_mode!r}")
        from models.networks.stage import check_facing, parse_stage

        if self.stage is not None:
            parse_stage(self.stage)
        check_facing(self.facing)
        from realtime.vmc import check_root_mode

        check_root_mode(self.vmc_root)
        checks = [
            ("sample_rate", self.sample_rate is None or 4000 <= self.sample_rate <= 192000, "4000..192000 Hz"),
            ("block_size", 16 <= self.block_size <= 65536, "16..65536 samples"),
            ("duration", self.duration is None or 0 < self.duration < 1e9, "> 0 seconds (and finite)"),
            ("threads", 1 <= self.threads <= 64, "1..64"),
            ("offset_ms", -10000 <= self.offset_ms <= 10000, "-10000..10000 ms"),
            ("smoothing", 0.0 <= self.smoothing < 1.0, "[0, 1)"),
            ("energy", ENERGY_RANGE[0] <= self.energy <= ENERGY_RANGE[1], "0..2 (1: as the music asks)"),
            ("lead", LEAD_RANGE_MS[0] <= self.lead <= LEAD_RANGE_MS[1], "0..200 ms"),
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
        if self.publish is not None:  # the broker output (realtime/publish.py)
            from realtime.publish import check_broker_url, check_subject

            check_broker_url(self.publish)
            check_subject(self.publish_subject)
        from realtime.sched import check_publish_cpus

        self.publish_cpus = check_publish_cpus(self.publish_cpus)  # the publisher process's CPUs
        if self.control_allow and self.control_osc is None:
            raise ConfigError("--control-allow limits the OSC control input: it needs --control-osc [HOST:]PORT")
        self.control_endpoint()
        self.control_networks()
        self.performer_specs()
        return self

    def performer_specs(self) -> list[PerformerSpec]:
        """The ensemble's performers with every setting resolved (empty without ``performer``).

        Unset keys take the top level's ``checkpoint``, ``style``, ``energy``, ``lead``, ``seed``,
        ``smoothing`` and ``offset_ms``. ``osc``: performer ``i`` (from 0) sends to the top level's targets with
        each port raised by ``i`` (none with ``no_osc``); ``ws_path``: ``/ws/NAME``;
        ``record``: the top level's ``record`` with ``-NAME`` added to its name, if set.
        ConfigError naming the performer for a missing or repeated name, a style that is not
        one of :data:`STYLE_CHOICES`, two performers on one OSC target, WebSocket path or
        recording, or a value out of range.
        """
        if not self.performer:
            return []
        from realtime.performer import check_performer_name
        from realtime.recorder import record_paths
        from realtime.ws_server import check_ws_path

        if len(self.performer) > MAX_PERFORMERS:
            raise ConfigError(f"at most {MAX_PERFORMERS} performers in one process, got {len(self.performer)}")
        top_osc = self.osc_targets()
        out: list[PerformerSpec] = []
        seen: dict[str, dict[object, str]] = {"name": {}, "osc": {}, "ws_path": {}, "record": {}}
        for i, p in enumerate(self.performer):
            if p.name is None:
                raise ConfigError(f"performer {i + 1} has no name (name = \"...\", or --performer NAME,...)")
            name = check_performer_name(p.name)
            what = f"performer {name!r}"
            style = self.style if p.style is None else p.style
            if style not in STYLE_CHOICES and self.library is None:
                raise ConfigError(f"{what}: style must be one of {STYLE_CHOICES}, got {style!r}")
            energy = self.energy if p.energy is None else float(p.energy)
            if not ENERGY_RANGE[0] <= energy <= ENERGY_RANGE[1]:
                raise ConfigError(f"{what}: energy must be 0..2 (1: as the music asks), got {energy!r}")
            lead = self.lead if p.lead is None else float(p.lead)
            if not LEAD_RANGE_MS[0] <= lead <= LEAD_RANGE_MS[1]:
                raise ConfigError(f"{what}: lead must be 0..200 ms, got {lead!r}")
            smoothing = self.smoothing if p.smoothing is None else float(p.smoothing)
            offset = self.offset_ms if p.offset_ms is None else float(p.offset_ms)
            if not 0.0 <= smoothing < 1.0:
                raise ConfigError(f"{what}: smoothing must be [0, 1), got {smoothing!r}")
            if not -10000 <= offset <= 10000:
                raise ConfigError(f"{what}: offset_ms must be -10000..10000 ms, got {offset!r}")
            if p.phase is not None and not 0 <= p.phase < 1024:
                raise ConfigError(f"{what}: phase must be 0..1023 frames, got {p.phase!r}")
            if p.osc is not None:
                osc = [parse_endpoint(e, f"{what}: osc") for e in p.osc]
            else:
                osc = [(host, port + i) for host, port in top_osc]
                if any(port > 65535 for _, port in osc):
                    raise ConfigError(f"{what}: its default OSC port (the top level's + {i}) is above 65535; "
                                      "give it osc = \"HOST:PORT\"")
            ws_path = f"/ws/{name}" if p.ws_path is None else p.ws_path
            try:
                check_ws_path(ws_path)
            except ConfigError as exc:
                raise ConfigError(f"{what}: {exc}") from None
            record = p.record
            if record is None and self.record is not None:
                npz = record_paths(self.record)[0]
                record = npz.with_name(f"{npz.stem}-{name}{npz.suffix}")
            keys: dict[str, list] = {"name": [name], "osc": [f"{h}:{port}" for h, port in osc],
                                     "ws_path": [ws_path],
                                     "record": [] if record is None else [str(record_paths(record)[0])]}
            for kind, values in keys.items():
                for value in values:
                    other = seen[kind].get(value)
                    if other is not None:
                        if kind == "name":
                            raise ConfigError(f"performer name {name!r} is given twice")
                        raise ConfigError(f"performers {other!r} and {name!r} both use {kind} {value}; "
                                          "give each its own")
                    seen[kind][value] = name
            out.append(PerformerSpec(name, self.checkpoint if p.checkpoint is None else Path(p.checkpoint),
                                     style, self.seed if p.seed is None else int(p.seed), osc, ws_path,
                                     smoothing, offset, record, p.phase, energy, lead))
        return out

    def osc_targets(self) -> list[tuple[str, int]]:
        """(host, port) of every OSC destination (empty with no_osc)."""
        return [] if self.no_osc else [parse_endpoint(e, "osc") for e in self.osc]

    def ws_endpoint(self) -> tuple[str, int] | None:
        """(host, port) the WebSocket server binds, or None with no_ws."""
        return None if self.no_ws else parse_endpoint(self.ws, "ws")

    def control_endpoint(self) -> tuple[str, int] | None:
        """(host, port) the OSC control input binds (a bare port: 127.0.0.1), or None (off)."""
        return None if self.control_osc is None else parse_control_endpoint(self.control_osc)

    def control_networks(self) -> list | None:
        """The ``control_allow`` networks (ipaddress objects), or None when none are given (any sender)."""
        return parse_networks(self.control_allow) if self.control_allow else None


_FIELDS = {f.name: f for f in dataclasses.fields(RunConfig)}
_PATHS = {"audio", "checkpoint", "library", "record", "fallback_audio", "publish_credentials", "publish_tls_ca"}
_TYPES: dict[str, tuple[type, ...]] = {
    "audio": (str,), "input_device": (str, int), "sample_rate": (int,), "block_size": (int,),
    "monitor": (bool,), "loop": (bool,), "fast": (bool,), "duration": (int, float), "osc": (list, str),
    "osc_mode": (str,), "vmc_root": (str,), "no_osc": (bool,), "ws": (str,), "no_ws": (bool,), "checkpoint": (str,), "style": (str,),
    "energy": (int, float), "lead": (int, float), "stage": (str, int, float), "facing": (str,), "seed": (int,), "record": (str,), "threads": (int,), "offset_ms": (int, float),
    "smoothing": (int, float), "library": (str,), "mix": (bool,),
    "warmup": (int, float), "fallback_audio": (str,), "fallback_after": (int, float), "ws_token": (str,),
    "ws_viewers_open": (bool,), "ws_max_clients": (int,), "ws_origin": (list, str),
    "control_osc": (str, int), "control_allow": (list, str), "performer": (list,),
    "publish": (str,), "publish_subject": (str,), "publish_credentials": (str,), "publish_tls_ca": (str,),
    "publish_cpus": (str, int),
}
assert set(_TYPES) == set(_FIELDS)


def _checked_key(key: str, value: object, types: dict[str, tuple[type, ...]], known, p: Path, where: str = "") -> str:
    """``key`` of a TOML table as a field name (``-`` -> ``_``), its value type-checked; ConfigError
    naming the file (and ``where``, e.g. which performer) otherwise."""
    name = key.replace("-", "_")
    if name not in types:
        raise ConfigError(f"{where}unknown key {key!r} (known: {', '.join(known)})", source=p)
    allowed = types[name]
    if isinstance(value, bool) and bool not in allowed or not isinstance(value, allowed):
        want = " or ".join(t.__name__ for t in allowed)
        raise ConfigError(f"{where}key {key!r} must be {want}, got {type(value).__name__} {value!r}", source=p)
    return name


def _string_list(key: str, value: object, what: str, p: Path, where: str = "") -> list[str]:
    """A string or a list of strings as a list; ConfigError otherwise."""
    value = [value] if isinstance(value, str) else value
    if not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{where}key {key!r} must be a list of {what} strings", source=p)
    return value


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
        name = _checked_key(key, value, _TYPES, sorted(_FIELDS), p)
        if name in ("osc", "ws_origin", "control_allow"):
            what = {"osc": '"HOST:PORT"', "ws_origin": "origin", "control_allow": "network"}[name]
            value = _string_list(key, value, what, p)
        if name in _PATHS:
            value = (p.parent / value) if not Path(value).is_absolute() else Path(value)
        if name == "control_osc":
            value = str(value)
        if name == "performer":
            value = [_performer_from_toml(i, entry, p) for i, entry in enumerate(value)]
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
            if name == "performer":  # --performer flags replace the file's [[performer]] list
                v = [p if isinstance(p, PerformerConfig) else parse_performer(p) for p in v]
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

    Live settings (``offset_ms``, ``smoothing``) can be applied to a running engine, and so
    can ``stage`` and ``facing`` (:func:`realtime.commands.run.reload_settings` sends them as
    controls); the other fields only take effect at the next start.
    """
    from realtime.engine_config import LIVE_SETTINGS

    live = {k: float(getattr(new, k)) for k in LIVE_SETTINGS if getattr(new, k) != getattr(old, k)}
    other = [f for f in _FIELDS if f not in LIVE_SETTINGS and getattr(new, f) != getattr(old, f)]
    return live, other


def performer_live_changes(old: RunConfig, new: RunConfig) -> tuple[dict[str, dict[str, float]], list[str]]:
    """What a reload changes in an ensemble: ``({performer: {live setting: new value}}, [other
    changes])``. Live: each performer's resolved ``offset_ms`` and ``smoothing`` (its own, or
    the top level's it takes); a performer added, removed or otherwise changed, and the
    non-live top-level fields, need a restart."""
    from realtime.engine_config import LIVE_SETTINGS

    olds = {p.name: p for p in old.performer_specs()}
    news = {p.name: p for p in new.performer_specs()}
    live: dict[str, dict[str, float]] = {}
    other = [f for f in _FIELDS if f not in LIVE_SETTINGS and f != "performer" and getattr(new, f) != getattr(old, f)]
    if list(olds) != list(news):
        other.append("performer (names)")
    for name, p in news.items():
        q = olds.get(name)
        if q is None:
            continue
        changed = {k: float(getattr(p, k)) for k in LIVE_SETTINGS if getattr(p, k) != getattr(q, k)}
        if changed:
            live[name] = changed
        rest = [k for k in ("checkpoint", "style", "energy", "lead", "seed", "osc", "ws_path", "record", "phase")
                if getattr(p, k) != getattr(q, k)]
        other += [f"performer {name}: {k}" for k in rest]
    return live, other
