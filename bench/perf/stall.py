"""Stall ride-through: loop stalls injected at the rated point, under load and while the FOC magnetises the motor
at a run's start, with and without it.

Each case is a lockstep run of the mock rig (the default controller, FOC with the current model) in which
the loop skips the ticks of one stall, as a real-time loop that the OS stalled does (`bench.runtime.loop.TimedLoop`
``inject_stalls``: the same code path, deterministic). Two drives:

* ``ride-through``: the drive turns the last reference at the field's frequency for up to the rig's
  ``limits.ride_through`` (bench.hal.InverterPort), the controller resynchronises after the stall, and the
  drive has its own over-current trip and current limit (`mock_hw.inverter`);
* ``hold``: the drive of before: it holds the last stator-fixed voltage for as long as the stall lasts, the
  controller does not resynchronise, and the drive has no over-current trip of its own (only the PC's
  supervisor trips, when the loop runs again).

Per case: whether and why the run tripped, the largest phase current while the drive rode through (the
drive's own samples at each period start; the PC sees none of them) and in the 50 ms after the stall (the
PC's samples), against the PC's phase trip, and the speed dip (the true speed's lowest point in the 0.3 s
after the stall below its mean in the 0.1 s before).

`speed_step` (``bench perf stall --speed-step``): stalls around fig5.7's speed step under the PI and the LPV laws.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from bench.controllers.foc import FocController
from mock_hw import plant
from mock_hw.inverter import Inverter
from bench.core.config import load
from bench.runtime.session import RunOptions, run as run_session

STALLS_MS = (2.0, 4.0, 8.0, 16.0, 20.0, 32.0, 64.0)
# (scenario, time of the stall [s]): the rated point (297 rad/s, 10 N m from 1 s), 100 rad/s at 7 N m, and the
# first milliseconds of a run (standstill, the FOC forcing the magnetising current up with the full voltage)
POINTS = (("hold", 3.0), ("warmup", 3.0), ("fig5.7", 0.0004))
MODES = ("ride-through", "hold")
WINDOW = 0.3  # [s] after the stall in which the speed dip is taken


@contextlib.contextmanager
def _drive_of_before() -> Iterator[None]:
    """The ``hold`` drive: it ignores the frequency sent with a reference (holds it), has no budget and no trip of
    its own, and the controller does not resynchronise."""

    saved = Inverter.set_voltage, FocController._ride_through, plant.drive_settings
    Inverter.set_voltage = lambda self, u, omega_u=0.0: saved[0](self, u, 0.0)  # type: ignore[method-assign]
    FocController._ride_through = lambda self, gap: None  # type: ignore[method-assign]
    plant.drive_settings = lambda limits: {"ride_through": None, "i_trip": 1e9, "i_limit": 1e9}  # type: ignore[assignment]
    try:
        yield
    finally:
        Inverter.set_voltage, FocController._ride_through, plant.drive_settings = saved  # type: ignore[method-assign]


def case(scenario: str, t_stall: float, stall_ms: float, mode: str) -> dict[str, Any]:
    """One lockstep run with one stall; the numbers of the module docstring."""
    opts = RunOptions(scenario=scenario, duration=t_stall + WINDOW + 0.05, realtime=False, log_enabled=False,
                      progress=False, inject_stalls={t_stall: stall_ms * 1e-3})  # fmt: skip
    with _drive_of_before() if mode == "hold" else contextlib.nullcontext():
        summary, code = run_session(opts)
    rec = summary["record"]
    rig, truth = rec.read("/rig"), rec.read("/truth")
    t, w = rig["t"], truth["omega_r"]
    t_end = t_stall + stall_ms * 1e-3
    before = (t > t_stall - 0.1) & (t < t_stall)
    after = t >= t_end - 1e-9
    i_ph = np.max(np.abs(np.stack([rig["i_a"], rig["i_b"], rig["i_c"]])), axis=0)
    soon = after & (t < t_end + 0.05)
    drive = summary["stalls"].get("drive", {})
    return {
        "scenario": scenario, "t_stall": t_stall, "stall_ms": stall_ms, "mode": mode, "exit_code": code,
        "tripped": summary["trip_cause"] is not None, "trip_cause": summary["trip_cause"],
        "i_peak_ride_through": round(float(drive.get("i_peak_ride_through", math.nan)), 3) if mode != "hold" else None,
        "i_peak_after": round(float(i_ph[soon].max()), 3) if soon.any() else None,
        "speed_before": round(float(w[before].mean()), 3),
        "speed_dip": round(float(w[before].mean() - w[after & (t < t_end + WINDOW)].min()), 3) if after.any() else None,
    }  # fmt: skip


def run(stalls_ms: tuple[float, ...] = STALLS_MS, plot: Path | None = None) -> dict[str, Any]:
    """Every point x mode x stall; progress on stderr; the plot of one stall of each mode at the rated point."""
    lim = load("mock").limits
    rows: list[dict[str, Any]] = []
    n, t0 = len(POINTS) * len(MODES) * len(stalls_ms), time.perf_counter()
    for scenario, t_stall in POINTS:
        for mode in MODES:
            for ms in stalls_ms:
                rows.append(case(scenario, t_stall, ms, mode))
                done = len(rows)
                eta = (time.perf_counter() - t0) / done * (n - done)
                print(f"\rstall cases {done}/{n}, ETA {eta:4.0f} s", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    doc: dict[str, Any] = {
        "benchmark": "stall", "rig": "mock", "I_trip_phase": lim.I_trip_phase, "ride_through_ms": lim.ride_through * 1e3,
        "max_stall_ms": lim.max_stall * 1e3, "cases": rows,
        "goal_met": all(not r["tripped"] for r in rows if r["mode"] == "ride-through" and r["scenario"] == "hold"
                        and r["stall_ms"] <= lim.ride_through * 1e3),
        "wall_s": round(time.perf_counter() - t0, 1),
    }  # fmt: skip
    if plot is not None:
        doc["plot"] = str(draw(plot, 16.0))
    return doc


# the speed step grid: fig5.7's step 0 -> 10 rad/s at 0.4 s (the end of the magnetising), each set of laws switched in
# at 0.2 s, a stall starting anywhere from 1 ms before the step to 11.5 ms after it
LAWS = {"pi": (), "lpv speed": ("speed_controller",),
        "lpv speed, observer, current": ("speed_controller", "observer", "current_controller")}
STEP_STALLS_MS = (2.0, 4.0, 7.0, 12.0)


def speed_step(stalls_ms: tuple[float, ...] = STEP_STALLS_MS) -> dict[str, Any]:
    """Per set of laws (`LAWS`): trips and the largest phase current the PC samples after 0.39 s, over stalls of
    ``stalls_ms`` starting every 0.5 ms from 0.399 s to 0.4115 s (lockstep runs to 0.6 s)."""
    lim = load("mock").limits
    starts = [round(0.399 + 0.0005 * i, 6) for i in range(26)]
    out: dict[str, Any] = {}
    n, t0, done = len(LAWS) * len(starts) * len(stalls_ms), time.perf_counter(), 0
    for name, parts in LAWS.items():
        worst: list[tuple[float, float, float, str | None]] = []
        for at in starts:
            for ms in stalls_ms:
                summary, _ = run_session(RunOptions(scenario="fig5.7", duration=0.6, realtime=False, log_enabled=False,
                                                    progress=False, switches=tuple((0.2, p, "lpv") for p in parts),
                                                    inject_stalls={at: ms * 1e-3}))  # fmt: skip
                rig = summary["record"].read("/rig")
                i_ph = np.max(np.abs(np.stack([rig["i_a"], rig["i_b"], rig["i_c"]])), axis=0)[rig["t"] > 0.39]
                worst.append((round(float(i_ph.max()), 3), at, ms, summary["trip_cause"]))
                done += 1
                eta = (time.perf_counter() - t0) / done * (n - done)
                print(f"\rspeed-step stall cases {done}/{n}, ETA {eta:4.0f} s", end="", file=sys.stderr, flush=True)
        worst.sort(reverse=True)
        out[name] = {"cases": len(worst), "trips": [w for w in worst if w[3] is not None],
                     "i_peak_max": worst[0][0], "i_peak_median": float(np.median([w[0] for w in worst])),
                     "worst": [w[:3] for w in worst[:3]]}  # fmt: skip
    print(file=sys.stderr)
    return {"benchmark": "stall-speed-step", "rig": "mock", "scenario": "fig5.7", "I_trip_phase": lim.I_trip_phase,
            "stalls_ms": list(stalls_ms), "stall_starts_s": [starts[0], starts[-1], 0.0005], "laws": out,
            "wall_s": round(time.perf_counter() - t0, 1)}  # fmt: skip


def draw(path: Path, stall_ms: float, scenario: str = "hold", t_stall: float = 3.0) -> Path:
    """Phase current and speed around one stall at the rated point, both drives (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    fig, (ax_i, ax_w) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for mode, colour in (("hold", "tab:red"), ("ride-through", "tab:blue")):
        opts = RunOptions(scenario=scenario, duration=t_stall + 0.15, realtime=False, log_enabled=False,
                          progress=False, inject_stalls={t_stall: stall_ms * 1e-3})  # fmt: skip
        with _drive_of_before() if mode == "hold" else contextlib.nullcontext():
            summary, _ = run_session(opts)
        rec = summary["record"]
        rig, truth = rec.read("/rig"), rec.read("/truth")
        t = rig["t"]
        sel = t > t_stall - 0.02
        label = f"{mode}: {(summary['trip_cause'] or 'no trip').split(';')[0]}"
        i_ph = np.max(np.abs(np.stack([rig["i_a"], rig["i_b"], rig["i_c"]])), axis=0)
        ax_i.plot((t[sel] - t_stall) * 1e3, i_ph[sel], ".", ms=2, color=colour, label=label)
        ax_w.plot((t[sel] - t_stall) * 1e3, truth["omega_r"][sel], ".", ms=2, color=colour)

    ax_i.axhline(load("mock").limits.I_trip_phase, color="k", lw=0.6, ls="--")  # the PC's phase trip
    for ax in (ax_i, ax_w):
        ax.axvspan(0, stall_ms, color="0.9")
    ax_i.set_ylabel("largest |phase current|\n(PC samples, LEM clips at 20 A) [A]", fontsize=8)
    ax_w.set_ylabel("ω_r (true) [rad/s]")
    ax_w.set_xlabel(f"time after the stall's start [ms] (grey: {stall_ms:g} ms without a tick)")
    ax_i.legend(loc="center right", fontsize=7)
    ax_i.set_title(f"A {stall_ms:g} ms loop stall at the rated point (297 rad/s, 10 N m)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
