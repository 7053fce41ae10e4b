"""numba's on-disk cache kept in step with the compiled family's sources (bench.jit_cache)."""

from __future__ import annotations

from pathlib import Path

from bench import jit_cache


def test_a_stale_stamp_flushes_the_modules_cache_entries_and_is_renewed() -> None:
    """A module whose cache entries were compiled from other sources (its stamp differs) gets them flushed (numba then
    compiles again on the first call) and the stamp renewed; with the stamp current nothing is flushed."""
    from bench.controllers import observers_compiled as oc

    oc.csq(1.0, 2.0)  # compiled, and its cache entry saved
    cache = oc.csq._cache._cache_file
    assert cache._load_index(), "the entry was not cached"
    stamp = Path(oc.csq._cache.cache_path) / "observers_compiled.deps"
    jit_cache.drop_stale(vars(oc))  # current: kept
    assert stamp.read_text() == jit_cache.family_stamp() and cache._load_index()
    stamp.write_text("another version of the sources")
    jit_cache.drop_stale(vars(oc))
    assert cache._load_index() == {}  # flushed
    assert stamp.read_text() == jit_cache.family_stamp()
    oc.csq.recompile()  # (this process's copy; the next process compiles and caches it again)
    oc.csq._cache.save_overload(oc.csq.signatures[0], oc.csq.overloads[oc.csq.signatures[0]])
    assert cache._load_index()


def test_the_stamp_covers_every_compiled_module_and_what_they_compile_in() -> None:
    import importlib

    for name in jit_cache.FAMILY:
        assert importlib.util.find_spec(name) is not None, name
    compiled = {"mock_hw.compiled", "bench.controllers.foc_compiled", "bench.controllers.observers_compiled",
                "bench.controllers.lpv_compiled", "bench.batch_kernel"}  # fmt: skip
    assert compiled <= set(jit_cache.FAMILY)
    for name in compiled:  # each calls drop_stale at import, before it compiles anything
        assert "drop_stale(globals())" in Path(importlib.util.find_spec(name).origin).read_text(), name
    assert "@njit(cache=True" not in Path(importlib.util.find_spec("bench.cpython_arith").origin).read_text()
