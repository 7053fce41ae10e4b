"""numba's on-disk cache, kept in step with every source compiled into the cached machine code, and unable to stop
a run.

numba's cache (``cache=True``) checks only the date and size of the file that defines the cached function,
not of the functions and module-level constants compiled into it. The compiled engines are one family: the plant
(`mock_hw.compiled`), the FOC tick (`bench.controllers.foc_compiled`) with its parts (`observers_compiled`,
`lpv_compiled`), the batch loop (`bench.batch.kernel`), all compiling the kernels of the Python modules that the
Python engines run, and reading their constants. After an update that changed only one of them, a cache entry of
another would be loaded as it is and run the old code. `drop_stale` (each compiled module calls it after defining its
kernels and before compiling any: fixed signatures by `compile_fixed`) keeps a hash of every source of the family
beside that module's cache entries and flushes them when it differs; the functions then compile again. Hand-written
because numba has no dependency tracking for its cache.

numba also trusts the files themselves: one truncated index (``*.nbi``) made every load raise (``EOFError``) and a
changed data file (``*.nbc``) would load whatever machine code it holds. So `drop_stale` puts `GuardedCache` in
front of each function's cache: numba's saves are followed by a SHA-256 of the function's files (``*.sums``
beside them), a load first checks them, and an entry that differs, has no sums or fails to load is removed and
compiled again (a note for the run's warnings, `take_notes`). A save that fails (a full disk) leaves the compiled
code in memory only. A cache numba cannot use at all (no writable folder: it raises at the module's import) is the
callers' to handle: they run the Python engines with a note (`mock_hw.plant.resolve_engine`, `FocController`).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import os
from pathlib import Path
from typing import Any

# the compiled modules and the Python modules whose constants or helpers they compile in
FAMILY = ("bench.core.encoder", "bench.hal", "bench.core.jit_cache", "mock_hw.compiled",
          "mock_hw.inverter", "mock_hw.load", "mock_hw.motor", "mock_hw.sensors", "mock_hw.thermal",
          "bench.core.slots", "bench.controllers.kernel_math",
          "bench.controllers.foc", "bench.controllers.foc_compiled", "bench.controllers.rr_adapt",
          "bench.controllers.observers", "bench.controllers.speed_estimators", "bench.controllers.observers_compiled",
          "bench.controllers.lpv_current", "bench.controllers.lpv_speed", "bench.controllers.lpv_law",
          "bench.controllers.lpv_compiled", "bench.core.supervisor_checks", "bench.batch.kernel")  # fmt: skip
_STAMP: list[str] = []  # the family's hash, computed once per process
_NOTES: list[str] = []  # what happened to the cache in this process, for the next run's warnings


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


def note(text: str) -> None:
    """Keep one line for the warnings of the next run of this process (`take_notes`)."""
    _NOTES.append(text)


def take_notes() -> list[str]:
    """The notes since the last call (the compiled engines' cache repaired, not saved, or not usable)."""
    out = _NOTES[:]
    del _NOTES[:]
    return out


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class GuardedCache:
    """numba's cache of one function (``dispatcher._cache``) that no damaged file can stop: see the module's
    docstring. Everything but loading, saving and flushing goes to numba's own object."""

    def __init__(self, cache: Any, name: str) -> None:
        self._inner = cache
        self._name = name  # module.function, for the notes
        files = cache._cache_file
        self._dir = Path(files._cache_path)
        self._index = Path(files._index_path)
        self._base = files._index_name[: -len(".nbi")]
        self._sums = self._dir / f"{self._base}.sums"

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._inner, attr)

    @property
    def cache_path(self) -> str:
        return self._inner.cache_path

    def _files(self) -> list[Path]:
        """The function's index and data files on disk."""
        return ([self._index] if self._index.exists() else []) + sorted(self._dir.glob(f"{self._base}.*.nbc"))

    def drop(self) -> bool:
        """Remove the function's entries (index, data, sums); False if a file could not be removed."""
        ok = True
        for p in [*self._files(), self._sums]:
            try:
                p.unlink(missing_ok=True)
            except OSError:
                ok = False
        return ok

    def flush(self) -> None:
        self.drop()

    def damage(self) -> str | None:
        """Why the files on disk are not the ones this function's last save left (None: they are, or there are
        none)."""
        if not self._index.exists():
            return None
        try:
            sums = json.loads(self._sums.read_text())
            if not isinstance(sums, dict) or self._index.name not in sums:
                return "no checksums for its index"
        except (OSError, ValueError):
            return "no checksums"
        for name, digest in sums.items():
            if not (isinstance(name, str) and name.startswith(self._base) and "/" not in name):
                return "checksums of other files"
            try:
                if hashlib.sha256((self._dir / name).read_bytes()).hexdigest() != digest:
                    return f"{name} changed"
            except OSError as exc:
                return f"{name}: {exc.strerror or exc}"
        return None

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        """numba's load of the entry for ``sig``, or None (numba then compiles) if the entry is damaged or fails to
        load: its files are removed first."""
        why = self.damage()
        if why is None:
            try:
                return self._inner.load_overload(sig, target_context)
            except Exception as exc:  # noqa: BLE001 - whatever a damaged entry makes numba or LLVM raise
                why = _why(exc)
        removed = self.drop()
        note(f"numba cache: {self._name}: entry damaged ({why}); compiled again"
             + ("" if removed else f" (its files in {self._dir} could not be removed)"))
        return None

    def save_overload(self, sig: Any, data: Any) -> None:
        """numba's save, then the checksums of the files; a save that fails leaves the code in memory only."""
        try:
            self._inner.save_overload(sig, data)
        except Exception as exc:  # noqa: BLE001 - a full disk, a folder gone read-only, a damaged index
            note(f"numba cache: {self._name}: not saved ({_why(exc)}); the next process compiles it again")
            return
        tmp = self._sums.with_name(f"{self._sums.name}.tmp.{os.getpid()}")
        try:
            sums = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in self._files()}
            tmp.write_text(json.dumps(sums, indent=0) + "\n")
            os.replace(tmp, self._sums)
        except OSError as exc:  # the entry then counts as damaged at the next load, and compiles again
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
            note(f"numba cache: {self._name}: checksums not saved ({_why(exc)})")


def drop_stale(namespace: dict[str, Any]) -> None:
    """Guard the cache of each cached numba function in ``namespace`` (a module's ``globals()``; `GuardedCache`) and
    flush the entries compiled from another version of the family's sources. Call it before anything of the module
    is compiled (a function with a fixed signature: declare it lazily and `compile_fixed` it after this call)."""
    module = namespace.get("__name__", "?")
    cached = [f for f in namespace.values() if getattr(getattr(f, "_cache", None), "cache_path", None)
              and getattr(getattr(f, "py_func", None), "__module__", None) == module]  # fmt: skip
    if not cached:
        return
    for f in cached:
        if not isinstance(f._cache, GuardedCache):
            f._cache = GuardedCache(f._cache, f"{module.rsplit('.', 1)[-1]}.{f.py_func.__name__}")
    path = Path(cached[0]._cache.cache_path)
    stamp = path / f"{module.rsplit('.', 1)[-1]}.deps"
    now = family_stamp()
    try:
        if stamp.read_text() == now:
            return
    except (OSError, ValueError):
        pass
    for f in cached:  # entries of unknown or other sources
        f._cache.drop()
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


def entry(dispatcher):  # noqa: ANN001, ANN201 - a numba dispatcher in, a callable out
    """The one compiled overload's own entry point, without the dispatcher in front of it.

    A dispatcher call first types every argument to pick an overload (~0.35 us a call here, a quarter of
    `advance`'s whole cost); these functions have a single explicit signature, so the choice is fixed and
    the entry point (which still converts each argument by that signature) is called directly. Falls back
    to the dispatcher where numba does not expose it.
    """
    try:
        (sig,) = dispatcher.signatures
        return dispatcher.overloads[sig].entry_point
    except (AttributeError, KeyError, ValueError):
        return dispatcher
