"""Sweep cases grouped into batches (`bench.batch.engine`): many cases in one Dask task, one compiled loop.

`group` splits the pending cases of a sweep into the ones the batch engine takes (FOC with its compiled
tick, mock rig, a scenario it models; grouped by scenario, duration and loop rate, at most ``size`` per
group) and the rest, which run one per task as before. `run_group` is the Dask task of one group: the
rows of `bench.workflows.sweep.cases.run_case` for each case, computed together; a case that trips stops alone
inside the batch. A case the engine turns down after all (building it: e.g. an LPV observer whose speed range
is below the rig's limit) runs on the scalar engine; should the batch fail as a whole (an exception in the
loop), every case of the group does, so the rows are the same either way. The rows differ from the scalar engine's only in the timing columns (``compute_us_*`` empty,
``wall_time`` and ``case_wall_time`` each case's share of the batch) and in the error numbers' last
digits (within 1e-12 relative: sums in the loop instead of numpy's over the log; tests/test_batch.py).
"""

from __future__ import annotations

import math
import os
import socket
import time
from typing import Any

from bench.workflows.sweep.cases import Case, run_case, summary_row
from bench import controllers

# cases per batch task by default (`bench sweep run --batch`, the atlas): large enough that the loop's set-up is
# paid back, small enough that every worker gets several tasks (`group` shrinks it for small sweeps)
DEFAULT_BATCH = 256

# the FOC's parts the compiled kernels cover (bench.controllers.foc_compiled.pack: observers_compiled, lpv_compiled);
# the worker checks again by building the controller, so this only decides what is grouped
_COVERED = {"observer": ("current_model", "voltage_model", "jl", "kubota", "lpv"),
            "speed_estimator": ("none", "kubota", "rotor_equation"), "speed_controller": ("pi", "lpv"),
            "current_controller": ("pi", "lpv"), "rr_adapt": ("off",)}  # fmt: skip


def batchable(case: Case) -> bool:
    """Whether the batch engine runs this case (cheap: from the case's data)."""
    from bench.batch.engine import SCENARIOS

    if case.controller != "foc" or case.scenario not in SCENARIOS:
        return False
    if (case.rig.get("rig") or {}).get("driver", "mock") != "mock":
        return False
    schema = controllers.available()["foc"].schema
    return all(case.params.get(k, schema[k].default) in v for k, v in _COVERED.items())


def group(cases: list[Case], size: int, workers: int) -> tuple[list[list[Case]], list[Case]]:
    """(groups for the batch engine, cases left for one task each). Groups hold at most ``size`` cases, and are
    small enough that every worker gets about four of them."""
    by: dict[tuple[Any, ...], list[Case]] = {}
    singles: list[Case] = []
    for c in cases:
        if batchable(c):
            rate = (c.rig.get("rig") or {}).get("rate_hz", 3000.0)
            by.setdefault((c.scenario, c.duration, float(rate)), []).append(c)
        else:
            singles.append(c)
    groups = []
    for cs in by.values():
        n = max(1, min(size, math.ceil(len(cs) / (4 * max(1, workers)))))
        groups += [cs[i:i + n] for i in range(0, len(cs), n)]
    return groups, singles


def run_group(cases: list[Case], log_dir: str | None = None) -> list[dict[str, Any]]:
    """The results rows of ``cases`` (one scenario, duration and loop rate) from one batch; never raises."""
    from bench.batch.engine import Run, simulate
    from bench.core.config import parse

    t0 = time.perf_counter()
    refused: dict[int, str] = {}  # cases the engine turns down after all (e.g. an observer's speed range): scalar
    try:
        runs = [Run(parse(c.rig, None), c.seed, dict(c.params), c.controller, dict(c.scenario_args)) for c in cases]
        summaries = simulate(runs, cases[0].scenario, cases[0].duration, refused=refused)
    except Exception:  # noqa: BLE001 - the scalar engine runs them and records what goes wrong per case
        return [run_case(c, log_dir) for c in cases]
    share = (time.perf_counter() - t0) / max(1, len(cases) - len(refused))
    worker = f"{socket.gethostname()}:{os.getpid()}"
    rows = []
    for c, s in zip(cases, summaries):
        if s is None:
            rows.append(run_case(c, log_dir))
            continue
        row = c.inputs()
        row.update(summary_row(s))
        row["case_wall_time"] = share
        row["worker"] = worker
        rows.append(row)
    return rows
