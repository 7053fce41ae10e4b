"""Filling numba's cache with every compiled engine, then writing the marker `bench.runtime.jit_warm.is_warm` reads.

``python3 -m bench.batch.warmup`` compiles (or loads) the plant `mock_hw.compiled`, the FOC tick
`bench.controllers.foc_compiled` with its parts and the batch loop (`bench.batch.engine`), about a minute on a
2-core machine after an install or update; a run starts it in the background (`jit_warm.warm_in_background`).
It sits with the batch engine, the highest of the compiled engines it builds.
"""

from __future__ import annotations

import fcntl
import importlib
import os
import sys

from bench.batch.engine import Run, simulate
from bench.core.config import load
from bench.core.jit_cache import family_stamp
from bench.runtime.jit_warm import is_warm, marker

# importing these compiles (or loads) every kernel of the family (foc_compiled imports its parts' modules)
MODULES = ("mock_hw.compiled", "bench.controllers.foc_compiled", "bench.batch.kernel")


def warm() -> None:
    """Compile (or load) every compiled engine, then write the marker. Two at once: the second waits."""
    path = marker()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if path.exists():
            return
        for name in MODULES:
            importlib.import_module(name)
        simulate([Run(load("mock"))], "fig5.7", 0.01)  # the batch loop compiles at its first call
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(family_stamp() + "\n")
        os.replace(tmp, path)


def main(argv: list[str]) -> int:
    if is_warm():
        if "--quiet" not in argv:
            print("imbench: the compiled engines are in numba's cache already", file=sys.stderr)
        return 0
    if "--quiet" not in argv:
        print("imbench: compiling the compiled engines into numba's cache (once after an install or update; "
              "about a minute on 2 cores) ...", file=sys.stderr, flush=True)  # fmt: skip
    try:
        warm()
    except ImportError as exc:
        print(f"imbench: the compiled engines cannot be built: {exc}", file=sys.stderr)
        return 1
    if "--quiet" not in argv:
        print(f"imbench: done ({marker()})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
