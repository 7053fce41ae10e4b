"""numba's on-disk cache, kept in step with every source compiled into the cached machine code.

numba's cache (``cache=True``) checks only the date and size of the file that defines the cached function,
not of the functions and module-level constants compiled into it. The compiled engines are one family: the plant
(`mock_hw.compiled`), the FOC tick (`bench.controllers.foc_compiled`) with its parts (`observers_compiled`,
`lpv_compiled`), the batch loop (`bench.batch_kernel`), all built on `bench.cpython_arith` and reading constants
of the Python modules they mirror. After an update that changed only one of them, a cache entry of another
would be loaded as it is and run the old code. `drop_stale` (each compiled module calls it after defining its
kernels and before compiling any: fixed signatures by `compile_fixed`) keeps a hash of every source of the family
beside that module's cache entries and flushes them when it differs; the functions then compile again. Hand-written
because numba has no dependency tracking for its cache.
"""

from __future__ import annotations

import hashlib
import importlib.util
from pathlib import Path
from typing import Any

# the compiled modules and the Python modules whose constants or helpers they compile in
FAMILY = ("bench.cpython_arith", "bench.hal", "bench.jit_cache", "mock_hw.compiled", "bench.controllers.foc",
          "bench.controllers.foc_compiled", "bench.controllers.rr_adapt", "bench.controllers.observers",
          "bench.controllers.speed_estimators", "bench.controllers.observers_compiled",
          "bench.controllers.lpv_current", "bench.controllers.lpv_speed", "bench.controllers.lpv_law",
          "bench.controllers.lpv_compiled", "bench.batch_kernel")  # fmt: skip
_STAMP: list[str] = []  # the family's hash, computed once per process


def family_stamp() -> str:
    """A hash of the family's source files (read from disk, not imported)."""
    if not _STAMP:
        h = hashlib.sha256()
        for name in FAMILY:
            spec = importlib.util.find_spec(name)
            origin = spec.origin if spec is not None else None
            h.update(name.encode())
            h.update(Path(origin).read_bytes() if origin else b"?")
        _STAMP.append(h.hexdigest())
    return _STAMP[0]


def drop_stale(namespace: dict[str, Any]) -> None:
    """Flush the cache entries of the cached numba functions in ``namespace`` (a module's ``globals()``) that were
    compiled from another version of the family's sources. Call it before anything of the module is compiled (a
    function with a fixed signature: declare it lazily and `compile_fixed` it after this call)."""
    cached = [f for f in namespace.values() if getattr(getattr(f, "_cache", None), "cache_path", None)
              and getattr(getattr(f, "py_func", None), "__module__", None) == namespace.get("__name__")]  # fmt: skip
    if not cached:
        return
    path = Path(cached[0]._cache.cache_path)
    stamp = path / f"{namespace['__name__'].rsplit('.', 1)[-1]}.deps"
    now = family_stamp()
    try:
        if stamp.read_text() == now:
            return
    except OSError:
        pass
    for f in cached:
        if f._cache._cache_file._load_index():  # entries of unknown or other sources (nothing cached: nothing to do)
            f._cache.flush()
    try:
        path.mkdir(parents=True, exist_ok=True)  # (a first run: the entries about to be cached are of these sources)
        stamp.write_text(now)
    except OSError:  # a read-only cache: numba then compiles anyway
        pass


def compile_fixed(dispatcher: Any, *signatures: Any) -> None:
    """Compile ``dispatcher`` for ``signatures`` now (from the cache where it is current) and for no other: what
    ``@njit(signatures, cache=True)`` does at definition, after `drop_stale` has looked at the cache."""
    for sig in signatures:
        dispatcher.compile(sig)
    dispatcher.disable_compile()
