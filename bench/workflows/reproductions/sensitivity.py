"""Variance-based sensitivity (Sobol indices) of the current-model FOC's errors over the true machine and the operating
point: a study the batch engine makes affordable (~10^5 whole sessions).

Factors (uniform): the true machine's R_r, R_s, L_m and J as factors on the thesis machine (3.57) in the robustness
atlas' ranges (R_r x0.5-1.5, R_s x0.8-1.2, L_m x0.85-1.15, J x0.7-1.3; the controller keeps the nominal values),
the speed reference 10-150 rad/s (electrical) and the load step 0-6 N m of the scenario ``load-step``
(`bench.core.scenarios.load_step`: the magnetising lead-in, the constant speed reference from 0.4 s, the load step at
0.7 s, 1 s in all). Outputs of each case (`bench.batch.engine.simulate`, the session's summary): the current-model
observer's flux-angle error against the true rotor flux, RMS from 0.5 s [deg]
(`bench.runtime.metrics.estimation_errors`), and the speed-tracking error, RMS over the settled ticks (0.2 s after the
reference step; the load step's dip included) [rad/s].

Sampling and indices by SALib: Saltelli's scheme on a scrambled Sobol sequence, N (D + 2) cases for D = 6 factors
(first-order and total indices; no second order), the indices' 95 % confidence intervals by SALib's bootstrap.
A case that trips would leave a hole in Saltelli's design: the study stops then, naming how many.

    python3 -m bench.workflows.reproductions.sensitivity --out runs/sensitivity [--n 16384] [--batch 4096]

JSON on stdout (the indices with their intervals, the outputs' spread, wall time, motor-ticks/s), progress with an ETA
on stderr, ``OUT/sensitivity.png`` (the indices as bars with their intervals) and ``OUT/sensitivity.md`` (the table
of docs/results/sensitivity.md).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import tomllib
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from bench.core.progress import Steps
from bench.workflows.sweep.plant import apply
from bench.core.plotstyle import grid_figsize, pyplot, save
from bench.batch.engine import Run, simulate
from bench.core.config import RIGS_DIR, parse

# (name, low, high, label): machine factors on the true machine (bench.workflows.sweep.plant), then the scenario's
# arguments
FACTORS = (("R_r", 0.5, 1.5, "R_r (true / nominal)"), ("R_s", 0.8, 1.2, "R_s (true / nominal)"),
           ("L_m", 0.85, 1.15, "L_m (true / nominal)"), ("J", 0.7, 1.3, "J (true / nominal)"),
           ("speed", 10.0, 150.0, "speed reference [rad/s, el.]"), ("load", 0.0, 6.0, "load step [N m]"))  # fmt: skip
MACHINE = ("R_r", "R_s", "L_m", "J")
OUTPUTS = (("flux_angle_rms_deg", "flux-angle error RMS [deg]"), ("speed_error_settled_rms", "speed-tracking error "
           "RMS, settled [rad/s]"))  # fmt: skip
SCENARIO = "load-step"


def problem() -> dict[str, Any]:
    """SALib's problem: the factors and their bounds."""
    return {"num_vars": len(FACTORS), "names": [f[0] for f in FACTORS], "bounds": [[f[1], f[2]] for f in FACTORS]}


def design(n: int, seed: int = 0) -> np.ndarray:
    """Saltelli's design for first-order and total indices: ``n (D + 2)`` rows, one per case."""
    from SALib.sample import sobol as sobol_sample

    return sobol_sample.sample(problem(), n, calc_second_order=False, scramble=True, seed=seed)


def _outputs(summary: dict[str, Any]) -> tuple[float, float]:
    est, sp = summary["estimation_errors"], summary["speed_error_settled"]
    return float(est["flux_angle_rms_deg"]), float(sp["rms"])


def run_cases(X: np.ndarray, batch: int = 4096, progress: bool = True) -> dict[str, Any]:
    """Every row of ``X`` as a case of the batch engine (seed = row index): the outputs, trips, timing."""

    base = tomllib.loads((RIGS_DIR / "mock.toml").read_text())
    names = [f[0] for f in FACTORS]
    Y = np.full((len(X), len(OUTPUTS)), math.nan)
    trips: list[str] = []
    ticks, build, loop, loop_cpu = 0, 0.0, 0.0, 0.0
    t0 = time.perf_counter()
    with Steps(len(X), "sensitivity cases", tty=None if progress else False) as step:
        for lo in range(0, len(X), batch):
            runs = []
            for i in range(lo, min(lo + batch, len(X))):
                v = dict(zip(names, (float(x) for x in X[i])))
                plant = {k: v[k] for k in MACHINE}
                rig = parse({**base, "mock": apply(base.get("mock", {}), plant)}, None)
                runs.append(Run(rig, seed=i, scenario_args={"speed": v["speed"], "load": v["load"]}))
            timing: dict[str, float] = {}
            out = simulate(runs, SCENARIO, None, timing)
            for j, s in enumerate(out):
                if s["trip_cause"] is not None:
                    trips.append(f"case {lo + j}: {s['trip_cause']}")
                else:
                    Y[lo + j] = _outputs(s)
                ticks += s["ticks"]
            build += timing["build_s"]
            loop += timing["loop_s"]
            loop_cpu += timing["loop_cpu_s"]
            if progress:
                step(lo + len(runs))
    wall = time.perf_counter() - t0
    return {"Y": Y, "trips": trips, "motor_ticks": ticks, "wall_s": wall, "build_s": build, "loop_s": loop,
            "loop_cpu_s": loop_cpu}  # fmt: skip


def indices(Y: np.ndarray, resamples: int = 1000, seed: int = 0) -> dict[str, Any]:
    """First-order and total Sobol indices of each output, with their 95 % bootstrap confidence half-widths."""
    from SALib.analyze import sobol

    names = [f[0] for f in FACTORS]
    out: dict[str, Any] = {}
    for k, (key, label) in enumerate(OUTPUTS):
        y = Y[:, k]
        r = sobol.analyze(problem(), y, calc_second_order=False, num_resamples=resamples, conf_level=0.95,
                          seed=seed)  # fmt: skip
        out[key] = {"label": label, "mean": float(np.mean(y)), "std": float(np.std(y)),
                    "p5": float(np.percentile(y, 5)), "p95": float(np.percentile(y, 95)),
                    "factors": {n: {"S1": float(r["S1"][i]), "S1_conf": float(r["S1_conf"][i]),
                                    "ST": float(r["ST"][i]), "ST_conf": float(r["ST_conf"][i])}
                                for i, n in enumerate(names)}}  # fmt: skip
    return out


def study(n: int = 16384, batch: int = 4096, seed: int = 0, resamples: int = 1000,
          progress: bool = True) -> dict[str, Any]:  # fmt: skip
    """The whole study: design, cases, indices; the JSON document (without the per-case arrays)."""
    load0 = os.getloadavg()
    X = design(n, seed)
    res = run_cases(X, batch, progress)
    if res["trips"]:
        raise SystemExit(f"sensitivity: {len(res['trips'])} of {len(X)} cases tripped (first: {res['trips'][0]}); "
                         "Saltelli's design needs every case")  # fmt: skip
    return {
        "study": "Sobol indices of the current-model FOC's errors (batch engine)", "scenario": SCENARIO,
        "date_utc": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M"), "n": n, "cases": len(X),
        "factors": {f[0]: {"low": f[1], "high": f[2], "label": f[3]} for f in FACTORS},
        "sampling": "Saltelli (SALib.sample.sobol, scrambled Sobol sequence, no second order), seed " f"{seed}",
        "confidence": f"95 %, SALib bootstrap, {resamples} resamples",
        "indices": indices(res["Y"], resamples, seed),
        "motor_ticks": res["motor_ticks"], "wall_s": res["wall_s"], "build_s": res["build_s"],
        "loop_s": res["loop_s"], "motor_ticks_per_s": res["motor_ticks"] / res["wall_s"],
        "loop_motor_ticks_per_s": res["motor_ticks"] / res["loop_s"],
        "loop_motor_ticks_per_cpu_s": res["motor_ticks"] / res["loop_cpu_s"],
        "cpus": os.cpu_count(), "load_average_before": load0, "load_average_after": os.getloadavg(),
    }  # fmt: skip


def markdown(doc: dict[str, Any]) -> str:
    """The indices as a table: per output a row per factor, S1 and ST with their 95 % intervals."""
    lines = []
    for key, _ in OUTPUTS:
        o = doc["indices"][key]
        lines += [f"**{o['label']}**: mean {o['mean']:.3g}, standard deviation {o['std']:.3g}, 5-95 % "
                  f"{o['p5']:.3g} ... {o['p95']:.3g}", "",
                  "| factor | range | first-order S1 | total ST |", "|---|---|---|---|"]  # fmt: skip
        for name, f in o["factors"].items():
            fr = doc["factors"][name]
            lines.append(f"| {fr['label']} | {fr['low']:g} ... {fr['high']:g} | {f['S1']:.3f} ± {f['S1_conf']:.3f} "
                         f"| {f['ST']:.3f} ± {f['ST_conf']:.3f} |")  # fmt: skip
        lines.append("")
    return "\n".join(lines)


def plot(doc: dict[str, Any], png: Path) -> Path:
    """Per output, first-order and total indices as bars per factor, the 95 % intervals as error bars."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(OUTPUTS), figsize=grid_figsize(1, len(OUTPUTS), 6.5, 3.6))
    names = list(doc["factors"])
    x = np.arange(len(names))
    for ax, (key, _) in zip(axes, OUTPUTS):
        o = doc["indices"][key]
        f = [o["factors"][n] for n in names]
        ax.bar(x - 0.2, [v["S1"] for v in f], 0.4, yerr=[v["S1_conf"] for v in f], capsize=3, label="first order S1")
        ax.bar(x + 0.2, [v["ST"] for v in f], 0.4, yerr=[v["ST_conf"] for v in f], capsize=3, label="total ST")
        ax.set_xticks(x, names)
        ax.set_ylim(min(0.0, *(v["S1"] - v["S1_conf"] for v in f)) - 0.02, 1.05)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(o["label"], fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_ylabel("Sobol index (95 % interval)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"current-model FOC, scenario {doc['scenario']}: {doc['cases']} cases (Saltelli, N = {doc['n']})",
                 fontsize=10)  # fmt: skip
    return save(fig, png)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m bench.workflows.reproductions.sensitivity",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for sensitivity.png and sensitivity.md")
    ap.add_argument("--n", type=int, default=16384, help="Saltelli's base sample N (a power of 2); cases = 8 N")
    ap.add_argument("--batch", type=int, default=4096, help="cases per batch-engine call (memory: ~50 kB a case)")
    ap.add_argument("--seed", type=int, default=0, help="the Sobol sequence's scrambling and the bootstrap's seed")
    ap.add_argument("--resamples", type=int, default=1000, help="bootstrap resamples for the confidence intervals")
    a = ap.parse_args(argv)
    for name, v, lo, hi in (("--n", a.n, 8, 1 << 20), ("--batch", a.batch, 1, 20000), ("--resamples", a.resamples,
                            10, 100000)):  # fmt: skip
        if not lo <= v <= hi:
            print(f"sensitivity: {name} must be in {lo}..{hi}, got {v}", file=sys.stderr)
            return 2
    if a.n & (a.n - 1):
        print(f"sensitivity: --n must be a power of 2 (Sobol sequence), got {a.n}", file=sys.stderr)
        return 2
    if a.out.exists() and not a.out.is_dir():
        print(f"sensitivity: --out must be a folder, got the file {a.out}", file=sys.stderr)
        return 2
    import importlib.util

    for mod, dist in (("SALib", "sensitivity"), ("numba", "")):
        if importlib.util.find_spec(mod) is None:
            print(f"sensitivity: needs {mod}: pip install 'imbench[{dist}]'" if dist else
                  f"sensitivity: needs {mod} (the batch engine)", file=sys.stderr)  # fmt: skip
            return 2
    a.out.mkdir(parents=True, exist_ok=True)
    doc = study(a.n, a.batch, a.seed, a.resamples)
    doc["png"] = str(plot(doc, a.out / "sensitivity.png"))
    (a.out / "sensitivity.md").write_text(markdown(doc))
    doc["markdown"] = str(a.out / "sensitivity.md")
    print(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
