"""Per-tick cost of the current controllers (JSON): ``python -m bench.perf.current [repeats]``.

CPU time per call (timeit, best of `repeats` runs of 20000 calls, one process) of

- the LPV law alone (`LPVCurrentLaw.step`: scheduling (5.36), the 2 x 2 inversion of 5.4.4, state update),
- the FOC part (`LPVCurrentController.update`, with δ floor/clipping and the voltage limit) and the PI
  (`CurrentPI.update`, (4.13)(4.14)) for comparison,
- one whole `FocController.step` (encoder, current-model observer, speed PI, current loop, rotation) per
  base tick, for pi, lpv at 600 Hz (divisor 5: the law runs every 5th tick) and lpv at 3 kHz, replaying
  the measurements of a 1 s lockstep run of the demo scenario (mean, p50, p99, max of single calls).

Lockstep CPU time, not the real-time loop: ``bench perf loop -p current_controller=lpv ...`` measures that.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import timeit

import numpy as np

from bench.controllers.base import ControllerContext
from bench.controllers.foc import CurrentPI, FocController
from bench.controllers.lpv_current import LPVCurrentController, LPVCurrentLaw, artifact_path
from bench.hal import Measurement
from bench.params import T_S_DEFAULT, MotorParams
from bench.core.scenarios import get
from bench.workflows.reproductions.common import simulate

N = 20000


def _best_us(fn, repeats: int) -> float:  # noqa: ANN001
    return 1e6 * min(timeit.repeat(fn, number=N, repeat=repeats)) / N


def _ctx() -> ControllerContext:
    return ControllerContext(T_s=T_S_DEFAULT, motor=MotorParams(), I_max=10.0, counts_per_rev=4096,
                             enc_modulus=2**16)  # fmt: skip


def _recorded_ticks(duration: float = 1.0) -> list[tuple[Measurement, float, float]]:
    """(measurement, ω_ref, i_mR_ref) of every tick of a lockstep demo run with the default FOC."""
    rec: list[tuple[Measurement, float, float]] = []

    class Recorder(FocController):
        def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
            rec.append((meas, omega_ref, i_mR_ref))
            return super().step(meas, omega_ref, i_mR_ref)

    simulate(get("demo"), make=lambda ctx: Recorder(ctx), duration=duration)
    return rec


def foc_tick_us(trace: list[tuple[Measurement, float, float]], params: dict, repeats: int) -> dict:
    """Single `FocController.step` calls with ``params`` replaying ``trace``: mean, p50, p99, max [us] of the best
    (lowest-mean) of ``repeats`` replays."""
    best: dict | None = None
    for _ in range(repeats):
        foc = FocController(_ctx(), **params)
        ns = []
        for meas, w_ref, i_ref in trace:
            t0 = time.perf_counter_ns()
            foc.step(meas, w_ref, i_ref)
            ns.append(time.perf_counter_ns() - t0)
        a = np.array(ns) / 1e3
        r = dict(mean=float(a.mean()), p50=float(np.percentile(a, 50)), p99=float(np.percentile(a, 99)),
                 max=float(a.max()))  # fmt: skip
        if best is None or r["mean"] < best["mean"]:
            best = r
    assert best is not None
    return best


def run(repeats: int = 5) -> dict:
    m = MotorParams()
    out: dict = {"benchmark": "current controller per-call CPU time [us]", "calls": N, "repeats": repeats}
    for rate in (600.0, 3000.0):
        law = LPVCurrentLaw(artifact_path(rate))
        out[f"lpv_law_step_{rate:g}Hz_us"] = _best_us(lambda law=law: law.step(0.3 - 0.1j, 0.4, -0.2), repeats)
        c = LPVCurrentController(artifact_path(rate), m)
        out[f"lpv_update_{rate:g}Hz_us"] = _best_us(lambda c=c: c.update(2 + 3j, 2.1 + 2.9j, 150.0, 2.0, 300.0), repeats)
        out[f"lpv_n_c_{rate:g}Hz"] = law.n_c
    pi = CurrentPI(m.Ls_p * 1000.0, m.Ls_p / m.R_s, T_S_DEFAULT, m.Ls_p, m.Lm_p, m.Rr_p)
    out["pi_update_us"] = _best_us(lambda: pi.update(2 + 3j, 2.1 + 2.9j, 150.0, 2.0, 300.0), repeats)
    trace = _recorded_ticks()
    for name, params in (("pi", {}), ("lpv_600Hz", {"current_controller": "lpv", "lpv_current_rate": 600.0}),
                         ("lpv_3000Hz", {"current_controller": "lpv", "lpv_current_rate": 3000.0})):  # fmt: skip
        out[f"foc_step_{name}_us"] = foc_tick_us(trace, params, repeats)
    out["env"] = dict(python=platform.python_version(), cpus=os.cpu_count(), machine=platform.machine(),
                      note="shared 2-core VM; lockstep CPU time")  # fmt: skip
    return out


if __name__ == "__main__":
    print(json.dumps(run(int(sys.argv[1]) if len(sys.argv) > 1 else 5), indent=2))
