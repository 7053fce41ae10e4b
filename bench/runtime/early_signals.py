"""Signals while the `bench` command is still importing: nothing is open yet, so one line and exit 128 + signal.

Installed by `bench.__main__.entry` (the console script) and, for ``python -m bench``, already while Python
imports the package (`bench/__init__.py`, before runpy compiles ``__main__``). The handler ends the process with
``os._exit``: an exception raised from a signal handler can land inside an import that catches it (and the
command would then go on), and there is nothing to close at this point.
"""

from __future__ import annotations

import os
import signal
import sys

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _while_importing(signum: int, frame: object) -> None:
    try:
        sys.stderr.write(f"bench: interrupted ({signal.Signals(signum).name}) while starting: nothing ran\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum)


def install() -> None:
    """Take the signals until `release`."""
    for s in SIGNALS:
        signal.signal(s, _while_importing)


def release() -> None:
    """Python's defaults again (KeyboardInterrupt for SIGINT); the command installs its own handling."""
    for s in SIGNALS:
        signal.signal(s, signal.default_int_handler if s == signal.SIGINT else signal.SIG_DFL)
