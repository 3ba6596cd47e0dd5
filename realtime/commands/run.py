"""``performer run``: stream poses from live audio or a replayed file to OSC / WebSocket / a file."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

DESCRIPTION = """\
Listen to audio and stream the performer's pose, 30 frames per second: root position
and one quaternion per humanoid bone, over OSC (VMC protocol by default) and
WebSocket (which also serves the web viewer), optionally recorded to NPZ + BVH.

Audio comes from an input device (default: the system's default input) or from a
file replayed in real time (--audio FILE; --fast for as fast as possible).
Settings can come from a TOML file (--config); flags override it.
"""

EPILOG = """\
defaults: OSC to 127.0.0.1:39539 (VMC), WebSocket server on 127.0.0.1:8765,
one torch thread, no smoothing, no offset. Ctrl-C stops cleanly (the recording is
written) and exits with status 130; the end of a file or --duration exits with 0.
Errors about inputs (missing file, bad checkpoint, port in use) print one line and
exit with status 2. SIGHUP re-reads --config and applies offset_ms, smoothing, stage
and facing live (a bad file is reported and the current settings are kept). See
docs/engine.md, docs/reliability.md and docs/security.md.

show control (--control-osc, off by default; docs/show.md): OSC messages to
  /performer/reset                 restart the streaming state
  /performer/offset     NUMBER     stage offset in ms, -10000..10000
  /performer/smoothing  NUMBER     pose smoothing in [0, 1)
  /performer/idle       0|1        1: settle to the idle pose and hold it; 0: dance again
  /performer/style      STRING     style name (only models that offer styles)
  /performer/energy     NUMBER     0..2, 1: as the music asks (only models that offer it)
  /performer/lead       NUMBER     ms, 0..200: send the poses ahead for the display's delay (same)
  /performer/stage      STRING     "WxD" metres or "0" (in place); /performer/facing free|audience;
  /performer/home                  walk back to the centre of the stage (same)
A bad message is logged once per address, counted in the status line
("control N ok M bad") and changes nothing; the stream never stops for it.
In an ensemble these act on every performer, and /performer/NAME/reset (offset,
smoothing, idle, style, energy, lead) on the one called NAME.

show desk: http://HOST:PORT/desk.html on the WebSocket port (printed at start) shows what the
performer hears and does and steers it like the addresses above; watching as the viewer may,
steering only with --ws-token (docs/show.md, "The show desk").

ensemble (several performers on one audio input; docs/show.md): repeat --performer,
or give [[performer]] tables in --config. Each performer has its own checkpoint, style,
energy, lead, seed, smoothing, offset, OSC targets and WebSocket path; the audio input and, where the
checkpoints' feature configs agree, the feature extractor are shared. Unset keys take
the top-level options; performer i (from 0) sends OSC to the --osc ports + i and streams
on ws://HOST:PORT/ws/NAME (/ws is the first performer). Keys: name, checkpoint, style,
energy, lead, seed, osc (repeatable), ws_path, smoothing, offset_ms, record, phase. --stage
and --facing apply to the ensemble: each performer dances on its own spot of the stage, the
spots at least 0.6 m apart (docs/stage.md); --stage 0: all in place at the origin.

examples:
  performer run --audio song.wav --record take1.npz
  performer run --audio song.wav --stage 6x5 --facing audience
  performer run --input-device "USB Audio" --osc 192.168.1.20:39539 --smoothing 0.3
  performer run --audio song.wav --fast --no-ws --osc-mode plain --osc 127.0.0.1:9000
  performer run --input-device "USB Audio" --control-osc 0.0.0.0:9100 --control-allow 192.168.10.0/24
  oscsend 127.0.0.1 9100 /performer/offset f 40       # liblo-tools; QLab, TouchOSC: docs/show.md
  performer run --audio song.wav --performer alice,style=waltz --performer bob,style=rumba,seed=7
  performer run --audio song.wav --performer calm,energy=0.5 --performer lively,energy=1.6
  PERFORMER_PUBLISH_TOKEN=s3cret performer run --audio song.wav --publish nats://127.0.0.1:4222
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from realtime.commands.library import add_play_options

    p = subparsers.add_parser(
        "run", help="stream poses from live audio or a file (OSC/VMC, WebSocket, record)",
        description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", metavar="RUN.TOML", help="TOML file with any of these options (keys like offset_ms)")
    a = p.add_argument_group("audio in")
    src = a.add_mutually_exclusive_group()
    src.add_argument("--audio", metavar="FILE", help="replay this audio file (any format soundfile/librosa reads)")
    src.add_argument("--input-device", metavar="NAME|INDEX",
                     help="live input device: index or (part of) its name; see 'performer devices'")
    a.add_argument("--sample-rate", type=int, metavar="HZ",
                   help="device: capture rate (default: the device's); file: replay rate (default 22050)")
    a.add_argument("--block-size", type=int, metavar="N", help="samples per audio block (default 512)")
    a.add_argument("--fast", action=argparse.BooleanOptionalAction, default=None,
                   help="file replay as fast as possible instead of in real time")
    a.add_argument("--loop", action=argparse.BooleanOptionalAction, default=None,
                   help="replay the file again and again until Ctrl-C (the demo)")
    a.add_argument("--monitor", action=argparse.BooleanOptionalAction, default=None,
                   help="also play the replayed file on the default output device")
    a.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of audio")
    a.add_argument("--fallback-audio", metavar="FILE",
                   help="replay FILE (looped, in real time) whenever the input gives no audio for --fallback-after "
                        "seconds; back to the input as soon as it delivers again")
    a.add_argument("--fallback-after", type=float, metavar="S",
                   help="seconds without input audio before switching to --fallback-audio (default 2)")
    o = p.add_argument_group("outputs")
    o.add_argument("--osc", action="append", metavar="HOST:PORT",
                   help="OSC destination; repeat for several (default 127.0.0.1:39539)")
    o.add_argument("--osc-mode", choices=("vmc", "plain"), help="VMC protocol (default) or /performer/... addresses")
    o.add_argument("--no-osc", action="store_true", default=None, help="send no OSC")
    o.add_argument("--vmc-root", choices=("world", "in-place", "hips"),
                   help="VMC: world (default): /VMC/Ext/Root/Pos carries the performer's place on the stage and "
                        "heading, the Hips their height; in-place: the root stays at the origin (no travel, no "
                        "turns); hips: the root at the origin, the Hips carry place and heading (docs/receivers.md)")
    o.add_argument("--ws", metavar="HOST:PORT", help="WebSocket + viewer server address (default 127.0.0.1:8765)")
    o.add_argument("--no-ws", action="store_true", default=None, help="run no WebSocket server")
    o.add_argument("--ws-token", metavar="TOKEN",
                   help="shared secret WebSocket clients must present; it also enables the control channel "
                        "(prefer $PERFORMER_WS_TOKEN or ws_token in --config: flags show in the process list)")
    o.add_argument("--ws-viewers-open", action=argparse.BooleanOptionalAction, default=None,
                   help="with a token: let clients without it connect as read-only viewers")
    o.add_argument("--ws-max-clients", type=int, metavar="N", help="most WebSocket clients at once (default 16)")
    o.add_argument("--ws-origin", action="append", metavar="URL",
                   help="allowed browser Origin (e.g. http://stage-pc:8765); repeat; default: any")
    o.add_argument("--publish", metavar="URL",
                   help="also publish every frame to a NATS broker for a web audience: nats://HOST:4222 or "
                        "tls://HOST:4222; credentials from $PERFORMER_PUBLISH_TOKEN or $PERFORMER_PUBLISH_USER "
                        "and $PERFORMER_PUBLISH_PASSWORD, or --publish-credentials (docs/audience.md)")
    o.add_argument("--publish-subject", metavar="PREFIX",
                   help="publish on PREFIX.NAME.frames and PREFIX.NAME.meta (default performer; "
                        "one performer alone is NAME main)")
    o.add_argument("--publish-credentials", metavar="FILE",
                   help="TOML file with the broker login: token = \"...\", or user and password")
    o.add_argument("--publish-tls-ca", metavar="FILE", help="CA file that signed the broker's TLS certificate")
    o.add_argument("--publish-cpus", metavar="CPUS",
                   help="CPUs for the publisher process, e.g. 1 or 2-3 (default auto: the CPUs the performer is "
                        "not pinned to, when it is pinned with taskset; else anywhere). It always runs under "
                        "SCHED_BATCH, so it never preempts the audio worker (docs/audience.md)")
    o.add_argument("--record", metavar="FILE", help="write what was streamed to FILE.npz and FILE.bvh when the run stops")
    c = p.add_argument_group("show control")
    c.add_argument("--control-osc", metavar="[HOST:]PORT",
                   help="listen for OSC show control (/performer/reset, offset, smoothing, idle, style, energy, lead) "
                        "on this UDP port; host 127.0.0.1 unless given (0.0.0.0: every interface). Off by default")
    c.add_argument("--control-allow", action="append", metavar="CIDR",
                   help="only senders in this network (e.g. 192.168.10.0/24, or one address) may steer; repeat "
                        "for several; without it a non-loopback --control-osc is open to anyone (warned about)")
    m = p.add_argument_group("model and timing")
    m.add_argument("--checkpoint", metavar="CKPT", help="model checkpoint (default: the packaged one)")
    add_play_options(m)  # --style, --library, --mix (realtime/commands/library.py)
    m.add_argument("--energy", type=float, metavar="E",
                   help="how lively the dance is, 0 (calmest) .. 2 (liveliest); default 1: as the music asks. "
                        "dance_vq models only; live: /performer/energy (docs/show.md, \"Energy\")")
    m.add_argument("--stage", metavar="WxD",
                   help="travel and turn inside a stage of W x D metres centred on the origin (default 3x2: a "
                        "screen or a small stage), or 0: dance in place facing +Z; dance_vq models only; live: "
                        "/performer/stage, /performer/home walks back to the centre (docs/stage.md)")
    m.add_argument("--facing", choices=("free", "audience"),
                   help="free (default): turn as the dancers did; audience: dance the turns but come back to "
                        "face the audience (+Z) within a few seconds; live: /performer/facing")
    m.add_argument("--lead", type=float, metavar="MS",
                   help="send the pose the performer takes MS ms later, 0..200 (default 0), so it is on the beat "
                        "behind a display chain of that delay; dance_vq models only; live: /performer/lead "
                        "(docs/show.md, \"Lead\")")
    m.add_argument("--seed", type=int, metavar="N",
                   help="seed of the dance's random choices (default 0: the same music gives the same dance)")
    m.add_argument("--threads", type=int, metavar="N", help="torch threads (default 1: fastest for per-frame work)")
    m.add_argument("--smoothing", type=float, metavar="X",
                   help="exponential pose smoothing in [0, 1): weight of the previous pose (default 0 = off)")
    m.add_argument("--offset-ms", type=float, metavar="MS",
                   help="positive: delay output by MS and add MS to audio_time; negative: only subtract from "
                        "audio_time (a lead is only possible for receivers that schedule by audio_time)")
    m.add_argument("--warmup", type=float, metavar="S",
                   help="seconds of silence run at start, after 1 s of noise that readies the compiled kernels "
                        "(default 3; 0: no warm-up)")
    e = p.add_argument_group("ensemble (docs/show.md)")
    e.add_argument("--performer", action="append", metavar="NAME[,KEY=VALUE...]",
                   help="one performer of an ensemble on the same audio input; repeat for each. Keys: checkpoint, "
                        "style, energy, lead, seed, osc (repeatable), ws_path, smoothing, offset_ms, record, phase; unset "
                        "keys take the options above (OSC: their ports + the performer's position from 0; WebSocket path "
                        "/ws/NAME). Replaces the [[performer]] tables of --config")
    p.add_argument("--quiet", action="store_true", help="no status line")
    p.set_defaults(func=run)


def _open_source(cfg):
    from realtime.audio_input import DeviceSource, FileSource

    if cfg.audio is not None:
        return FileSource.open(cfg.audio, sample_rate=cfg.sample_rate, block_size=cfg.block_size,
                               realtime=not cfg.fast, monitor=cfg.monitor, loop=cfg.loop)
    return DeviceSource(cfg.input_device, sample_rate=cfg.sample_rate, block_size=cfg.block_size)


def _open_sinks(cfg, input_sample_rate: int) -> list:
    """OSC targets, WebSocket server and recorder; closes what it opened if one fails."""
    from realtime.osc_out import OscSink
    from realtime.publish_process import open_routes
    from realtime.recorder import Recorder
    from realtime.ws_server import WebSocketSink

    sinks: list = []
    try:
        if cfg.record is not None:
            sinks.append(Recorder(cfg.record, input_sample_rate=input_sample_rate))
        for host, port in cfg.osc_targets():
            sinks.append(OscSink(host, port, mode=cfg.osc_mode, vmc_root=cfg.vmc_root))
        ws = cfg.ws_endpoint()
        if ws is not None:
            sinks.append(WebSocketSink(*ws, token=cfg.ws_token, viewers_open=cfg.ws_viewers_open,
                                       max_clients=cfg.ws_max_clients, allowed_origins=cfg.ws_origin or None))
        sinks += open_routes(cfg, ["main"])  # --publish: the broker for a web audience
    except BaseException:
        _discard(sinks)
        raise
    return sinks


def _discard(sinks) -> None:
    """Close sinks of a run that never started (a recorder is dropped, not written)."""
    from realtime.recorder import Recorder

    for s in sinks:
        if not isinstance(s, Recorder):
            s.close()


def _open_control(cfg, engine):
    """The OSC control input of ``--control-osc`` (bound, not started), or None when off."""
    from realtime.osc_control import OscControl

    endpoint = cfg.control_endpoint()
    if endpoint is None:
        return None
    return OscControl(*endpoint, control=engine.control, allow=cfg.control_networks())


def _open_ensemble(cfg, specs, source, fallback):
    """The engine of an ensemble: one pipeline per performer (a checkpoint loaded once however
    many performers use it), its sinks (recorder, OSC targets, a route on the one WebSocket
    server). Returns (engine, every sink, the server or None, description lines).
    Closes what it opened if anything fails."""
    from models.errors import PerformerError
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_out import OscSink
    from realtime.performer import Performer
    from realtime.pipeline import build_pipeline
    from realtime.publish_process import open_routes
    from realtime.recorder import Recorder
    from realtime.ws_server import WebSocketSink

    loaded: dict = {}
    pipelines = []
    for k, spec in enumerate(specs):
        try:  # each performer dances on its own spot of the stage (models/networks/stage.py, ensemble_spots)
            pipelines.append(build_pipeline(spec.checkpoint, seed=spec.seed, loaded=loaded, energy=spec.energy,
                                            library=cfg.library, mix=cfg.mix,
                                            lead=spec.lead, stage=cfg.stage, facing=cfg.facing,
                                            spot=(k, len(specs)),
                                            style=None if spec.style == "auto" else spec.style))
        except PerformerError as exc:
            raise type(exc)(f"performer {spec.name!r}: {exc}") from None
    opened: list = []
    server = None
    try:
        ws = cfg.ws_endpoint()
        if ws is not None:
            server = WebSocketSink(*ws, token=cfg.ws_token, viewers_open=cfg.ws_viewers_open,
                                   max_clients=cfg.ws_max_clients, allowed_origins=cfg.ws_origin or None,
                                   routes_pending=True)  # an early /ws/NAME client waits for its route
        routes = open_routes(cfg, [spec.name for spec in specs])  # --publish: one subject each
        opened += routes
        performers = []
        for k, (spec, pipe) in enumerate(zip(specs, pipelines)):
            sinks: list = []
            if spec.record is not None:
                sinks.append(Recorder(spec.record, input_sample_rate=source.sample_rate))
                opened.append(sinks[-1])
            for host, port in spec.osc:
                sinks.append(OscSink(host, port, mode=cfg.osc_mode, vmc_root=cfg.vmc_root))
                opened.append(sinks[-1])
            if server is not None:
                sinks.append(server.route(spec.ws_path, spec.name, default=k == 0))
            if routes:
                sinks.append(routes[k])
            performers.append(Performer(spec.name, pipe.model, pipe.extractor_factory, sinks,
                                        feature_key=pipe.feature_key, smoothing=spec.smoothing,
                                        offset_ms=spec.offset_ms, phase=spec.phase))
        if server is not None:
            server.routes_done()
        engine = Engine(
            source, config=EngineConfig(smoothing=cfg.smoothing, offset_ms=cfg.offset_ms, threads=cfg.threads,
                                        warmup_s=cfg.warmup, duration_s=cfg.duration,
                                        fallback_after_s=cfg.fallback_after),
            fallback_source=fallback, performers=performers)
    except BaseException:
        _discard(opened)
        if server is not None:
            server.close()
        raise
    if server is not None:
        server.control = engine.control  # only token-authenticated clients can use it
    phases = engine.phases
    lines = [f"{source.name} at {source.sample_rate} Hz -> {len(specs)} performers, "
             f"{len(engine.extractors)} feature extractor{'s' if len(engine.extractors) != 1 else ''}"
             + (f"; WebSocket {server.url} (/ws: {specs[0].name})" if server is not None else "")]
    for spec, pipe, perf in zip(specs, pipelines, performers):
        outs = [f"{s.name} (viewer {s.url})" if hasattr(s, "url") else s.name for s in perf.sinks]
        energy = f", energy {spec.energy:g}" if spec.energy != 1.0 else ""
        energy += f", lead {spec.lead:g} ms" if spec.lead != 0.0 else ""
        spot = getattr(getattr(pipe.model, "stage", None), "state", None)
        if callable(spot) and pipe.model.stage.active:
            cx, cz, w, d = spot()["spot"]
            energy += f", spot {w:.2g}x{d:.2g} m at ({cx:+.2f}, {cz:+.2f})"
        lines.append(f"  {spec.name} [{pipe.checkpoint.name}, style {spec.style}{energy}, seed {spec.seed}, "
                     f"phase {phases[spec.name]}] -> {', '.join(outs) or 'no outputs'}")
    return engine, [s for perf in performers for s in perf.sinks], server, lines


def _describe(sinks, source, pipeline, control=None) -> str:
    outs = []
    for s in sinks:
        outs.append(f"{s.name} (viewer {s.url})" if hasattr(s, "url") else s.name)
    text = f"{source.name} at {source.sample_rate} Hz -> {', '.join(outs) or 'no outputs'} [{pipeline.checkpoint.name}]"
    lib = getattr(getattr(pipeline.model, "model", None), "library_path", None)  # performer run --library
    if lib is not None:
        text += f" dancing {lib.name} ({', '.join(pipeline.model.model.library_styles)})"
    stage = getattr(pipeline.model, "stage", None)
    if stage is not None and hasattr(stage, "width"):
        text += (f"; stage {stage.width:g}x{stage.depth:g} m, facing {stage.facing}" if stage.active
                 else "; dancing in place")
    if control is not None:
        text += f"; OSC control on {control.host}:{control.port}"
    return text


def run(args: argparse.Namespace) -> int:
    from realtime.config import resolve_run_config
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.kernels import compile_unreached_kernels, uncached_kernels
    from realtime.pipeline import build_pipeline
    from realtime.status import StatusLine

    cfg = resolve_run_config(args)
    logging.basicConfig(level=logging.WARNING, format="performer run: %(message)s", stream=sys.stderr)
    source = _open_source(cfg)
    fallback = None
    if cfg.fallback_audio is not None:
        from realtime.audio_input import FileSource

        fallback = FileSource.open(cfg.fallback_audio, sample_rate=cfg.sample_rate, block_size=cfg.block_size,
                                   realtime=True, loop=True)
    specs = cfg.performer_specs()
    server = None
    if specs:
        engine, sinks, server, lines = _open_ensemble(cfg, specs, source, fallback)
    else:
        pipeline = build_pipeline(cfg.checkpoint, seed=cfg.seed, style=None if cfg.style == "auto" else cfg.style,
                                  energy=cfg.energy, lead=cfg.lead, stage=cfg.stage, facing=cfg.facing,
                                  library=cfg.library, mix=cfg.mix)
        sinks = _open_sinks(cfg, source.sample_rate)
        engine = Engine(
            source, pipeline.extractor_factory, pipeline.model, sinks,
            EngineConfig(smoothing=cfg.smoothing, offset_ms=cfg.offset_ms, threads=cfg.threads,
                         warmup_s=cfg.warmup, duration_s=cfg.duration, fallback_after_s=cfg.fallback_after),
            fallback_source=fallback,
        )
        for s in sinks:
            if hasattr(s, "control"):
                s.control = engine.control  # only token-authenticated clients can use it
    try:
        control = _open_control(cfg, engine)
    except BaseException:
        _discard(sinks)
        if server is not None:
            server.close()
        raise
    if not args.quiet:
        if specs:
            if control is not None:
                lines[0] += f"; OSC control on {control.host}:{control.port}"
            print("\n".join(f"performer run: {line}" for line in lines), file=sys.stderr)
        else:
            print(f"performer run: {_describe(sinks, source, pipeline, control)}", file=sys.stderr)
    compiling = [] if args.quiet or not cfg.warmup else uncached_kernels()
    if compiling:  # a first run (empty numba cache): the warm-up compiles them, seconds to a minute
        print(f"performer run: compiling the live path's {len(compiling)} numba kernels (first run only: "
              f"they are cached for the next)...", file=sys.stderr)
        compile_unreached_kernels()  # the ones the warm-up's audio does not reach, before it starts
    try:
        engine.start()
    except BaseException:
        engine.stop()
        if control is not None:
            control.close()
        _discard(sinks)
        if server is not None:
            server.close()
        raise
    if compiling:
        print(f"performer run: warm-up done in {engine.warmup_seconds:.1f} s", file=sys.stderr)
    if control is not None:
        control.start()
    from realtime.desk import start_desk

    desk = start_desk(engine, server if server is not None else sinks,
                      extra=None if control is None else lambda: {"control": control.stats()})
    if desk is not None and not args.quiet:
        print(f"performer run: show desk {desk.url} (steering with the WebSocket token)", file=sys.stderr)
    status = None if args.quiet else StatusLine(lambda: _stats(engine, control))
    interrupted = False
    restore = _install_reload(args, engine, cfg)
    try:
        if status is not None:
            status.start()
        while not engine.wait(0.2):
            pass
    except KeyboardInterrupt:
        interrupted = True
    finally:
        restore()
        if desk is not None:
            desk.close()
        if control is not None:
            control.close()
        if status is not None:
            status.stop(final=engine.frames_out > 0 or interrupted)
        engine.close()
        if server is not None:
            server.close()
    for s in sinks:
        for path in getattr(s, "written", ()):
            print(f"performer run: wrote {path}", file=sys.stderr)
    return 130 if interrupted else 0


def _stats(engine, control) -> dict:
    """The engine's stats, plus the OSC control input's under ``"control"`` when it is on."""
    stats = engine.stats()
    if control is not None:
        stats["control"] = control.stats()
    return stats


def reload_settings(args: argparse.Namespace, engine, current):
    """Re-read ``--config`` (flags still win) and apply the live settings to ``engine``.

    Returns the config now in effect. A bad file is logged as one error and changes
    nothing; changed settings that need a restart are logged as warnings and ignored.
    """
    from models.errors import PerformerError
    from realtime.config import live_changes, performer_live_changes, resolve_run_config

    log = logging.getLogger("realtime.reload")
    try:
        new = resolve_run_config(args)
        if current.performer:  # an ensemble: each performer's resolved settings
            per, other = performer_live_changes(current, new)
            for name in per:
                engine.update(name, **per[name])  # validated by the file's own checks already
            live = {}
        else:
            live, other = live_changes(current, new)
            engine.update(**live)
        for key in ("stage", "facing"):  # live controls of the model, like /performer/stage (an
            if key in other and getattr(new, key) is not None:  # ensemble's: every spot cut anew)
                engine.control(key, getattr(new, key))
                other.remove(key)
                live[key] = getattr(new, key)
    except PerformerError as exc:
        log.error("config reload of %s failed, keeping the current settings: %s", args.config, exc)
        return current
    if other:
        log.warning("config reload: %s changed; applied at the next start only", ", ".join(other))
    import dataclasses

    if current.performer:
        changes = "; ".join([f"{name}: " + ", ".join(f"{k} -> {v:g}" for k, v in c.items()) for name, c in per.items()]
                            + [f"{k} -> {v}" for k, v in live.items()])
        log.warning("config reloaded from %s: %s", args.config, changes or "no live changes")
        kept = {k: getattr(new, k) for k in ("offset_ms", "smoothing")} | live
        if "performer (names)" in other:
            return dataclasses.replace(current, **kept)
        by_name = {p.name: p for p in new.performer}
        return dataclasses.replace(current, **kept, performer=[
            dataclasses.replace(p, offset_ms=by_name[p.name].offset_ms, smoothing=by_name[p.name].smoothing)
            for p in current.performer])
    show = lambda v: f"{v:g}" if isinstance(v, float) else str(v)  # noqa: E731 - numbers, or a stage/facing
    changes = ", ".join(f"{k} {show(getattr(current, k))} -> {show(v)}" for k, v in live.items()) or "no live changes"
    log.warning("config reloaded from %s: %s", args.config, changes)
    return dataclasses.replace(current, **live)


def _install_reload(args: argparse.Namespace, engine, cfg):
    """SIGHUP -> :func:`reload_settings` (with --config, on the main thread); returns an undo function."""
    if not getattr(args, "config", None) or not hasattr(signal, "SIGHUP") \
            or threading.current_thread() is not threading.main_thread():
        return lambda: None
    state = [cfg]

    def on_hup(_signum, _frame) -> None:
        state[0] = reload_settings(args, engine, state[0])

    previous = signal.signal(signal.SIGHUP, on_hup)
    return lambda: signal.signal(signal.SIGHUP, previous)
