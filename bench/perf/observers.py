"""Per-call cost of the flux observers and speed estimators, and of the whole FOC tick with each (JSON).

``bench perf observers`` (CPU time of the calling thread, not real time, so it can run on a busy
machine; the numbers still vary with the machine's load). Two measurements:

* ``per_call``: each observer's ``update`` / estimator's ``update`` called ``n_calls`` times on
  realistic inputs (a rotating current and voltage with sensor-size noise, a speed that varies),
  median over ``repeats`` of the mean time per call. ``call_overhead_ns`` is the same loop calling a
  do-nothing function with the same arguments; the net cost is the difference.
* ``foc_tick``: `FocController.step` with each observer, encoder speed and sensorless (Kubota speed),
  and the current model with the on-line R_r estimate (``rr_adapt = mras``), and the compiled engine with and
  without it, timed call by call inside a lockstep closed-loop run of scenario fig5.7 (p50 / p99 / max; the
  clock's own cost, some 0.1-0.2 us, is in each call: ``rr_adapt_engines`` below times the compiled tick better).
* ``rr_adapt``: the R_r estimate's own cost per tick while it adapts (`RrMRAS.update`, and with it the
  hand-over of the estimate to the FOC's parts), also in yardsticks (one plain-Python RK4 motor step,
  ../shared/yardstick.py).
* ``rr_adapt_engines``: `FocController.step` with and without the R_r estimate, for both engines (python and
  compiled), on the same recorded measurements of a loaded run where the estimate adapts (scenario warmup on
  rigs/mock-warm-fast.toml, from 1.5 s), the four interleaved: mean per tick (median over ``repeats``), in us
  and yardsticks; ``adaptation_*`` is the difference with - without, per engine.

The budget is one 3 kHz tick, 333 us, shared with the rig I/O and the logger (docs/RESULTS.md 1.3).
"""

from __future__ import annotations

import cmath
import math
import platform
import statistics
import time
from typing import Any

import numpy as np

from bench.controllers.base import Controller, ControllerContext
from bench.hal import Measurement
from bench.params import T_S_DEFAULT, MotorParams
from bench.core import scenarios
from bench.perf.live import yardstick_us
from bench.controllers.observers import OBSERVERS, KubotaObserver
from bench.controllers.speed_estimators import SPEED_ESTIMATORS, KubotaSpeed
from bench.controllers.foc import FocController
from bench.controllers.rr_adapt import RrMRAS
from bench.workflows.reproductions.common import simulate
from bench.workflows.reproductions.closed_loop import SENSORLESS

TICK_NS = 1e9 * T_S_DEFAULT


def _inputs(n: int, seed: int) -> list[tuple[complex, complex, float]]:
    """(i_s, u_s, omega_r): 2.5 A flux + 4 A torque current and 120 V at omega_mR ~ 60 rad/s, noisy."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        w = 50.0 + 20.0 * math.sin(k * 1e-3)
        rot = cmath.exp(1j * 60.0 * k * T_S_DEFAULT)
        i_s = (2.5 + 4j) * rot + complex(*rng.normal(0.0, 0.02, 2))
        u_s = (40.0 + 110j) * rot + complex(*rng.normal(0.0, 1.0, 2))
        out.append((i_s, u_s, w))
    return out


def _per_call_ns(fn: Any, args: list[tuple], repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.thread_time_ns()
        for a in args:
            fn(*a)
        runs.append((time.thread_time_ns() - t0) / len(args))
    return statistics.median(runs)


def per_call(n_calls: int = 20000, repeats: int = 5, seed: int = 0) -> dict[str, Any]:
    """Median ns per ``update`` of every registered observer and speed estimator."""

    m, T = MotorParams(), T_S_DEFAULT
    args = _inputs(n_calls, seed)
    out: dict[str, Any] = {"call_overhead_ns": _per_call_ns(lambda a, b, c: None, args, repeats)}
    obs: dict[str, Any] = {name: cls(m, T) for name, cls in OBSERVERS.items()}
    obs["kubota (adapt off)"] = KubotaObserver(m, T, adapt=0.0)
    res: dict[str, Any] = {}
    for name, o in obs.items():
        res[name] = _per_call_ns(o.update, args, repeats)
    out["observers_ns"] = res
    est_args = [(i, u, i * 0.5) for i, u, _ in args]  # (i_s, u_s, i_m_hat)
    ests: dict[str, Any] = {}
    for name, cls in SPEED_ESTIMATORS.items():
        e = KubotaSpeed(m, T) if cls is KubotaSpeed else cls(m, T)
        ests[name] = _per_call_ns(e.update, est_args, repeats)
    out["speed_estimators_ns"] = ests
    return out


def rr_adapt_per_call(n_calls: int = 20000, repeats: int = 5, seed: int = 0) -> dict[str, Any]:
    """Median ns per tick of the R_r estimate while it adapts (gate open every tick: its worst case)."""

    m, T = MotorParams(), T_S_DEFAULT
    args = [(k * T, i, u, w, 60.0, 4.0, 2.5, False) for k, (i, u, w) in enumerate(_inputs(n_calls, seed))]
    rr = RrMRAS(m, T, 3.0, 20.0, 0.8, 1.0)
    foc = FocController(ControllerContext(T, m, 10.0, 4096, 1 << 16), rr_adapt="mras")

    def with_hand_over(*a: Any) -> None:
        if foc.rr.update(*a):
            foc._use_R_r()

    return {"update_ns": _per_call_ns(rr.update, args, repeats),
            "update_and_hand_over_ns": _per_call_ns(with_hand_over, args, repeats)}  # fmt: skip


class _Recorder(Controller):
    """Wraps a controller and keeps each tick's arguments of ``step``."""

    name = "recorder"
    summary = "records the controller's inputs"

    def __init__(self, inner: Controller) -> None:
        self.inner, self.ctx, self.p = inner, inner.ctx, {}
        self.fields = inner.fields
        self.calls: list[tuple[Measurement, float, float]] = []

    def reset(self) -> None:
        self.inner.reset()

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        self.calls.append((meas, omega_ref, i_mR_ref))
        return self.inner.step(meas, omega_ref, i_mR_ref)

    def internals(self) -> tuple[float, ...]:
        return self.inner.internals()


def rr_adapt_engines(duration: float = 3.0, repeats: int = 5, skip: float = 1.5) -> dict[str, Any]:
    """FocController.step per tick, python and compiled, rr_adapt off and mras, on one loaded run's measurements."""

    rec: list[_Recorder] = []

    def make(ctx, rec=rec):  # noqa: ANN001, ANN202
        rec.append(_Recorder(FocController(ctx, rr_adapt="mras")))
        return rec[0]

    simulate(scenarios.get("warmup"), make=make, duration=duration, rig="mock-warm-fast")
    ctx, n0 = rec[0].ctx, int(skip / T_S_DEFAULT)
    # each controller replays the run from its start (the ones with the estimate then repeat it exactly: the same
    # inputs, their own voltage references the recorded ones); timed: from ``skip`` on (the load is on from 1 s)
    start, calls = rec[0].calls[:n0], rec[0].calls[n0:]
    cases = {(eng, rr): FocController(ctx, engine=eng, rr_adapt=rr) for eng in ("python", "compiled")
             for rr in ("off", "mras")}  # fmt: skip
    times: dict[tuple[str, str], list[float]] = {k: [] for k in cases}
    for _ in range(repeats):
        for key, c in cases.items():  # interleaved: a change of the machine's load hits all four alike
            c.reset()
            step = c.step
            for a in start:
                step(*a)
            t0 = time.thread_time_ns()
            for a in calls:
                step(*a)
            times[key].append((time.thread_time_ns() - t0) / len(calls) / 1e3)
    c = cases["compiled", "mras"]
    c.reset()
    for a in start:
        c.step(*a)
    gate_open = 0
    for a in calls:  # (untimed) how often the estimate adapted in the timed stretch
        c.step(*a)
        gate_open += c.rr.gate == 0
    out: dict[str, Any] = {"ticks": len(calls), "gate_open_fraction": gate_open / len(calls)}
    for (eng, rr), v in times.items():
        out[f"{eng}_{rr}_us"] = statistics.median(v)
    for eng in ("python", "compiled"):
        out[f"adaptation_{eng}_us"] = out[f"{eng}_mras_us"] - out[f"{eng}_off_us"]
    return out


class _Timed(Controller):
    """Wraps a controller and records the CPU time of each ``step``."""

    name = "timed"
    summary = "timing wrapper"

    def __init__(self, inner: Controller) -> None:
        self.inner, self.ctx, self.p = inner, inner.ctx, {}
        self.fields = inner.fields
        self.ns: list[int] = []

    def reset(self) -> None:
        self.inner.reset()

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        t0 = time.thread_time_ns()
        u = self.inner.step(meas, omega_ref, i_mR_ref)
        self.ns.append(time.thread_time_ns() - t0)
        return u

    def internals(self) -> tuple[float, ...]:
        return self.inner.internals()


def foc_tick(duration: float = 1.0) -> dict[str, Any]:
    """FocController.step per tick [us] with each observer, encoder and sensorless, on both engines, and the current
    model with the R_r estimate, closed loop (fig5.7)."""

    out: dict[str, Any] = {}
    modes = (("encoder", {}), ("sensorless", SENSORLESS))
    cases = [(f"{name}, {mode}", {"observer": name, **extra}) for mode, extra in modes for name in OBSERVERS]
    cases += [(f"{name}, {mode}, compiled", {"observer": name, "engine": "compiled", **extra}) for mode, extra in modes
              for name in OBSERVERS]  # fmt: skip
    cases += [("current_model, encoder, rr_adapt=mras", {"rr_adapt": "mras"}),
              ("current_model, encoder, compiled, rr_adapt=mras", {"engine": "compiled", "rr_adapt": "mras"})]
    for label, params in cases:
        holder: list[_Timed] = []

        def make(ctx, params=params, holder=holder):  # noqa: ANN001, ANN202
            holder.append(_Timed(FocController(ctx, **params)))
            return holder[0]

        simulate(scenarios.get("fig5.7"), make=make, duration=duration)
        a = np.array(holder[0].ns[int(0.1 / T_S_DEFAULT):], dtype=float) / 1e3  # skip the first 0.1 s
        q = np.percentile(a, [50, 99])
        out[label] = {"p50_us": float(q[0]), "p99_us": float(q[1]), "max_us": float(a.max())}
    return out


def run(n_calls: int = 20000, repeats: int = 5, duration: float = 1.0) -> dict[str, Any]:
    pc = per_call(n_calls, repeats)
    worst = max(max(pc["observers_ns"].values()), max(pc["speed_estimators_ns"].values()))
    ft = foc_tick(duration)

    yard = yardstick_us()
    rr = rr_adapt_per_call(n_calls, repeats)
    eng = rr_adapt_engines(repeats=repeats)
    if yard:
        rr.update({k.replace("_ns", "_yardsticks"): v / 1e3 / yard for k, v in list(rr.items())})
        eng.update({k.replace("_us", "_yardsticks"): v / yard for k, v in list(eng.items()) if k.endswith("_us")})
    return {
        "benchmark": "perf observers",
        "clock": "time.thread_time_ns (CPU time of the calling thread)",
        "tick_budget_us": TICK_NS / 1e3,
        "n_calls": n_calls, "repeats": repeats,
        "per_call": pc,
        "worst_per_call_fraction_of_tick": worst / TICK_NS,
        "foc_tick": ft,
        "worst_foc_tick_p99_fraction_of_tick": max(v["p99_us"] for v in ft.values()) * 1e3 / TICK_NS,
        "rr_adapt": rr, "rr_adapt_engines": eng, "yardstick_us": yard,
        "machine": {"python": platform.python_version(), "cpus": __import__("os").cpu_count()},
    }  # fmt: skip
