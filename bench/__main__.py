"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

import signal
import sys
from types import FrameType


def _leave(signum: int, frame: FrameType | None) -> None:
    sys.exit(128 + signum)


def entry() -> None:
    """The `bench` command. Ctrl-C, SIGTERM or SIGHUP while it is still importing: leave quietly with
    128 + the signal (nothing is open yet); `bench.cli.main` and a session install their own handling."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, _leave)
    from bench.cli import main

    main()


if __name__ == "__main__":
    entry()
