"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

from bench.cli import main

main()
