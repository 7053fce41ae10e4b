"""Record the golden runs' digests into tests/golden/data/, or check today's code against them.

    python3 -m tests.golden.record                  # record every run (all its engines must agree)
    python3 -m tests.golden.record fig5.7 atlas     # only these runs
    python3 -m tests.golden.record --check          # compare with the recorded digests, write nothing
    python3 -m tests.golden.record --check --mcap   # the same, the logged runs through their MCAP logs

Recording runs every engine of a run and writes its digest only if they all give the same one; the file names the
commit (and whether the tree had uncommitted changes), the environment (Python, numpy, scipy, numba, the BLAS
kernel) and how long the run took. Exit code 0: recorded, or equal; 1: a difference (listed); 2: bad arguments.
"""

from __future__ import annotations

import argparse
import json
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
    out["libc"] = " ".join(platform.libc_ver())
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
    runs.path(name).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return []


def check(name: str, work: Path, mcap: bool, engines: tuple[str, ...] | None = None) -> list[str]:
    """The differences of today's run ``name`` (each engine) from its recorded digest."""
    rec = runs.recorded(name)
    digests, _ = run_all_engines(name, work, mcap, engines)
    return [f"[{e}] {p}" for e, d in digests.items() for p in digest.diff(rec["digest"], d)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m tests.golden.record", description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"runs (default: all): {', '.join(runs.RUNS)}")
    ap.add_argument("--check", action="store_true", help="compare with the recorded digests; write nothing")
    ap.add_argument("--mcap", action="store_true", help="the logged runs as bench run writes them (MCAP log, plot), "
                                                         "digested from the file (default: the in-memory record)")
    ap.add_argument("--engine", action="append", help="with --check: only this engine (repeatable)")
    a = ap.parse_args(argv)
    unknown = [n for n in a.names if n not in runs.RUNS]
    if unknown:
        print(f"record: unknown run {unknown[0]!r}; runs: {', '.join(runs.RUNS)}", file=sys.stderr)
        return 2
    if a.engine and not a.check:
        print("record: --engine only with --check (a recording runs every engine)", file=sys.stderr)
        return 2
    status = 0
    with tempfile.TemporaryDirectory(prefix="golden-") as tmp:
        for name in a.names or list(runs.RUNS):
            t0 = time.perf_counter()
            engines = tuple(e for e in runs.RUNS[name].engines if e in a.engine) if a.engine else None
            problems = check(name, Path(tmp), a.mcap, engines) if a.check else record(name, Path(tmp), a.mcap)
            took = f"{time.perf_counter() - t0:.1f} s"
            if problems:
                status = 1
                print(digest.report(name, problems), f"({took})", flush=True)
            else:
                print(f"golden run {name}: {'equal' if a.check else 'recorded'} ({took})", flush=True)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
