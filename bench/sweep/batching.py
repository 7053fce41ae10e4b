"""Sweep cases grouped into batches (`bench.batch`): many cases in one Dask task, one compiled loop.

`group` splits the pending cases of a sweep into the ones the batch engine takes (FOC with its compiled
tick, mock rig, a scenario it models; grouped by scenario, duration and loop rate, at most ``size`` per
group) and the rest, which run one per task as before. `run_group` is the Dask task of one group: the
rows of `bench.sweep.cases.run_case` for each case, computed together; a case that trips stops alone
inside the batch. Should the batch fail as a whole (a case the engine turns down after all, an exception
in the loop), every case of the group runs on the scalar engine instead, so the rows are the same either
way. The rows differ from the scalar engine's only in the timing columns (``compute_us_*`` empty,
``wall_time`` and ``case_wall_time`` each case's share of the batch) and in the error numbers' last
digits (within 1e-12 relative: sums in the loop instead of numpy's over the log; tests/test_batch.py).
"""

from __future__ import annotations

import math
import os
import socket
import time
from typing import Any

from bench.sweep.cases import Case, run_case, summary_row

# the FOC configuration its compiled tick runs (bench.controllers.foc.FocController._compiled_engine); the worker
# checks again by building the controller, so this only decides what is grouped
_COMPILED_FOC = {"observer": "current_model", "speed_controller": "pi", "current_controller": "pi",
                 "speed_estimator": "none"}  # fmt: skip


def batchable(case: Case) -> bool:
    """Whether the batch engine runs this case (cheap: from the case's data)."""
    from bench import controllers
    from bench.batch import SCENARIOS

    if case.controller != "foc" or case.scenario not in SCENARIOS:
        return False
    if (case.rig.get("rig") or {}).get("driver", "mock") != "mock":
        return False
    schema = controllers.available()["foc"].schema
    return all(case.params.get(k, schema[k].default) == v for k, v in _COMPILED_FOC.items())


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
    from bench.batch import Run, simulate
    from bench.config import parse

    t0 = time.perf_counter()
    try:
        runs = [Run(parse(c.rig, None), c.seed, dict(c.params), c.controller, dict(c.scenario_args)) for c in cases]
        summaries = simulate(runs, cases[0].scenario, cases[0].duration)
    except Exception:  # noqa: BLE001 - the scalar engine runs them and records what goes wrong per case
        return [run_case(c, log_dir) for c in cases]
    share = (time.perf_counter() - t0) / len(cases)
    worker = f"{socket.gethostname()}:{os.getpid()}"
    rows = []
    for c, s in zip(cases, summaries):
        row = c.inputs()
        row.update(summary_row(s))
        row["case_wall_time"] = share
        row["worker"] = worker
        rows.append(row)
    return rows
