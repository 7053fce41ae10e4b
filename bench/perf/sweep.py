"""`bench perf sweep`: the sweep engine's throughput and Dask's cost per case (JSON, docs/sweeps.md).

The same cases (FOC, three flux observers x rotor-resistance mismatch x seeds, ``duration`` seconds of
Fig. 5.7 each, no per-tick log) run

1. serially in this process (`bench.sweep.cases.run_case` in a loop, after one untimed warm-up case);
2. on a local Dask cluster with one worker, twice: ``cold`` (fresh worker processes, which import
   the bench and load the observers on their first case) and ``warm``;
3. on a local cluster with two workers, cold and warm.

Dask's overhead per case is (warm 1-worker wall time - serial wall time) / cases; the parallel
efficiency with two workers is serial / (2 x warm 2-worker wall time). ``outside_cases_per_case_s``
is the worker time not spent inside a case (workers x wall - the cases' own wall times) per case:
dispatch, results and table writes, less sensitive to the machine's load than the difference of two
wall times. ``cpu_overhead_*`` compares CPU time: the sweep's (this process, which also runs the
local scheduler, plus every worker; warm round) against the serial run's (on a shared VM CPU time
varies with the load too). Cluster start-up is reported apart. The machine is shared: run it on a quiet machine,
and repeat.
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
    from bench.sweep.table import RESULTS, read

    spec = _spec(cases, duration)
    todo = expand(spec)
    n = len(todo)
    run_case(todo[0])  # warm-up: imports, artifacts
    t0, c0 = time.perf_counter(), time.process_time()
    rows = [run_case(c) for c in todo]
    serial, cpu_serial = time.perf_counter() - t0, time.process_time() - c0
    sim = sum(r.get("sim_time") or 0.0 for r in rows)
    out: dict[str, Any] = {
        "benchmark": "perf sweep", "cases": n, "case_duration_s": duration, "simulated_s": sim,
        "tripped": sum(r["status"] == "tripped" for r in rows),
        "serial_in_process": {"wall_s": serial, "cpu_s": cpu_serial, "cases_per_minute": 60 * n / serial,
                              "sim_s_per_wall_s": sim / serial},
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_1min_at_start": os.getloadavg()[0]},
    }  # fmt: skip
    for workers in (1, 2):
        t0 = time.perf_counter()
        with Cluster(workers) as cl, tempfile.TemporaryDirectory() as tmp:
            startup = time.perf_counter() - t0
            walls, cpus = {}, {}
            for rnd in ("cold", "warm"):
                w0, c1 = cl.client.run(time.process_time), time.process_time()
                t1 = time.perf_counter()
                res = run_sweep(spec, Path(tmp) / rnd, client=cl.client, progress=False)
                walls[rnd] = time.perf_counter() - t1
                w1, c2 = cl.client.run(time.process_time), time.process_time()
                cpus[rnd] = c2 - c1 + sum(w1[k] - w0[k] for k in w1)  # this process (client, scheduler) + workers
                assert res["ran"] == n and res["error"] == 0, res
            in_cases = sum(r["case_wall_time"] for r in read(Path(tmp) / "warm" / RESULTS))
        warm, cpu = walls["warm"], cpus["warm"]
        rec: dict[str, Any] = {"cluster_startup_s": startup, "cold_wall_s": walls["cold"], "warm_wall_s": warm,
                               "cases_per_minute": 60 * n / warm, "sim_s_per_wall_s": sim / warm,
                               # worker time not spent inside a case (dispatch, results, table writes)
                               "outside_cases_per_case_s": (workers * warm - in_cases) / n,
                               # CPU time of the whole sweep (this process with the scheduler, and the
                               # workers) against the serial run's: insensitive to other load
                               "cpu_s": cpu, "cpu_overhead_per_case_s": (cpu - cpu_serial) / n,
                               "cpu_overhead_fraction": (cpu - cpu_serial) / cpu_serial}  # fmt: skip
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
