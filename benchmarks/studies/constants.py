"""Run any script of the project with some module constants set: a variant measured beside the default.

Each ``MODULE.NAME=VALUE`` before ``--`` sets that module-level constant (VALUE read as a Python
literal) before the script after ``--`` runs in this process (``runpy``); the script's own arguments
follow it. The figures then are the variant's; the same command without the assignments is the
default's. Single-process scripts only (a worker process would start with the shipped constants).
Example (the tempo's tilt reading liveliness only, the listening benchmark's stretch set and ramp)::

    PYTHONPATH=. .venv/bin/python benchmarks/studies/constants.py models.networks.chooser.TEMPO_FREQ=0 -- \\
        benchmarks/listening.py --checkpoint models/assets/default.pt --sets stretch,ramp --out /tmp/freq0 --quiet
"""

from __future__ import annotations

import ast
import importlib
import runpy
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def apply(assignments: list[str]) -> list[str]:
    """Set each ``MODULE.NAME=VALUE`` (VALUE a Python literal); returns them as set, for the log."""
    done = []
    for item in assignments:
        target, sep, value = item.partition("=")
        module, dot, name = target.rpartition(".")
        if not sep or not dot:
            raise SystemExit(f"constants.py: {item!r} is not MODULE.NAME=VALUE")
        mod = importlib.import_module(module)
        if not hasattr(mod, name):
            raise SystemExit(f"constants.py: {module} has no constant {name}")
        setattr(mod, name, ast.literal_eval(value) if value not in ("inf", "-inf") else float(value))
        done.append(f"{module}.{name}={getattr(mod, name)!r}")
    return done


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if "--" not in args or args.index("--") + 1 >= len(args) or args[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if args[:1] in (["-h"], ["--help"]) else 2
    cut = args.index("--")
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    print("constants: " + (", ".join(apply(args[:cut])) or "as shipped"), flush=True)
    script = args[cut + 1]
    sys.argv = [script] + args[cut + 2:]
    runpy.run_path(script, run_name="__main__")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
