"""`python -m bench` = the `bench` command (works even where the console script is not on PATH)."""

from bench.runtime import early_signals


def entry() -> None:
    """The console script's entry point: `main` and a session install their own handling once imported."""
    early_signals.install()
    import bench.core.shutdown  # noqa: F401 - what `main` imports before its own handling: still under the early one
    from bench.cli import main

    early_signals.release()
    main()


if __name__ == "__main__":
    entry()
