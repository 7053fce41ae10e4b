"""numba's on-disk cache kept in step with the compiled family's sources (bench.core.jit_cache)."""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import random
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.core import jit_cache
from bench.runtime.session import COMPILED_FROM


def test_a_stale_stamp_flushes_the_modules_cache_entries_and_is_renewed() -> None:
    """A module whose cache entries were compiled from other sources (its stamp differs) gets them flushed (numba then
    compiles again on the first call) and the stamp renewed; with the stamp current nothing is flushed."""
    from bench.controllers import observers_compiled as oc

    oc._c(np.zeros(2), 0)  # compiled, and its cache entry saved
    cache = oc._c._cache._cache_file
    assert cache._load_index(), "the entry was not cached"
    stamp = Path(oc._c._cache.cache_path) / "observers_compiled.deps"
    jit_cache.drop_stale(vars(oc))  # current: kept
    assert stamp.read_text() == jit_cache.family_stamp() and cache._load_index()
    stamp.write_text("another version of the sources")
    jit_cache.drop_stale(vars(oc))
    assert cache._load_index() == {}  # flushed
    assert stamp.read_text() == jit_cache.family_stamp()
    oc._c.recompile()  # (this process's copy; the next process compiles and caches it again)
    oc._c._cache.save_overload(oc._c.signatures[0], oc._c.overloads[oc._c.signatures[0]])
    assert cache._load_index()


def test_the_stamp_covers_every_compiled_module_and_what_they_compile_in() -> None:
    import importlib

    for name in jit_cache.FAMILY:
        assert importlib.util.find_spec(name) is not None, name
    compiled = {"mock_hw.compiled", "bench.controllers.foc_compiled", "bench.controllers.observers_compiled",
                "bench.controllers.lpv_compiled", "bench.batch.kernel"}  # fmt: skip
    assert compiled <= set(jit_cache.FAMILY)
    for name in compiled:  # each calls drop_stale at import, before it compiles anything
        assert "drop_stale(globals())" in Path(importlib.util.find_spec(name).origin).read_text(), name
    # the kernels written once in other modules (njit(f), register_jitable(f)): their modules are in the family too,
    # and so are the modules of the globals they read (the slot layouts, bench.core.slots)
    import re

    found = set()
    for name in compiled:
        mod = importlib.import_module(name)
        for fn in re.findall(r"(?:njit|register_jitable)\((\w+)\)", Path(mod.__file__).read_text()):
            f = getattr(mod, fn)
            found.add(f.__module__)
            found.update(type(v).__module__ for v in f.__globals__.values() if hasattr(type(v), "kinds"))
    assert len(found) >= 10 and found <= set(jit_cache.FAMILY), sorted(found - set(jit_cache.FAMILY))
    assert "bench.core.slots" in jit_cache.FAMILY


# --- a damaged cache never stops a run (real `bench run` processes on a copy of the cache) ----------------------
COMPILED = ("mock_hw.compiled", "bench.controllers.foc_compiled", "bench.controllers.observers_compiled",
            "bench.controllers.lpv_compiled", "bench.batch.kernel")  # fmt: skip
# a lockstep run long enough for the compiled engines by default (`bench.runtime.session.default_engines`, the path a
# real-time run takes too); not paced by the wall clock, so a busy machine cannot make it late
RUN = [sys.executable, "-m", "bench", "run", "--duration", f"{COMPILED_FROM:g}", "--no-progress"]


def _guarded(module: str, name: str) -> jit_cache.GuardedCache:
    cache = getattr(importlib.import_module(module), name)._cache
    assert isinstance(cache, jit_cache.GuardedCache)
    return cache


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """This process's numba cache of the compiled engines (current: tests/conftest.py compiled it) copied into the
    layout of a ``NUMBA_CACHE_DIR``, so the tests damage a copy and not the shared cache."""
    from numba.core.caching import _CacheLocator

    dst = tmp_path_factory.mktemp("numba-cache")
    for name in COMPILED:
        mod = importlib.import_module(name)
        caches = [getattr(f, "_cache", None) for f in vars(mod).values()]
        src = Path(next(c for c in caches if isinstance(c, jit_cache.GuardedCache)).cache_path)
        to = dst / _CacheLocator.get_suitable_cache_subpath(mod.__file__)
        to.mkdir(parents=True, exist_ok=True)
        for f in src.glob(f"{name.rsplit('.', 1)[-1]}.*"):
            if f.suffix in (".nbi", ".nbc", ".sums", ".deps"):
                shutil.copy2(f, to)
    from bench.runtime import jit_warm

    (dst / jit_warm.marker().name).write_text("a copy of a warm cache\n")  # a run takes the compiled engines
    return dst


def _files(cache_dir: Path, module: str, name: str) -> tuple[Path, Path, Path]:
    """The index, first data file and checksums of ``module.name`` in the copy at ``cache_dir``."""
    from numba.core.caching import _CacheLocator

    g = _guarded(module, name)
    d = cache_dir / _CacheLocator.get_suitable_cache_subpath(importlib.import_module(module).__file__)
    return d / g._index.name, d / f"{g._base}.1.nbc", d / g._sums.name


def _run(cache_dir: Path, out: Path, *extra: str, **env: str) -> tuple[subprocess.CompletedProcess, dict]:
    """`bench run` (compiled engines by default) with ``cache_dir`` as numba's cache; its process and summary."""
    summary = out / "summary.json"
    p = subprocess.run([*RUN, "--log", str(out / "run.mcap"), "--summary", str(summary), "--plot", str(out / "run.png"),
                        "--force", *extra], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), **env})  # fmt: skip
    return p, json.loads(summary.read_text()) if summary.exists() else {}


def _cache_notes(summary: dict) -> list[str]:
    return [w for w in summary.get("warnings", []) if w.startswith(("numba cache", "plant:", "controller:"))]


def _damage(path: Path, how: str, other: Path) -> None:
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "garbled":
        path.write_bytes(random.Random(1).randbytes(len(data)))
    elif how == "flipped":  # a few bytes inside the payload: numba would load it as it is
        mid = len(data) // 2
        path.write_bytes(data[:mid] + bytes(b ^ 0x5A for b in data[mid:mid + 8]) + data[mid + 8:])
    else:  # foreign: another function's file of the same kind
        shutil.copy2(other, path)


@pytest.mark.parametrize("how", ["truncated", "empty", "garbled", "flipped", "foreign"])
def test_a_damaged_index_or_data_file_is_compiled_again_and_cached(how: str, warm_cache: Path, tmp_path: Path) -> None:
    """A damaged index of one function (the plant's `truth`) and data file of another (the FOC tick's `fill_row`):
    the run starts on the compiled engines with a note per function (was: exit 1, "start-up failed: EOFError",
    every run until the cache was deleted by hand), and the next run loads both from the cache, warning-free."""
    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    index, _, _ = _files(cache, "mock_hw.compiled", "truth")
    _, data, _ = _files(cache, "bench.controllers.foc_compiled", "fill_row")
    _damage(index, how, _files(cache, "mock_hw.compiled", "truth_sat")[0])
    _damage(data, how, _files(cache, "bench.controllers.foc_compiled", "step")[1])

    p, summary = _run(cache, tmp_path / "damaged")
    assert p.returncode == 0, p.stderr
    assert summary["engines"] == {"plant": "compiled", "controller": "compiled"}
    notes = _cache_notes(summary)
    assert len(notes) == 2 and all("entry damaged" in n and "compiled again" in n for n in notes), notes
    assert {n.split(":")[1].strip() for n in notes} == {"compiled.truth", "foc_compiled.fill_row"}
    assert all("\n" not in n for n in notes)

    p, summary = _run(cache, tmp_path / "next", NUMBA_DEBUG_CACHE="1")
    assert p.returncode == 0, p.stderr
    assert summary["engines"] == {"plant": "compiled", "controller": "compiled"} and not _cache_notes(summary)
    assert f"data loaded from '{data}'" in p.stdout
    assert f"data loaded from '{_files(cache, 'mock_hw.compiled', 'truth')[1]}'" in p.stdout
    assert "data saved" not in p.stdout  # nothing compiled again


def test_damaged_checksums_and_stamp_compile_again(warm_cache: Path, tmp_path: Path) -> None:
    """The guard's own files: empty checksums compile that function again (with a note); a garbled source stamp
    (not text: it raised UnicodeDecodeError at import) flushes the module's entries, which compile again."""
    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    _, _, sums = _files(cache, "bench.controllers.foc_compiled", "fill_row")
    sums.write_bytes(b"")
    index, _, _ = _files(cache, "mock_hw.compiled", "truth")
    (index.parent / "compiled.deps").write_bytes(random.Random(2).randbytes(64) + b"\xff")

    p, summary = _run(cache, tmp_path / "damaged")
    assert p.returncode == 0, p.stderr
    assert summary["engines"] == {"plant": "compiled", "controller": "compiled"}
    assert [n.split(":")[1].strip() for n in _cache_notes(summary)] == ["foc_compiled.fill_row"]
    assert (index.parent / "compiled.deps").read_text() == jit_cache.family_stamp()
    p, summary = _run(cache, tmp_path / "next", NUMBA_DEBUG_CACHE="1")
    assert p.returncode == 0 and "data saved" not in p.stdout and not _cache_notes(summary), p.stderr


def _read_only_ok() -> bool:
    return shutil.which("unshare") is not None and subprocess.run(
        ["unshare", "-m", "sh", "-c", "mount --bind /tmp /tmp && mount -o remount,ro,bind /tmp"],
        capture_output=True).returncode == 0  # fmt: skip


@pytest.mark.skipif(not _read_only_ok(), reason="needs root and unshare -m (read-only bind mounts)")
def test_no_writable_cache_folder_runs_the_python_engines_with_a_note(warm_cache: Path, tmp_path: Path) -> None:
    """The sources' folders, NUMBA_CACHE_DIR and the user's cache read-only (bind mounts in a mount namespace of
    the run alone; a damaged entry there could not be removed, and numba refuses to cache at all): the run falls
    back to the Python engines with a one-line note each; an explicit ``engine = compiled`` is refused in one
    line, exit 2."""
    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    _damage(_files(cache, "bench.controllers.foc_compiled", "fill_row")[0], "empty", cache)
    xdg = tmp_path / "xdg"
    xdg.mkdir()
    ro = {str(Path(importlib.util.find_spec(m).origin).parent) for m in COMPILED} | {str(cache), str(xdg)}
    mounts = " && ".join(f"mount --bind {shlex.quote(d)} {shlex.quote(d)} && mount -o remount,ro,bind {shlex.quote(d)}"
                         for d in sorted(ro))  # fmt: skip
    out = tmp_path / "run"
    out.mkdir()

    def run(*extra: str) -> tuple[subprocess.CompletedProcess, dict]:
        cmd = " ".join(map(shlex.quote, [*RUN, "--log", str(out / "run.mcap"), "--summary", str(out / "s.json"),
                                         "--plot", str(out / "run.png"), "--force", *extra]))  # fmt: skip
        p = subprocess.run(["unshare", "-m", "sh", "-c", f"{mounts} && exec {cmd}"], capture_output=True, text=True,
                           timeout=300, env={**os.environ, "NUMBA_CACHE_DIR": str(cache), "XDG_CACHE_HOME": str(xdg),
                                             "MPLCONFIGDIR": str(tmp_path)})  # fmt: skip
        return p, json.loads((out / "s.json").read_text()) if (out / "s.json").exists() else {}

    p, summary = run()
    assert p.returncode == 0, p.stderr
    assert summary["engines"] == {"plant": "python", "controller": "python"}
    notes = _cache_notes(summary)
    assert [n.split(":")[0] for n in notes] == ["plant", "controller"], notes
    assert all("the Python engine ran, the compiled one failed to load" in n and "\n" not in n for n in notes)
    (out / "s.json").unlink()
    p, _ = run("-p", "engine=compiled")
    assert p.returncode == 2, p.stderr
    err = p.stderr.strip().splitlines()
    assert len(err) == 1 and "controller.foc.engine" in err[0] and "compiled cannot load here" in err[0], p.stderr
