"""`bench perf batch`: motor-ticks per second of the batch engine against the batch size, with the scalar engine
measured in the same run (JSON, docs/sweeps.md).

Cases like the robustness atlas': the FOC (current-model
observer, encoder speed) on Fig. 5.7 (or another scenario), each with its own true machine (R_r x0.5-1.5, R_s
x0.8-1.2, L_m x0.85-1.15, J x0.7-1.3, uniform) and noise seed. For each batch size the cases' construction
(``build_s``) and the compiled loop (``loop_s``) are timed apart; ``motor_ticks_per_s`` is the loop's,
``motor_ticks_per_cpu_s`` the same per CPU-second of the loop's threads (what one core gives when the machine's
other load leaves it alone). The scalar engine (`bench.runtime.session.run`, compiled plant and FOC, no log: what a
sweep runs per case) runs the first cases before the batches and again after, so a drifting machine load hits both
sides. Start-up (numba's import and cached machine code, the thread pool's first call) is measured in a fresh
process; ``--cold`` also compiles into an empty cache there. The peers (`bench.perf.peers`: gym-electric-motor's and
motulator's induction motor, where they import) are timed in the same run, each in a fresh process. Every rate is
also a cost per motor step in microseconds and in yardsticks (../shared/yardstick.py, one plain-Python RK4 step of
the motor, measured in the same run): the figures to compare across machines. `plot` draws motor-ticks/s against
the batch size, the scalar engine and the peers as horizontal lines.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from typing import Any

import numpy as np

from bench.workflows.sweep.plant import apply
from bench.perf import peers as peer_mod
from bench.perf.live import yardstick_us
from bench.core.plotstyle import pyplot, save
from bench.workflows.reproductions.atlas import SPECS, markdown, summarise
from bench.workflows.sweep.batching import batchable, run_group
from bench.workflows.sweep.cases import expand, run_case
from bench.workflows.sweep.spec import load
from bench.batch.engine import Run, simulate, rows_differ
from bench.core.config import RIGS_DIR, parse
from bench.runtime.session import RunOptions, run as run_session

FACTORS = {"R_r": (0.5, 1.5), "R_s": (0.8, 1.2), "L_m": (0.85, 1.15), "J": (0.7, 1.3)}

_STARTUP = """
import json, time
t0 = time.perf_counter()
import bench.batch.kernel
t1 = time.perf_counter()
from bench.batch.engine import Run, simulate
from bench.core.config import load
rig = load("mock")
t2 = time.perf_counter()
simulate([Run(rig)], "fig5.7", 0.01)
t3 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "first_batch_s": t3 - t2}))
"""


def startup(cold: bool = False) -> dict[str, Any]:
    """Import (numba, the compiled modules) and the first batch call in a fresh process [s]; ``cold``: with an
    empty numba cache, i.e. compiling everything."""
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        if cold:
            env["NUMBA_CACHE_DIR"] = tmp
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-c", _STARTUP], capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
    if p.returncode != 0:
        return {"error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    out = json.loads(p.stdout.strip().splitlines()[-1])
    return {"cache": "empty (compiles)" if cold else "as found (warm after the first run)", **out,
            "process_wall_s": wall}  # fmt: skip


def cases(n: int, seed: int = 0) -> list[Any]:
    """``n`` atlas-like runs: random factors on the true machine, seeds 0..n-1."""

    base = tomllib.loads((RIGS_DIR / "mock.toml").read_text())
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        plant = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in FACTORS.items()}
        out.append(Run(parse({**base, "mock": apply(base.get("mock", {}), plant)}, None), seed=i))
    return out


def scalar(runs: list[Any], scenario: str, duration: float) -> dict[str, Any]:
    """The runs one by one on the scalar engine (compiled plant and FOC, no log)."""
    ticks, loop, t0 = 0, 0.0, time.perf_counter()
    for r in runs:
        opts = RunOptions(rig=r.rig, controller="foc", scenario=scenario, duration=duration, realtime=False,
                          seed=r.seed, params={"engine": "compiled"}, progress=False, log_enabled=False)
        s, _ = run_session(opts)
        ticks += s["ticks"]
        loop += s["wall_time"]
    wall = time.perf_counter() - t0
    return {"cases": len(runs), "motor_ticks": ticks, "session_wall_s": wall, "loop_wall_s": loop,
            "motor_ticks_per_s": ticks / loop, "session_motor_ticks_per_s": ticks / wall}  # fmt: skip


def _cost(rate: float, yard: float | None) -> dict[str, float | None]:
    """A rate [motor steps/s] as a cost per step: microseconds, and yardsticks where the yardstick ran."""
    us = 1e6 / rate
    return {"us_per_motor_tick": us, "yardsticks_per_motor_tick": us / yard if yard else None}


def run(sizes: tuple[int, ...] = (1, 10, 100, 1000), duration: float = 0.5, scenario: str = "fig5.7",
        scalar_cases: int = 3, cold: bool = False, peers: bool = True,
        peers_python: str | None = None) -> dict[str, Any]:  # fmt: skip
    """The benchmark's JSON document (``peers_python``: the interpreter the peers run in, e.g. a venv of their own)."""
    import numba


    out: dict[str, Any] = {"benchmark": "batch engine: motor-ticks/s vs batch size", "scenario": scenario,
                           "duration_s": duration, "numba_threads": numba.get_num_threads(),
                           "cpus": os.cpu_count(), "load_average_before": os.getloadavg()}  # fmt: skip
    out["startup"] = startup(cold)
    out["yardstick_us"] = yardstick_us()
    pool = cases(max(sizes))
    simulate(pool[:1], scenario, 0.01)  # this process's start-up (cache, threads): not in the figures below
    out["scalar_before"] = scalar(pool[:scalar_cases], scenario, duration)
    rows = []
    for n in sizes:
        timing: dict[str, float] = {}
        res = simulate(pool[:n], scenario, duration, timing)
        ticks = sum(s["ticks"] for s in res)
        rows.append({"cases": n, "motor_ticks": ticks, "tripped": sum(s["trip_cause"] is not None for s in res),
                     "build_s": timing["build_s"], "loop_s": timing["loop_s"],
                     "loop_cpu_s": timing["loop_cpu_s"], "motor_ticks_per_s": ticks / timing["loop_s"],
                     "motor_ticks_per_cpu_s": ticks / timing["loop_cpu_s"],
                     "end_to_end_motor_ticks_per_s": ticks / (timing["build_s"] + timing["loop_s"])})  # fmt: skip
    out["batch"] = rows
    out["scalar_after"] = scalar(pool[:scalar_cases], scenario, duration)
    out["peers"] = [peer_mod.run(name, python=peers_python) for name in peer_mod.PEERS] if peers else []
    yard = out["yardstick_us"]
    ref = 0.5 * (out["scalar_before"]["motor_ticks_per_s"] + out["scalar_after"]["motor_ticks_per_s"])
    for r in rows:
        r["speedup_vs_scalar_loop"] = r["motor_ticks_per_s"] / ref
        r.update(_cost(r["motor_ticks_per_s"], yard))
    for key in ("scalar_before", "scalar_after"):
        out[key].update(_cost(out[key]["motor_ticks_per_s"], yard))
    side = [{"engine": f"batch, {r['cases']} cases", "motor_ticks_per_s": r["motor_ticks_per_s"],
             **_cost(r["motor_ticks_per_s"], yard)} for r in rows]  # fmt: skip
    side.append({"engine": "scalar (mean of before and after)", "motor_ticks_per_s": ref, **_cost(ref, yard)})
    for p in out["peers"]:
        if "steps_per_s" in p:
            p.update(_cost(p["steps_per_s"], yard))
            side.append({"engine": p["peer"], "motor_ticks_per_s": p["steps_per_s"], **_cost(p["steps_per_s"], yard),
                         "step_s": p["step_s"]})  # fmt: skip
    out["side_by_side"] = side
    out["load_average_after"] = os.getloadavg()
    out["note"] = ("loop rates exclude the cases' construction (build_s); the machine may be shared: compare "
                   "rows of one run, and the load averages; a peer's motor tick is its own step (step_s), the "
                   "batch and scalar engines' is 1/3000 s with the FOC, sensors and supervisor")  # fmt: skip
    return out


def plot(doc: dict[str, Any], path: Any) -> Any:
    """Motor-ticks/s against the batch size (log-log; per wall second and per CPU-second), the scalar engine and the
    peers as horizontal lines; a PNG at ``path``."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    rows = doc["batch"]
    n = [r["cases"] for r in rows]
    ax.loglog(n, [r["motor_ticks_per_s"] for r in rows], "o-", color="C0", label="batch engine (wall)")
    ax.loglog(n, [r["motor_ticks_per_cpu_s"] for r in rows], "s--", color="C0", alpha=0.6,
              label="batch engine (per CPU-second)")  # fmt: skip
    ref = 0.5 * (doc["scalar_before"]["motor_ticks_per_s"] + doc["scalar_after"]["motor_ticks_per_s"])
    ax.axhline(ref, color="C1", label="scalar engine (compiled plant and FOC)")
    for i, p in enumerate(q for q in doc.get("peers", []) if "steps_per_s" in q):
        ax.axhline(p["steps_per_s"], color=f"C{i + 2}", ls=":",
                   label=f"{p['peer']} {p.get('version') or ''} (step {p['step_s'] * 1e6:.0f} us)")  # fmt: skip
    ax.set_xlabel("cases in one batch")
    ax.set_ylabel("motor-ticks / s")
    load = doc.get("load_average_before", [None])[0]
    ax.set_title(f"{doc['scenario']}, {doc['duration_s']:g} s per case; {doc['cpus']} CPUs, "
                 f"load average {load:.1f} before" if load is not None else doc["scenario"], fontsize=9)  # fmt: skip
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    return save(fig, path)


def atlas(sample: int = 40, seed: int = 0) -> dict[str, Any]:
    """The robustness atlas' cases the batch engine covers (`bench.workflows.reproductions.atlas`: both sweeps' specs),
    run in this process by the sweep's batch task (`bench.workflows.sweep.batching.run_group`, one batch per sweep),
    with their table rows (`bench.workflows.reproductions.atlas.markdown`) and whether each equals its row in
    docs/results/atlas.md;
    ``sample`` random cases of each sweep are also run on the scalar engine (`run_case`) and compared row by row."""
    import random


    doc = SPECS["observers"].parents[1] / "docs" / "results" / "atlas.md"
    published = doc.read_text().splitlines() if doc.is_file() else []
    out: dict[str, Any] = {"load_average_before": os.getloadavg(), "atlases": {}}
    total = 0.0
    for name, path in SPECS.items():
        cases = [c for c in expand(load(path)) if batchable(c)]
        t0, c0 = time.perf_counter(), time.process_time()
        rows = run_group(cases)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        total += wall
        ticks = sum(r["ticks"] for r in rows)
        lines = markdown(name, summarise(name, rows)).splitlines()[2:]
        table = [ln for ln in lines if ln.startswith("| ")]
        picks = random.Random(seed).sample(range(len(cases)), min(sample, len(cases)))
        t1 = time.perf_counter()
        checks = {cases[i].case_id: rows_differ(rows[i], run_case(cases[i])) for i in picks}
        out["atlases"][name] = {
            "cases": len(rows), "engine": "batch" if all(r["compute_us_p50"] is None for r in rows) else "scalar",
            "motor_ticks": ticks, "wall_s": wall, "cpu_s": cpu, "motor_ticks_per_s": ticks / wall,
            "table_rows": table, "equal_to_docs_results_atlas_md": [ln in published for ln in table],
            "scalar_check": {"cases": len(checks), "equal": sum(v is None for v in checks.values()),
                             "differing": {k: v for k, v in checks.items() if v is not None},
                             "scalar_wall_s": time.perf_counter() - t1},
        }  # fmt: skip
    out["wall_s"] = total
    out["load_average_after"] = os.getloadavg()
    return out


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
