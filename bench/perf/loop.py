"""Benchmarks of the loop (JSON results; recorded in docs/RESULTS.md).

* `loop`: real-time 3 kHz, FOC + full logging on the mock rig: ticks, deadline misses, wake-up
  latency and compute-time percentiles, and the log writer's put() cost.
* `sim`: lockstep, full logging: simulated seconds per wall second, for the loop alone and until
  the log file is closed.
"""

from __future__ import annotations

import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from bench.core import scenarios
from bench.core.config import load as load_rig
from bench.daq import Topic
from bench.daq.memory import MemoryLog
from bench.runtime.loop import TimedLoop, log_topics
from bench.runtime.session import open_log
from bench.runtime.compose import build_rig, make_controller
from bench.core.supervisor import Supervisor


def run_benchmark(kind: str, duration: float, rig_name: str = "mock", controller: str = "foc",
                  scenario: str = "demo", seed: int = 0, log: bool | str = True,
                  params: dict[str, Any] | None = None, engine: str | None = None) -> dict[str, Any]:  # fmt: skip
    """One benchmark run; ``log``: True (MCAP through the writer process), False (none) or ``"memory"`` (the
    in-memory record every sweep case keeps, `bench.daq.memory.MemoryLog`); ``engine``: the mock plant's and,
    for the FOC, the controller's (unless ``params`` sets ``engine``)."""
    cfg = load_rig(rig_name)
    if engine is not None:  # the mock plant's engine ([mock] engine: compiled | python | auto)
        cfg = replace(cfg, mock={**cfg.mock, "engine": engine})
        if controller == "foc":  # and the FOC's (``params`` may still set its own)
            params = {"engine": engine, **(params or {})}
    scn = scenarios.get(scenario)
    rig = build_rig(cfg, seed)
    ctrl = make_controller(cfg, rig, controller, params or {})
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    realtime = kind == "loop"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "perf.mcap"
        topics = [Topic(n, s, f) for n, s, f in log_topics(rig, ctrl)]
        if log == "memory":
            writer: Any = MemoryLog(topics)
        else:
            writer = open_log(path, topics, {"run": {"benchmark": kind}}, realtime=realtime, rate_hz=cfg.rate_hz,
                              on_fault=sup.request_trip) if log else None  # fmt: skip
        rig.configure()
        rig.activate()
        t_start = time.perf_counter()
        try:
            res = TimedLoop(rig, ctrl, scn, sup, T_s=cfg.T_s, duration=duration, realtime=realtime, log=writer).run()
        finally:
            rig.deactivate()
            if writer is not None and log is True:
                writer.close()
        t_closed = time.perf_counter() - t_start
        log_stats = writer.stats() if writer is not None else None
        size = path.stat().st_size if log is True else 0
    out: dict[str, Any] = {
        "benchmark": f"perf {kind}",
        "rate_hz": cfg.rate_hz,
        "duration_s": res.sim_time,
        "ticks": res.ticks,
        "logging": log,
        "plant_engine": getattr(rig.truth, "engine", None),
        "controller_params": params or {},
        "machine": {"python": platform.python_version(), "cpus": __import__("os").cpu_count()},
    }
    if realtime:
        out.update({
            "deadline_misses": res.deadline_misses,
            "deadline_miss_fraction": res.deadline_misses / max(res.ticks + res.skipped, 1),
            "overruns": res.overruns,
            "skipped_ticks": res.skipped,
            "rt_setup": res.rt_setup,
        })  # fmt: skip
    else:
        out.update({
            "sim_seconds_per_wall_second_loop": res.realtime_factor,
            "sim_seconds_per_wall_second_incl_log_close": res.sim_time / t_closed,
        })  # fmt: skip
    out["timing"] = res.timing()
    if log_stats is not None:
        out["log_writer"] = log_stats
        out["log_bytes_per_tick"] = size / max(res.ticks, 1)
    out["trip_cause"] = res.trip_cause
    return out
