"""`bench perf sweep`: the sweep engine's throughput and Dask's cost per case (JSON, docs/sweeps.md).

The same cases (FOC, three flux observers x rotor-resistance mismatch x seeds, ``duration`` seconds of
Fig. 5.7 each, no per-tick log) run on a local Dask cluster with one worker, then with two. With each
cluster up, after one ``cold`` sweep (fresh worker processes, which import the bench and load the
observers on their first case), ``rounds`` rounds alternate

1. the cases serially in this process (`bench.workflows.sweep.cases.run_case` in a loop), and
2. the same cases as a ``warm`` sweep (`bench.workflows.sweep.engine.run_sweep` on the running cluster),

so that the machine's load, which drifts over a minute on a shared VM, hits both sides alike.

Dask's overhead per case is (warm 1-worker wall time - serial wall time) / cases, summed over the rounds
(each round's own figure is kept too); the parallel efficiency with two workers is serial / (2 x warm
2-worker wall time). ``outside_cases_per_case_s`` is the worker time not spent inside a case (workers x
wall - the cases' own wall times) per case: dispatch, results and table writes, less sensitive to the
machine's load than the difference of two wall times. ``cpu_overhead_*`` compares CPU time: the
sweep's (this process, which also runs the local scheduler, plus every worker) against the serial
run's. Cluster start-up is reported apart. Run it on a quiet machine, and repeat.
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.workflows.sweep.table import RESULTS, read
from bench.workflows.sweep.spec import parse
from bench.workflows.sweep.cases import expand, run_case
from bench.workflows.sweep.engine import Cluster, run_sweep


def _spec(cases: int, duration: float) -> Any:
    if cases < 6 or cases % 6:
        raise ValueError(f"cases must be a positive multiple of 6, got {cases}")
    seeds = cases // 6
    return parse({"sweep": {"name": "perf", "scenarios": ["fig5.7"], "duration": duration,
                            "seeds": list(range(seeds))},
                  "design": {"axes": {"params.observer": ["current_model", "jl", "voltage_model"],
                                      "plant.R_r": [1.0, 1.5]}}})  # fmt: skip


def run(cases: int = 12, duration: float = 3.0, rounds: int = 2) -> dict[str, Any]:
    """Measure; returns the JSON document."""

    spec = _spec(cases, duration)
    todo = expand(spec)
    n = len(todo)
    run_case(todo[0])  # warm-up: imports, artifacts
    out: dict[str, Any] = {
        "benchmark": "perf sweep", "cases": n, "case_duration_s": duration, "rounds": rounds,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_1min_at_start": os.getloadavg()[0]},
    }  # fmt: skip
    sim = None
    serial_all: list[float] = []
    for workers in (1, 2):
        t0 = time.perf_counter()
        with Cluster(workers) as cl, tempfile.TemporaryDirectory() as tmp:
            startup = time.perf_counter() - t0

            def sweep(name: str) -> tuple[float, float, list[dict[str, Any]]]:
                w0, c0 = cl.client.run(time.process_time), time.process_time()
                t1 = time.perf_counter()
                res = run_sweep(spec, Path(tmp) / name, client=cl.client, progress=False)
                wall = time.perf_counter() - t1
                w1, c1 = cl.client.run(time.process_time), time.process_time()
                assert res["ran"] == n and res["error"] == 0, res
                # CPU: this process (client, scheduler) + the workers
                return wall, c1 - c0 + sum(w1[k] - w0[k] for k in w1), read(Path(tmp) / name / RESULTS)

            cold, _, _ = sweep("cold")
            serial, cpu_serial, warm, cpu_warm, in_cases = [], [], [], [], []
            for r in range(rounds):
                t1, c1 = time.perf_counter(), time.process_time()
                rows = [run_case(c) for c in todo]
                serial.append(time.perf_counter() - t1)
                cpu_serial.append(time.process_time() - c1)
                sim = sum(row.get("sim_time") or 0.0 for row in rows)
                wall, cpu, table = sweep(f"warm{r}")
                warm.append(wall)
                cpu_warm.append(cpu)
                in_cases.append(sum(row["case_wall_time"] for row in table))
        serial_all += serial
        s_wall, w_wall, s_cpu, w_cpu = sum(serial), sum(warm), sum(cpu_serial), sum(cpu_warm)
        rec: dict[str, Any] = {
            "cluster_startup_s": startup, "cold_wall_s": cold, "serial_wall_s_rounds": serial,
            "warm_wall_s_rounds": warm, "serial_wall_s": s_wall / rounds, "warm_wall_s": w_wall / rounds,
            "serial_cases_per_minute": 60 * n * rounds / s_wall, "cases_per_minute": 60 * n * rounds / w_wall,
            "sim_s_per_wall_s": sim * rounds / w_wall if sim else None,
            # worker time not spent inside a case (dispatch, results, table writes)
            "outside_cases_per_case_s": (workers * w_wall - sum(in_cases)) / (n * rounds),
            # CPU time of the whole sweep (this process with the scheduler, and the workers) against the
            # serial run's: less sensitive to other load
            "cpu_s": w_cpu / rounds, "serial_cpu_s": s_cpu / rounds,
            "cpu_overhead_per_case_s": (w_cpu - s_cpu) / (n * rounds), "cpu_overhead_fraction": (w_cpu - s_cpu) / s_cpu,
        }  # fmt: skip
        if workers == 1:
            rec["overhead_per_case_s"] = (w_wall - s_wall) / (n * rounds)
            rec["overhead_fraction"] = (w_wall - s_wall) / s_wall
            rec["overhead_fraction_rounds"] = [(w - s) / s for w, s in zip(warm, serial)]
            rec["cold_overhead_per_case_s"] = (cold - s_wall / rounds) / n
        else:
            rec["speedup_vs_serial"] = s_wall / w_wall
            rec["parallel_efficiency"] = s_wall / (workers * w_wall)
        out[f"dask_{workers}_worker{'s' if workers > 1 else ''}"] = rec
    serial_mean = sum(serial_all) / len(serial_all)
    out["serial_in_process"] = {"wall_s": serial_mean, "cases_per_minute": 60 * n / serial_mean,
                                "sim_s_per_wall_s": sim / serial_mean if sim else None, "simulated_s": sim}  # fmt: skip
    out["machine"]["load_1min_at_end"] = os.getloadavg()[0]
    return out
