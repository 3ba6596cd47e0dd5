"""Helpers for tests that start performer processes."""

from __future__ import annotations

import signal


def default_sigint() -> None:
    """``preexec_fn`` for a child that the test stops with SIGINT.

    A shell starts background jobs (``make test &``, ``nohup ... &``) with SIGINT ignored,
    and an ignored signal stays ignored across exec, so a performer started from such a
    test run would never see the SIGINT the test sends and would run on until the test
    times out. The child gets the default disposition back, as under a terminal.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
