"""Open-loop V/f (scalar) control, the example plugin of docs/plugins.md.

The stator frequency follows the speed reference (electrical, rate-limited); the voltage amplitude is
what the nominal motor needs to carry the magnetising current at that frequency,
|u_s| = |R_s + j omega_s L_s| i_mR,ref (the steady state of (3.34) with the rotor current zero), plus a
boost. No current or speed feedback: under load the rotor slips behind the reference.
"""

from __future__ import annotations

import cmath
import math

from bench.controllers.base import Controller, ControllerContext
from bench.controllers.schema import Param
from bench.hal import Measurement


class VfController(Controller):
    name = "vf"
    summary = "open-loop V/f: stator frequency = speed reference, |u_s| from the nominal motor (example plugin)"
    schema = {
        "boost": Param(1.0, "voltage added at every frequency (stator-resistance error, friction)", "V",
                       ge=0.0, le=50.0, tunable=True),
        "ramp": Param(500.0, "rate limit of the stator frequency", "rad/s^2", gt=0.0, le=1e5, tunable=True),
    }
    fields = ("omega_s", "theta", "u_amp")  # logged on /ctrl every tick, in this order

    def __init__(self, ctx: ControllerContext, **params: float) -> None:
        super().__init__(ctx, **params)  # checks params against `schema`; the values are in self.p
        self.reset()

    def reset(self) -> None:
        self.omega_s = 0.0  # stator frequency [rad/s, electrical]
        self.theta = 0.0  # angle of the voltage vector [rad]
        self.u_amp = 0.0  # [V]

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        T_s, m = self.ctx.T_s, self.ctx.motor
        step = self.p["ramp"] * T_s
        self.omega_s += max(-step, min(step, omega_ref - self.omega_s))
        self.theta = (self.theta + self.omega_s * T_s) % (2.0 * math.pi)
        u = self.p["boost"] + abs(complex(m.R_s, self.omega_s * m.L_s)) * i_mR_ref
        self.u_amp = min(u, meas.u_dc / math.sqrt(3.0))  # the inverter's linear range
        return cmath.rect(self.u_amp, self.theta)  # stator-fixed voltage reference [V]

    def internals(self) -> tuple[float, ...]:
        return (self.omega_s, self.theta, self.u_amp)

    def retune(self, name: str) -> None:
        pass  # boost and ramp are read from self.p every tick: nothing to recompute
