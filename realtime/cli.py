"""The ``performer`` command line.

Each subcommand lives in its own module under :mod:`realtime.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (a callable taking
the parsed ``argparse.Namespace`` and returning an exit status). Command modules
import heavy libraries (torch, librosa) inside their handlers so that ``--help``
stays instant.

Errors: a :class:`models.errors.PerformerError` is printed as one line on stderr
and the process exits with status 2; Ctrl-C exits with 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from models.errors import PerformerError

# Order is the order shown by --help.
COMMAND_MODULES: tuple[str, ...] = (
    "realtime.commands.run",
    "realtime.commands.listen",
    "realtime.commands.devices",
    "realtime.commands.train",
    "realtime.commands.data",
    "realtime.commands.library",
    "realtime.commands.generate",
    "realtime.commands.evaluate",
    "realtime.commands.bench",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="performer",
        description=(
            "live-performer: listens to music and makes a virtual performer move to it. "
            "Poses (root position + per-bone quaternions of a humanoid rig, 30 frames per "
            "second) stream out over OSC (VMC protocol) and WebSocket, or are written to "
            "BVH/NPZ files."
        ),
        epilog="Run 'performer COMMAND --help' for the options of one command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except PerformerError as exc:
        print(f"performer {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"performer {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of our output went away (e.g. `performer ... | head`): not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second BrokenPipe at exit
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
