"""`bench perf switch`: what switching parts costs the real-time loop, side by side with a run that does not switch.

Real-time runs of scenario ``hold`` at `SPEED` and `LOAD` (100 rad/s, 5 N m; why not the rated point: at `SPEED`) on
the mock rig, alternating in rounds, all the same length, with the log: without switches (the default parts, and the
LPV parts throughout: what they cost per tick themselves), and with ``SWITCHES`` switches evenly spaced after the
load is on (`CYCLES`: among observers of about the same cost, which isolates the switching; and to the LPV parts and
back). Per run: deadline misses (overruns + skipped ticks), the compute time per tick (p50, p99, max) and that of
the ticks a switch was applied before (the incoming part's first tick; the hand-over itself runs in the slack before
the tick's deadline, bench.runtime.loop); and the hand-over alone per switch (`handover_us`, lockstep), in microseconds
and in yardsticks (one plain-Python RK4 motor step, ../shared/yardstick.py, measured in the same run).
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.core import load_profiles, scenarios
from bench.runtime.loop import TimedLoop
from bench.core.supervisor import Supervisor
from bench.perf.live import yardstick_us
from bench.daq import LogReader
from bench.core.config import load
from bench.runtime.session import RunOptions, run as run_session
from bench.runtime.compose import build_rig, make_controller

SWITCHES = 20
SPEED, LOAD = 100.0, 5.0  # [rad/s], [N m]: the operating point. At the rated speed a stall of the loop (another
# process taking the CPU for 1-2 ms: 3-6 skipped ticks with the last voltage held while the field turns 0.3-0.6 rad)
# tripped on over-current in 2 of 4 real-time runs at 5 N m here, with or without switches; never in lockstep
# what a run switches through: parts of about the same per-tick cost (the switching itself, side by side with a run
# that does not switch), and the LPV parts (whose ticks cost more in Python: that run's compute time rises with them)
CYCLES = {"observers": (("observer", "jl"), ("observer", "voltage_model"), ("observer", "kubota"),
                        ("observer", "current_model")),
          "lpv parts": (("speed_controller", "lpv"), ("current_controller", "lpv"), ("observer", "lpv"),
                        ("speed_controller", "pi"), ("current_controller", "pi"), ("observer", "current_model"))}  # fmt: skip
CYCLE = CYCLES["lpv parts"]  # the hand-overs timed alone (`handover_us`)


def schedule(duration: float, cycle: tuple = CYCLE, n: int = SWITCHES,
             start: float = 1.5) -> tuple[tuple[float, str, str], ...]:  # fmt: skip
    """``n`` switches evenly spaced from ``start`` to 0.3 s before the end, cycling through ``cycle``."""
    step = (duration - 0.3 - start) / n
    return tuple((round(start + i * step, 4), *cycle[i % len(cycle)]) for i in range(n))


LPV_PARTS = {"speed_controller": "lpv", "current_controller": "lpv", "observer": "lpv"}


def _one(switches: tuple, duration: float, folder: Path, name: str, params: dict | None = None) -> dict[str, Any]:
    log = folder / f"{name}.mcap"
    hold = scenarios.get("hold")
    scn = dataclasses.replace(hold, load=load_profiles.steps([1.0], [LOAD]),
                              speed_ref=lambda t: min(max(t - scenarios.T_MAGNETISE, 0.0) / 0.5, 1.0) * SPEED)  # fmt: skip
    summary, code = run_session(RunOptions(scenario=scn, duration=duration, realtime=True, log=log, progress=False,
                                   switches=switches, force=True, params=params or {}))  # fmt: skip
    r = LogReader(log).read("/rig")
    c, tick = r["compute_us"], r["tick"].astype(int)
    applied = [e["tick"] for e in LogReader(log).events() if e["status"] == "applied"]
    at = np.isin(tick, applied)
    q = np.percentile(c, [50, 99])
    return {"exit_code": code, "trip_cause": summary.get("trip_cause"), "switches_applied": len(applied), "ticks": int(c.size),
            "deadline_misses": summary.get("deadline_misses"), "overruns": summary.get("overruns"),
            "skipped": summary.get("skipped"), "compute_us": {"p50": float(q[0]), "p99": float(q[1]),
                                                               "max": float(c.max())},
            "compute_us_at_switch": {"mean": float(c[at].mean()), "max": float(c[at].max())} if at.any() else None}  # fmt: skip


def handover_us(repeats: int = 5) -> dict[str, float]:
    """The hand-over of each switch of `CYCLE` alone [us], best of ``repeats``: `FocController.set_param` at the
    rated point (lockstep, 1.5 s of scenario ``hold`` first), each switched there and back."""
    import time


    cfg = load("mock")
    rig = build_rig(cfg, 0)
    ctrl = make_controller(cfg, rig, "foc", {})
    ctrl.prepare_switching()
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    rig.configure()
    rig.activate()
    try:
        TimedLoop(rig, ctrl, scenarios.get("hold"), sup, T_s=cfg.T_s, duration=1.5).run()
    finally:
        rig.deactivate()
    out: dict[str, float] = {}
    for part, choice in CYCLE:
        back = ctrl.p[part]
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            ctrl.set_param(part, choice)
            best = min(best, time.perf_counter() - t0)
            ctrl.set_param(part, back)
        out[f"{part}={choice}"] = best * 1e6
    return out


def run(duration: float = 8.0, rounds: int = 2) -> dict[str, Any]:
    yard = yardstick_us()
    out: dict[str, Any] = {"benchmark": "perf switch", "scenario": "hold", "speed_rad_s": SPEED, "load_Nm": LOAD,
                           "duration_s": duration,
                           "switches": {k: schedule(duration, c) for k, c in CYCLES.items()}, "yardstick_us": yard,
                           "runs": []}  # fmt: skip
    out["handover_us"] = handover_us()
    if yard:
        out["handover_yardsticks"] = {k: v / yard for k, v in out["handover_us"].items()}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(rounds):
            variants = [("no switch", (), None), ("no switch, LPV parts", (), LPV_PARTS)] + [
                (f"{SWITCHES} switches: {k}", schedule(duration, c), None) for k, c in CYCLES.items()]  # fmt: skip
            for j, (label, sw, params) in enumerate(variants):
                res = _one(sw, duration, Path(tmp), f"{i}-{j}", params)
                out["runs"].append({"variant": label, "round": i, **res})
    if yard:
        for r in out["runs"]:
            r["compute_yardsticks"] = {k: v / yard for k, v in r["compute_us"].items()}
            if r["compute_us_at_switch"]:
                r["at_switch_yardsticks"] = {k: v / yard for k, v in r["compute_us_at_switch"].items()}
    out["yardstick_us_after"] = yardstick_us()
    return out
