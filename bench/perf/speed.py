"""Per-tick cost of the speed controllers (JSON): ``bench perf speed [--repeats N]``.

CPU time per call (timeit, best of `repeats` runs of 20000 calls, one process) of

- the LPV law alone (`bench.controllers.lpv_law.ScheduledLaw.step`: (5.36) for two residual gains, 5.4.4),
- the speed part (`LPVSpeedController.update`: scaling, the scheduling delta_j of (6.28) from the histories, the
  law, i_tau -> i_sq,ref and the limit), with 0 and 2 scheduling iterations, and the PI (`SpeedPI.update`),
- one whole `FocController.step` per base tick with the PI, the LPV speed controller at 600 Hz (divisor 5) and
  the 3 kHz design (every tick), replaying the measurements of a 1 s lockstep demo run (mean, p50, p99, max).

Lockstep CPU time on whatever machine runs it; ``bench perf loop -p speed_controller=lpv`` measures the
real-time loop.
"""

from __future__ import annotations

import os
import platform

from bench.controllers.foc import SpeedPI
from bench.controllers.lpv_law import ScheduledLaw
from bench.controllers.lpv_speed import LPVSpeedController, artifact_path
from bench.params import T_S_DEFAULT, MotorParams
from bench.perf.current import N, _best_us, _recorded_ticks, foc_tick_us
from bench.core.progress import stages
from synthesis.artifacts import load_controller


def run(repeats: int = 5) -> dict:
    say = stages("perf speed")
    m = MotorParams()
    out: dict = {"benchmark": "speed controller per-call CPU time [us]", "calls": N, "repeats": repeats}
    for name in ("nominal", "robust", "nominal_3000Hz"):
        say(f"LPV law and update, {name} ({repeats} repeats of {N} calls)")
        ctrl, _ = load_controller(artifact_path(name))
        law = ScheduledLaw(ctrl)
        out[f"lpv_law_step_{name}_us"] = _best_us(lambda law=law: law.step((0.01,), (0.3, -0.2)), repeats)
        out[f"lpv_n_c_{name}"] = law.n_c
        for it in (0, 2):
            c = LPVSpeedController(artifact_path(name), m, 10.0, iterations=it)
            c.update(0.0, 0.0, 2.0, 2.0)
            out[f"lpv_update_{name}_iter{it}_us"] = _best_us(lambda c=c: c.update(100.0, 99.0, 2.0, 2.0), repeats)
    pi = SpeedPI(1.886, 0.01288, m.torque_constant, 10.0, T_S_DEFAULT)
    out["pi_update_us"] = _best_us(lambda: pi.update(100.0, 99.0, 2.0, 2.0), repeats)
    say("FOC ticks with the PI and the LPV speed controllers (recorded trace)")
    trace = _recorded_ticks()
    for name, params in (("pi", {}), ("lpv_600Hz", {"speed_controller": "lpv"}),
                         ("lpv_3000Hz", {"speed_controller": "lpv", "lpv_speed_artifact": "nominal_3000Hz"})):  # fmt: skip
        out[f"foc_step_{name}_us"] = foc_tick_us(trace, params, repeats)
    out["env"] = dict(python=platform.python_version(), cpus=os.cpu_count(), machine=platform.machine(),
                      load_avg=os.getloadavg(), note="shared 2-core VM; lockstep CPU time")  # fmt: skip
    return out
