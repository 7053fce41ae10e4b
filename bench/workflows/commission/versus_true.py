"""Commissioned vs true: does a motor commissioned by `bench commission` run as well as the same designs made
with the machine's true parameters? (benchmark: `bench perf commission`)

For each hidden mock motor of the accuracy benchmark (`bench.workflows.commission.accuracy`: R_s, R_r, L_m and the
leakage within ±40 % of (3.57), dead time 0-3 µs, on-state drop 0-2 V, the default sensors):
`bench.workflows.commission.commission.commission` on a rig whose ``[motor]`` is (3.57) and whose ``[mock.motor]``
is the hidden machine (dry run: the designs for the *identified* motor); then
the LPV flux observer (5.6.2) and the quasi-LPV current controller (6.2.2) designed the same way for the
*true* parameters (`against_true`); both pairs run the same closed-loop check (`check.check_scenario`,
scaled to the motor's plate as the commissioning check is, whose first part is Fig. 5.7's experiment: 10 rad/s,
load 0 <-> 3 N m every 1/3 s on the thesis motor) on the same plant and seed. The
numbers, over Fig. 5.7's part after magnetising, against the plant's truth: the flux-angle error (RMS
and p95) and the speed-tracking error ω_ref − ω_r (RMS). The ratio commissioned / true of each is
what the benchmark reports (≤ 1.2 is "within 20 %").
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.workflows.commission.accuracy import HiddenMotor, draw_motors
from bench.params import MotorParams
from bench.core.scenarios import T_MAGNETISE
from bench.workflows.commission.check import LOW_TIME, truth_errors, run_check, check_scenario
from bench.workflows.commission.commission import (CURRENT_CENTRING, CURRENT_OBJECTIVE, CURRENT_RATE,
                                                   CURRENT_RESCALE, commission)
from bench.workflows import synth
from bench.workflows.commission.rigfile import motor_text
from bench.core.config import load as load_rig
from bench.runtime.session import scenario_scaling

METRICS = ("flux_angle_rms_deg", "flux_angle_p95_deg", "speed_tracking_rms")


def fig57_metrics(d: dict[str, np.ndarray], trip_t: float | None) -> dict[str, Any]:
    """The Fig. 5.7 part of the check (after magnetising + 0.1 s, 2 s) against the truth."""
    t_end = T_MAGNETISE + LOW_TIME if trip_t is None else min(trip_t, T_MAGNETISE + LOW_TIME)
    e = truth_errors(d, T_MAGNETISE + 0.1, t_end)
    return {"flux_angle_rms_deg": e["flux_angle_rms_deg"], "flux_angle_p95_deg": e["flux_angle_p95_deg"],
            "speed_tracking_rms": e["tracking_rms"], "tripped": trip_t is not None}


def against_true(rep: dict[str, Any], truth: MotorParams, work: Path, seed: int = 0, *,
                 centring: str = CURRENT_CENTRING, objective: str = CURRENT_OBJECTIVE) -> dict[str, Any]:  # fmt: skip
    """The designs of a `bench.workflows.commission.commission.commission` report ``rep`` (one that reached the closed
    loop) against the same designs made for the machine's true parameters ``truth``: the flux observer and the current
    controller synthesised for a copy of the commissioned candidate rig whose ``[motor]`` is the truth (L_s, L_r,
    L_m, R_s, R_r, J and the friction; the speed PI follows from its J as on any rig), then both pairs through the
    commissioned check's scenario (its rated speed, scaled to the candidate's motor: `check.check_scenario`)
    on the same plant and seed. Fig. 5.7's metrics of each (`fig57_metrics`), their ratio and difference.
    ``centring``, ``objective``: the true current controller's (`bench commission`'s by default)."""
    cand = Path(rep["candidate_rig"])
    names = ("L_s", "L_r", "L_m", "R_s", "R_r", "J", "B_visc", "m_coulomb")
    thesis_true = {k: {"value": getattr(truth, k), "ci95": [getattr(truth, k)] * 2} for k in names}
    work.mkdir(parents=True, exist_ok=True)
    true_rig = work / "true.toml"
    true_rig.write_text(motor_text(cand.read_text(), thesis_true, "true parameters", str(true_rig)))
    cfg = load_rig(str(true_rig))
    arts = work / "true-artifacts"
    synth.flux_observer(cfg.limits.omega_max, cfg.rate_hz, arts / "flux_observer", rig=str(true_rig))
    synth.current_controller(CURRENT_RATE, arts / "current_controller", rig=str(true_rig), rescale=CURRENT_RESCALE,
                             centring=centring, objective=objective)  # fmt: skip
    scn = check_scenario(rep["stages"]["closed loop"]["rated_speed"], scenario_scaling(load_rig(str(cand))))
    res = {}
    for name, r, a in (("commissioned", cand, Path(rep["stages"]["flux observer"]["artifact"]).parent),
                       ("true", true_rig, arts)):  # fmt: skip
        params = {"observer": "lpv", "lpv_artifact": str(a / "flux_observer"), "voltage_source": "measured",
                  "current_controller": "lpv", "lpv_current_artifact": str(a / "current_controller")}  # fmt: skip
        summary, _, cols = run_check(str(r), params, scn, work / f"run-{name}", seed, None, False, False)
        res[name] = fig57_metrics(cols, summary.get("trip_time") if summary.get("trip_cause") else None)
    out: dict[str, Any] = dict(res)
    out["ratio"] = {k: res["commissioned"][k] / res["true"][k] if res["true"][k] > 0 else math.nan for k in METRICS}
    out["difference"] = {k: res["commissioned"][k] - res["true"][k] for k in METRICS}
    return out


def compare_one(case: HiddenMotor, work: Path, seed: int = 0, rotating: bool = False) -> dict[str, Any]:
    """Commissioned vs true designs for one hidden machine (module docstring)."""
    truth = case.params
    rig = work / "hidden.toml"
    rig.write_text(case.rig_text())
    t0 = time.perf_counter()
    rep, code = commission(str(rig), work / "commissioned", dry_run=True, seed=seed, rotating=rotating)
    out: dict[str, Any] = {"truth": {k: getattr(truth, k) for k in ("L_s", "L_m", "R_s", "R_r")},
                           "label": case.label, "dead_time": case.dead_time, "v_on": case.v_on, "verdict": rep["verdict"],
                           "commission_wall_time_s": time.perf_counter() - t0}  # fmt: skip
    ident = rep["stages"]["identify"].get("motor")
    if ident:
        out["identified_error"] = {k: ident[k]["value"] / getattr(truth, k) - 1.0 for k in ("L_s", "L_m", "R_s", "R_r")}
    if "closed loop" not in rep["stages"]:
        return out
    out.update(against_true(rep, truth, work, seed))
    return out


def benchmark(n: int = 5, motors_seed: int = 0, seed: int = 0, rotating: bool = False, say: Any = None) -> dict[str, Any]:
    """`compare_one` over the first ``n`` hidden machines of the accuracy benchmark's draw
    (`bench.workflows.commission.accuracy.draw_motors`); JSON-able."""
    say = say or (lambda s: None)
    cases = draw_motors(n, motors_seed)
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="imbench-vs-true-") as tmp:
        for i, case in enumerate(cases):
            eta = (time.perf_counter() - t0) / i * (n - i) if i else math.nan
            say(f"motor {i + 1}/{n}" + (f" (ETA {eta:.0f} s)" if i else ""))
            work = Path(tmp) / f"m{i}"
            work.mkdir()
            rows.append(compare_one(case, work, seed, rotating))
    worst = {k: max((r["ratio"][k] for r in rows if "ratio" in r), default=math.nan) for k in METRICS}
    worst_diff = {k: max((r["difference"][k] for r in rows if "difference" in r), default=math.nan) for k in METRICS}
    return {"benchmark": "commissioned vs true designs, Fig. 5.7's experiment", "motors": n, "seed": seed,
            "motors_seed": motors_seed, "rotating": rotating, "rows": rows, "worst_ratio": worst, "worst_difference": worst_diff,
            "all_go": all(r["verdict"].startswith("GO") for r in rows),
            "within_20_percent": bool(all(v <= 1.2 for v in worst.values())),
            "wall_time_s": time.perf_counter() - t0}  # fmt: skip

