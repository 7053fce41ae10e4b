"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

from bench import early_signals


def entry() -> None:
    """The console script's entry point: `main` and a session install their own handling once imported."""
    early_signals.install()
    from bench.cli import main

    early_signals.release()
    main()


if __name__ == "__main__":
    entry()
