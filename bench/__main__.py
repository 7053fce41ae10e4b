"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

import signal
import sys

_EARLY = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _while_importing(signum: int, frame: object) -> None:
    """A signal while the command is still importing: nothing is open yet; one line, exit 128 + signal."""
    try:
        sys.stderr.write(f"bench: interrupted ({signal.Signals(signum).name}) while starting: nothing ran\n")
    finally:
        sys.exit(128 + signum)


def entry() -> None:
    """The console script's entry point: `main` and a session install their own handling once imported."""
    for s in _EARLY:
        signal.signal(s, _while_importing)
    from bench.cli import main

    for s in _EARLY:
        signal.signal(s, signal.default_int_handler if s == signal.SIGINT else signal.SIG_DFL)
    main()


if __name__ == "__main__":
    entry()
