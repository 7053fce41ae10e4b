"""`bench perf sweep`: the sweep engine's throughput and Dask's cost per case (JSON, docs/sweeps.md).

The same cases (FOC, three flux observers x rotor-resistance mismatch x seeds, ``duration`` seconds of
Fig. 5.7 each, no per-tick log) run

1. serially in this process (`bench.sweep.cases.run_case` in a loop, after one untimed warm-up case);
2. on a local Dask cluster with one worker, twice: ``cold`` (fresh worker processes, which import
   the bench and load the observers on their first case) and ``warm``;
3. on a local cluster with two workers, cold and warm.

Dask's overhead per case is (warm 1-worker wall time - serial wall time) / cases; the parallel
efficiency with two workers is serial / (2 x warm 2-worker wall time). Cluster start-up is reported
apart. The machine is shared: run it on a quiet machine and repeat.
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any


def _spec(cases: int, duration: float) -> Any:
    from bench.sweep.spec import parse

    if cases < 6 or cases % 6:
        raise ValueError(f"cases must be a positive multiple of 6, got {cases}")
    seeds = cases // 6
    return parse({"sweep": {"name": "perf", "scenarios": ["fig5.7"], "duration": duration,
                            "seeds": list(range(seeds))},
                  "design": {"axes": {"params.observer": ["current_model", "jl", "voltage_model"],
                                      "plant.R_r": [1.0, 1.5]}}})  # fmt: skip


def run(cases: int = 12, duration: float = 3.0) -> dict[str, Any]:
    """Measure; returns the JSON document."""
    from bench.sweep.cases import expand, run_case
    from bench.sweep.engine import Cluster, run_sweep

    spec = _spec(cases, duration)
    todo = expand(spec)
    n = len(todo)
    run_case(todo[0])  # warm-up: imports, artifacts
    t0 = time.perf_counter()
    rows = [run_case(c) for c in todo]
    serial = time.perf_counter() - t0
    sim = sum(r.get("sim_time") or 0.0 for r in rows)
    out: dict[str, Any] = {
        "benchmark": "perf sweep", "cases": n, "case_duration_s": duration, "simulated_s": sim,
        "tripped": sum(r["status"] == "tripped" for r in rows),
        "serial_in_process": {"wall_s": serial, "cases_per_minute": 60 * n / serial, "sim_s_per_wall_s": sim / serial},
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_1min_at_start": os.getloadavg()[0]},
    }  # fmt: skip
    for workers in (1, 2):
        t0 = time.perf_counter()
        with Cluster(workers) as cl, tempfile.TemporaryDirectory() as tmp:
            startup = time.perf_counter() - t0
            walls = {}
            for rnd in ("cold", "warm"):
                t1 = time.perf_counter()
                res = run_sweep(spec, Path(tmp) / rnd, client=cl.client, progress=False)
                walls[rnd] = time.perf_counter() - t1
                assert res["ran"] == n and res["error"] == 0, res
        warm = walls["warm"]
        rec: dict[str, Any] = {"cluster_startup_s": startup, "cold_wall_s": walls["cold"], "warm_wall_s": warm,
                               "cases_per_minute": 60 * n / warm, "sim_s_per_wall_s": sim / warm}  # fmt: skip
        if workers == 1:
            rec["overhead_per_case_s"] = (warm - serial) / n
            rec["overhead_fraction"] = (warm - serial) / serial
            rec["cold_overhead_per_case_s"] = (walls["cold"] - serial) / n
        else:
            rec["speedup_vs_serial"] = serial / warm
            rec["parallel_efficiency"] = serial / (workers * warm)
        out[f"dask_{workers}_worker{'s' if workers > 1 else ''}"] = rec
    out["machine"]["load_1min_at_end"] = os.getloadavg()[0]
    return out
