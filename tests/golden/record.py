"""Record the golden runs' digests into tests/golden/data/, or check today's code against them.

    python3 -m tests.golden.record                  # record every run (all its engines must agree)
    python3 -m tests.golden.record fig5.7 atlas     # only these runs
    python3 -m tests.golden.record --check          # compare with the recorded digests, write nothing
    python3 -m tests.golden.record --check --mcap   # the same, the logged runs through their MCAP logs
    python3 -m tests.golden.record --check --blas-kernel host --host numpy --host libm   # as this CPU runs it

Recording runs every engine of a run and writes its digest only if they all give the same one; the file names the
commit (and whether the tree had uncommitted changes), the environment (Python, numpy, scipy, numba, the BLAS
kernel) and how long the run took. Exit code 0: recorded, or equal; 1: a difference (listed); 2: bad arguments.

The runs run with fixed numerical kernels (`tests.golden.runs.LIBM_ENV`, `BLAS_ENV`, `numpy_baseline_env`): the
command starts itself again with them in its environment (the dynamic loader, OpenBLAS and numpy read them when
they load). With ``--check``, ``--blas-kernel`` names another BLAS kernel (an ``OPENBLAS_CORETYPE``) or ``host``
(the CPU's own), and ``--host numpy`` / ``--host libm`` let numpy / libm take the CPU's own paths.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tests.golden import digest, runs


def commit() -> dict[str, Any]:
    """The commit the code came from, and whether the tree held changes outside the recorded data."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(runs.ROOT), *args], capture_output=True, text=True,
                              check=True).stdout.strip()  # fmt: skip

    try:
        head = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--", ".", f":!{runs.DATA.relative_to(runs.ROOT)}")
    except (OSError, subprocess.CalledProcessError):
        return {"commit": None, "uncommitted_changes": None}
    return {"commit": head, "uncommitted_changes": bool(dirty)}


def environment() -> dict[str, Any]:
    """What the numbers were computed with (a library's release or another BLAS kernel can change last bits)."""
    from synthesis.environment import environment as env

    out = env()
    out["blas"] = sorted((b for b in out["blas"] if b["api"] != "openmp"), key=lambda b: json.dumps(b))  # (openmp:
    # numba's threading layer, once it has loaded)
    out["libc"] = " ".join(platform.libc_ver())
    out["kernel_env"] = {k: os.environ.get(k) for k in (*runs.LIBM_ENV, *runs.BLAS_ENV, *runs.numpy_baseline_env())}
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

        out["numpy_simd"] = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]  # the dispatched paths in use
    except ImportError:
        out["numpy_simd"] = None
    out["packages"]["llvmlite"] = _version("llvmlite")
    return out


def _version(name: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return None


def run_all_engines(name: str, work: Path, mcap: bool, engines: tuple[str, ...] | None = None) \
        -> tuple[dict[str, dict[str, Any]], dict[str, float]]:  # fmt: skip
    """Today's digest of run ``name`` on each of its engines (or ``engines``), and the seconds each took."""
    out, secs = {}, {}
    for eng in engines or runs.RUNS[name].engines:
        t0 = time.perf_counter()
        out[eng] = runs.execute(name, eng, work, mcap)
        secs[eng] = round(time.perf_counter() - t0, 1)
    return out, secs


def record(name: str, work: Path, mcap: bool) -> list[str]:
    """Record run ``name``; the differences between its engines if they disagree (then nothing is written)."""
    spec = runs.RUNS[name]
    digests, secs = run_all_engines(name, work, mcap)
    first, *others = spec.engines
    problems = [f"[{e} vs {first}] {p}" for e in others for p in digest.diff(digests[first], digests[e])]
    if problems:
        return problems
    doc = {"run": name, "what": spec.what, "command": spec.command(), "engines": list(spec.engines),
           "recorded_from": commit(), "environment": environment(), "seconds": secs, "digest": digests[first]}  # fmt: skip
    runs.DATA.mkdir(parents=True, exist_ok=True)
    runs.path(name).write_text(digest.dumps(doc) + "\n", encoding="utf-8")
    return []


def check(name: str, work: Path, mcap: bool, engines: tuple[str, ...] | None = None) -> list[str]:
    """The differences of today's run ``name`` (each engine) from its recorded digest."""
    rec = runs.recorded(name)
    digests, _ = run_all_engines(name, work, mcap, engines)
    out = [f"[{e}] {p}" for e, d in digests.items() for p in digest.diff(rec["digest"], d)]
    if out:  # a release of the numerical stack or another BLAS can change last bits too: say so
        env = digest.diff(rec["environment"], environment(), "environment")
        out.append(f"{digest.NOTE} {rec['recorded_from']['commit']}; "
                   + ("; ".join(env) if env else "the same environment (packages, BLAS kernel) as the recording"))
    return out


def kernel_env(blas: str | None = None, host: tuple[str, ...] = ()) -> tuple[dict[str, str], list[str]]:
    """(the environment variables that select the numerical kernels, those to remove): the golden BLAS kernel,
    another one or the host's (``host``); numpy's baseline SIMD paths and libm's SSE2 variants, or (named in
    ``host``) the CPU's own."""
    want = {} if blas == "host" else {**runs.BLAS_ENV, **({"OPENBLAS_CORETYPE": blas} if blas else {})}
    npy = runs.numpy_baseline_env()
    want.update({} if "numpy" in host else npy)
    want.update({} if "libm" in host else runs.LIBM_ENV)
    return want, [k for k in (*runs.BLAS_ENV, *npy, *runs.LIBM_ENV) if k not in want]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(prog="python3 -m tests.golden.record", description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"runs (default: all): {', '.join(runs.RUNS)}")
    ap.add_argument("--check", action="store_true", help="compare with the recorded digests; write nothing")
    ap.add_argument("--mcap", action="store_true", help="the logged runs as bench run writes them (MCAP log, plot), "
                                                         "digested from the file (default: the in-memory record)")
    ap.add_argument("--engine", action="append", help="with --check: only this engine (repeatable; a run that has "
                                                       "none of them runs on its own)")
    ap.add_argument("--blas-kernel", metavar="KERNEL", help="an OPENBLAS_CORETYPE to run under instead of the "
                    f"golden {runs.BLAS_ENV['OPENBLAS_CORETYPE']!r} (with --check), or 'host': the CPU's own")
    ap.add_argument("--host", action="append", choices=("numpy", "libm"), default=[],
                    help="with --check: numpy's SIMD paths / libm's variants the CPU's own, not the golden baseline")
    ap.add_argument("--json", metavar="FILE", type=Path, help="also write {run: [differences]} to FILE")
    ap.add_argument("--max", type=int, default=digest.MAX_MESSAGES, help="differences listed per run")
    a = ap.parse_args(argv)
    want, drop = kernel_env(a.blas_kernel, tuple(a.host))
    unset = [k for k in drop if k in os.environ]
    if any(os.environ.get(k) != v for k, v in want.items()) or unset:  # numpy and OpenBLAS read them on loading
        env = {k: v for k, v in os.environ.items() if k not in unset} | want
        os.execve(sys.executable, [sys.executable, "-m", "tests.golden.record", *argv], env)
    unknown = [n for n in a.names if n not in runs.RUNS]
    if unknown:
        print(f"record: unknown run {unknown[0]!r}; runs: {', '.join(runs.RUNS)}", file=sys.stderr)
        return 2
    if (a.engine or a.blas_kernel or a.host) and not a.check:
        print("record: --engine, --blas-kernel and --host only with --check (a recording runs every engine, with "
              "the golden kernels)", file=sys.stderr)  # fmt: skip
        return 2
    status, found = 0, {}
    with tempfile.TemporaryDirectory(prefix="golden-") as tmp:
        for name in a.names or list(runs.RUNS):
            t0 = time.perf_counter()
            engines = tuple(e for e in runs.RUNS[name].engines if e in a.engine) if a.engine else None
            problems = check(name, Path(tmp), a.mcap, engines) if a.check else record(name, Path(tmp), a.mcap)
            took = f"{time.perf_counter() - t0:.1f} s"
            found[name] = problems
            if problems:
                status = 1
                print(digest.report(name, problems, a.max), f"({took})", flush=True)
            else:
                print(f"golden run {name}: {'equal' if a.check else 'recorded'} ({took})", flush=True)
    if a.json:
        a.json.write_text(json.dumps(found), encoding="utf-8")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
