"""Per-tick cost of the mock rig: ``rig.read(t)`` + ``rig.write(cmd)``, printed as JSON.

    python -m bench.perf.plant [--ticks N] [--substeps S] [--engine auto|compiled|python]

Drives the motor open loop with a V/f ramp (a rotating voltage, so every code path is live:
RK4, filter, sensors with noise, encoder with index) and reports the mean and p99 per tick; and one RK4 step of the
Python engine's motor beside the yardstick (../shared/yardstick.py) measured in the same run.
"""

from __future__ import annotations

import argparse
import cmath
import json
import math
import time
from typing import Any

from bench.hal import Command
from bench.params import T_S_DEFAULT, MotorParams
from bench.perf.live import yardstick_us
from mock_hw.motor import InductionMotor
from mock_hw.plant import MockConfig, make_mock_rig


def measure(ticks: int = 30000, substeps: int = 1, repeats: int = 3, engine: str = "auto") -> dict[str, Any]:
    """Best-of-``repeats`` mean and p99 cost of read+write per tick [us]."""
    best_mean, best_p99 = math.inf, math.inf
    dt = T_S_DEFAULT
    for _ in range(repeats):
        rig = make_mock_rig(MockConfig(substeps=substeps, engine=engine), dt=dt, seed=1)
        rig.configure()
        rig.activate()
        cmd = Command(enable=True, m_L_ref=1.0)
        per = []
        pc = time.perf_counter
        for k in range(1, ticks + 1):
            t = k * dt
            f = min(50.0, 50.0 * t / 0.5)  # V/f ramp to 50 Hz in 0.5 s
            cmd.u_s_ref = (20.0 + 6.0 * f) * cmath.exp(1j * math.pi * f * t)
            t0 = pc()
            rig.read(t)
            rig.write(cmd)
            per.append(pc() - t0)
        rig.deactivate()
        per.sort()
        mean = sum(per) / len(per) * 1e6
        best_mean = min(best_mean, mean)
        best_p99 = min(best_p99, per[int(0.99 * len(per))] * 1e6)
    yard = yardstick_us()
    rk4 = motor_rk4_us()
    return {"plant_tick_us": round(best_mean, 2), "plant_tick_p99_us": round(best_p99, 2),
            "substeps": substeps, "ticks": ticks, "engine": rig.truth.engine, "motor_rk4_python_us": round(rk4, 3),
            "yardstick_us": yard, "motor_rk4_python_yardsticks": round(rk4 / yard, 3) if yard else None}  # fmt: skip


def motor_rk4_us(n: int = 20000, repeats: int = 5) -> float:
    """One RK4 step of the linear motor's Python engine (`InductionMotor._rk4`, the shared kernel
    `mock_hw.motor.rk4` called from Python) [us], best of ``repeats`` loops of ``n``."""
    m = InductionMotor(MotorParams())
    m.reset(i_s=3 + 1j, i_m=2 + 0.5j, omega_r=100.0)
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            m._rk4(100 + 20j, 2.0, T_S_DEFAULT)
        best = min(best, (time.perf_counter() - t0) / n * 1e6)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=30000)
    ap.add_argument("--substeps", type=int, default=1)
    ap.add_argument("--engine", choices=("auto", "compiled", "python"), default="auto")
    a = ap.parse_args()
    print(json.dumps(measure(a.ticks, a.substeps, engine=a.engine)))


if __name__ == "__main__":
    main()
