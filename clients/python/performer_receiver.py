#!/usr/bin/env python3
"""Minimal standalone receiver for live-performer's pose stream: a starting point for your own code.

Needs only ``pip install python-osc websockets`` (no live-performer install). It prints
one line per frame; replace ``on_frame`` with what your application does.

    python performer_receiver.py osc                   # VMC on UDP 39539 (performer run's default)
    python performer_receiver.py osc --port 9000 --mode plain
    python performer_receiver.py ws --url ws://127.0.0.1:8765/ws

Every frame is delivered in live-performer's project frame: right-handed, Y up, metres,
the character faces +Z and its left is +X (glTF/VRM). Rotations are local, relative
to the T-pose, quaternions x, y, z, w. The VMC stream is in Unity's left-handed frame
and is converted back here: position (-x, y, z), rotation (x, -y, -z, w).
See docs/protocol.md for the wire formats and docs/receivers.md for engines.
"""

from __future__ import annotations

import argparse
import json
import struct
import time

BONES = (
    "Hips", "Spine", "Chest", "Neck", "Head",
    "LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes",
    "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes",
)


def on_frame(index: int, audio_time: float, root: tuple, rotations: dict, delay_ms: float | None) -> None:
    """Called once per pose. ``rotations``: bone name -> (x, y, z, w); ``root``: Hips position, metres."""
    q = rotations.get("LeftUpperArm")
    arm = "" if q is None else " LeftUpperArm (" + ", ".join(f"{v:+.3f}" for v in q) + ")"
    delay = "" if delay_ms is None else f" delay {delay_ms:.1f} ms"
    print(f"#{index} t={audio_time:.3f}s root ({root[0]:+.3f}, {root[1]:+.3f}, {root[2]:+.3f}){arm}{delay}", flush=True)


class Counter:
    """Stops the program after ``limit`` frames (None: never)."""

    def __init__(self, limit: int | None) -> None:
        self.limit, self.n = limit, 0

    def done(self) -> bool:
        self.n += 1
        return self.limit is not None and self.n >= self.limit


# -- OSC: VMC protocol or plain /performer/... ----------------------------------------------------


def compose(base: tuple, position: tuple, rotation: tuple) -> tuple:
    """A bone's local (position, rotation xyzw) under a parent ``base`` = (position, rotation)
    -> the bone's (position, rotation) in the parent's frame."""
    (bp, (bx, by, bz, bw)), (px, py, pz), (qx, qy, qz, qw) = base, position, rotation
    tx, ty, tz = 2 * (by * pz - bz * py), 2 * (bz * px - bx * pz), 2 * (bx * py - by * px)
    moved = (px + bw * tx + by * tz - bz * ty, py + bw * ty + bz * tx - bx * tz, pz + bw * tz + bx * ty - by * tx)
    rot = (bw * qx + bx * qw + by * qz - bz * qy, bw * qy - bx * qz + by * qw + bz * qx,
           bw * qz + bx * qy - by * qx + bz * qw, bw * qw - bx * qx - by * qy - bz * qz)
    return tuple(b + m for b, m in zip(bp, moved)), rot


def receive_osc(port: int, mode: str, host: str, counter: Counter) -> None:
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import BlockingOSCUDPServer

    state = {"root": (0.0, 0.0, 0.0), "rot": {}, "index": 0, "time": 0.0, "frames": 0}
    dispatcher = Dispatcher()
    server: BlockingOSCUDPServer

    def emit() -> None:
        on_frame(state["index"], state["time"], state["root"], state["rot"], None)
        state["rot"] = {}
        if counter.done():
            server.done = True

    if mode == "vmc":
        def model_root(_addr, _name, px, py, pz, qx, qy, qz, qw, *_):
            # the model root: where the performer stands on the stage and its heading
            # (performer run --vmc-root world; identity with in-place or hips)
            state["base"] = ((-px, py, pz), (qx, -qy, -qz, qw))  # Unity (left-handed) -> project frame

        def bone(_addr, name, px, py, pz, qx, qy, qz, qw, *_):
            if name == "Hips":
                state["root"] = (-px, py, pz)  # Unity (left-handed) -> project frame
            state["rot"][name] = (qx, -qy, -qz, qw)

        def vmc_time(_addr, t, *_):  # /VMC/Ext/T ends a frame; its value is the audio time
            state["time"], state["index"] = t, round(t * 30) - 1
            base = state.pop("base", None)
            if base is not None and "Hips" in state["rot"]:  # the Hips in the world: root * Hips
                state["root"], state["rot"]["Hips"] = compose(base, state["root"], state["rot"]["Hips"])
            emit()

        dispatcher.map("/VMC/Ext/Root/Pos", model_root)
        dispatcher.map("/VMC/Ext/Bone/Pos", bone)
        dispatcher.map("/VMC/Ext/T", vmc_time)
    else:
        def start(_addr, index, t):
            state["index"], state["time"] = index, t

        def root(_addr, x, y, z):
            state["root"] = (x, y, z)

        def plain_bone(addr, x, y, z, w):
            state["rot"][addr.rsplit("/", 1)[1]] = (x, y, z, w)
            if len(state["rot"]) == len(BONES):
                emit()

        dispatcher.map("/performer/frame", start)
        dispatcher.map("/performer/root", root)
        dispatcher.map("/performer/bone/*", plain_bone)

    server = BlockingOSCUDPServer((host, port), dispatcher)
    server.done = False
    print(f"listening for {mode} OSC on udp {host}:{port}", flush=True)
    while not server.done:
        server.handle_request()
    server.server_close()


# -- WebSocket ------------------------------------------------------------------------------------

HEADER = struct.Struct("<4sHHIIdd")  # magic, version, bones, index, reserved, audio time, send time


def receive_ws(url: str, fmt: str, counter: Counter) -> None:
    from websockets.sync.client import connect

    sep = "&" if "?" in url else "?"
    with connect(f"{url}{sep}format={fmt}") as ws:
        hello = json.loads(ws.recv())
        bones = hello["bones"]
        print(f"connected to {url}: {len(bones)} bones at {hello['fps']} fps", flush=True)
        for message in ws:
            now = time.time()
            if isinstance(message, bytes):
                _magic, _version, n, index, _, audio_time, send_time = HEADER.unpack_from(message)
                values = struct.unpack_from(f"<{3 + 4 * n}f", message, HEADER.size)
                root = values[:3]
                rotations = {b: values[3 + 4 * j : 7 + 4 * j] for j, b in enumerate(bones)}
            else:
                msg = json.loads(message)
                if msg.get("type") != "frame":
                    continue
                index, audio_time, send_time = msg["index"], msg["audio_time"], msg["send_time"]
                root, rotations = msg["root"], dict(zip(bones, msg["rotations"]))
            # send_time is the server's time.time(): the delay is right when both run on one machine.
            on_frame(index, audio_time, root, rotations, (now - send_time) * 1000)
            if counter.done():
                return


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="transport", required=True)
    o = sub.add_parser("osc", help="receive OSC (VMC protocol or plain)")
    o.add_argument("--port", type=int, default=39539)
    o.add_argument("--host", default="127.0.0.1", help="0.0.0.0 to receive from other machines")
    o.add_argument("--mode", choices=("vmc", "plain"), default="vmc")
    w = sub.add_parser("ws", help="receive the WebSocket stream")
    w.add_argument("--url", default="ws://127.0.0.1:8765/ws")
    w.add_argument("--format", choices=("binary", "json"), default="binary")
    for p in (o, w):
        p.add_argument("--count", type=int, help="stop after this many frames")
    args = parser.parse_args()
    try:
        if args.transport == "osc":
            receive_osc(args.port, args.mode, args.host, Counter(args.count))
        else:
            receive_ws(args.url, args.format, Counter(args.count))
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
