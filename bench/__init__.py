"""imbench: test-bench driver and data acquisition for induction-motor drive research.

Package map, one package per layer, each importing only those below it (docs/architecture.md): `bench.cli` (the
`bench` command), `bench.perf`, `bench.workflows` (commission, sweep, reproductions, synth, narx, ...), `bench.api`
(``bench.run(...)`` returns a run's summary or raises `bench.RunFailed`), `bench.batch`, `bench.runtime` (a session,
the timed loop), `bench.daq` (MCAP logs; ``bench.LogReader(path)`` reads one), `bench.drivers`, `bench.operate`,
`bench.controllers` (plugins), `bench.core`, `bench.wire`; `bench.hal`, `bench.params` and `bench.errors` are the
plugin API's types. The names above are imported on first use, so ``import bench`` stays cheap.
"""

import sys
from typing import Any


def _run_as_the_command() -> bool:
    """`python -m bench` while Python still locates the module (not another package's ``-m`` importing bench)."""
    argv = getattr(sys, "orig_argv", [])
    after_m = argv[argv.index("-m") + 1:][:1] if "-m" in argv else []
    return sys.argv[:1] == ["-m"] and ("-mbench" in argv or after_m == ["bench"])


if _run_as_the_command():  # the command's early signal handling from here on (bench.__main__ keeps it until
    from bench.runtime import early_signals  # bench.cli is imported); a plain `import bench` changes no signal handling

    early_signals.install()

__version__ = "0.1.0"

_LAZY = {"run": "bench.api", "RunFailed": "bench.api", "BadInput": "bench.errors", "LogReader": "bench.daq.reader"}
__all__ = ["run", "RunFailed", "BadInput", "LogReader", "__version__"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # found directly from now on
        return value
    raise AttributeError(f"module 'bench' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
