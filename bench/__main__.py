"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

import signal
import sys

# Ctrl-C while the command is still importing: leave quietly (nothing is open yet); `main` and a
# session install their own handling
signal.signal(signal.SIGINT, lambda signum, frame: sys.exit(130))

from bench.cli import main  # noqa: E402

signal.signal(signal.SIGINT, signal.default_int_handler)
main()
