"""``performer`` run in the test's own process, for command-line error paths."""

from __future__ import annotations

import pytest


def run_cli(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    """``performer ARGS`` through :func:`realtime.cli.main` in this process: (exit status, stdout,
    stderr). The same code as the ``performer`` command, without a new process's start-up (a few
    seconds of imports each), for the paths that fail or print help before any work."""
    from realtime.cli import main

    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:  # argparse: --help, usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return int(code or 0), out, err
