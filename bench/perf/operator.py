"""Cost of on-line operation in the loop (bench.operate.operator): lockstep ticks, no log, side by side.

Three variants, interleaved in rounds so machine noise hits them alike: no operator (a run without
--live), an idle operator (a live run nobody talks to: one check per tick), and one applying a
parameter change every 0.1 s of loop time (a busy tuning session). Per-tick compute time is given
in microseconds and in yardsticks (one plain-Python RK4 motor step, measured in the same run).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.core import scenarios
from bench.core.config import load as load_rig
from bench.runtime.loop import TimedLoop
from bench.operate.operator import Operator
from bench.operate.requests import ParamSpace, ReplaySource, Request
from bench.perf.live import yardstick_us
from bench.runtime.compose import build_rig, make_controller
from bench.core.supervisor import Supervisor
from bench.daq.writer import RequestInbox
from bench.daq.writer_process import IDX_SLOTS


def _one(variant: str, duration: float) -> float:
    cfg = load_rig("mock")
    rig = build_rig(cfg, 0)
    ctrl = make_controller(cfg, rig, "foc", {})
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    op = None
    if variant != "none":
        every = int(round(0.1 * cfg.rate_hz))
        n = int(duration * cfg.rate_hz)
        reqs = [Request(i, "set", "speed_Kp", 0.6 + 0.01 * (i % 2), "perf", k)
                for i, k in enumerate(range(every, n, every))] if variant == "busy" else []  # fmt: skip
        events: list[dict] = []
        op = Operator(ctrl, ParamSpace.of(ctrl, cfg.limits, rig.load.torque_limit), ReplaySource(reqs), events.append,
                      sup.request_trip)  # fmt: skip
    rig.configure()
    rig.activate()
    try:
        res = TimedLoop(rig, ctrl, scenarios.get("demo"), sup, T_s=cfg.T_s, duration=duration, operator=op).run()
    finally:
        rig.deactivate()
    return float(np.mean(res.compute_us))


def _idle_check_us(n: int = 200_000) -> float:
    """What an idle operator adds to a tick, timed alone: the loop's ``op is not None and op.due(k)``
    (a live run's inbox: three reads of shared memory)."""
    import multiprocessing as mp
    import timeit


    r, w = mp.Pipe(duplex=False)
    try:
        op = Operator.__new__(Operator)  # only what `due` reads
        op.source, op._wake = RequestInbox(mp.RawArray("q", IDX_SLOTS), r), float("inf")
        t = min(timeit.repeat("op is not None and op.due(k)", globals={"op": op, "k": 12345}, number=n, repeat=5))
    finally:
        r.close()
        w.close()
    return t / n * 1e6


def run(duration: float = 2.0, rounds: int = 3) -> dict[str, Any]:
    variants = ("none", "idle", "busy")
    times: dict[str, list[float]] = {v: [] for v in variants}
    yard = yardstick_us()
    for _ in range(rounds):
        for v in variants:
            times[v].append(_one(v, duration))
    out: dict[str, Any] = {"benchmark": "perf operator", "duration_s": duration, "rounds": rounds,
                           "yardstick_us": yard, "compute_us_mean": {}}  # fmt: skip
    for v in variants:  # the minimum over rounds is the least disturbed by other load on the machine
        best, med = float(np.min(times[v])), float(np.median(times[v]))
        out["compute_us_mean"][v] = {"min_of_rounds": best, "median_of_rounds": med, "rounds": times[v],
                                     "yardsticks_min": best / yard if yard else None}  # fmt: skip
    out["idle_check_us"] = _idle_check_us()
    c = out["compute_us_mean"]
    out["extra_us_per_tick"] = {v: {"min": c[v]["min_of_rounds"] - c["none"]["min_of_rounds"],
                                    "median": c[v]["median_of_rounds"] - c["none"]["median_of_rounds"]}
                                for v in variants[1:]}  # fmt: skip
    return out
