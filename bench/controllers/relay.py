"""Relay-feedback experiment on the speed loop (thesis Sec. 4.2: "a PI-controller tuned by a relay
feedback experiment"; Åström-Hägglund relay method).

`RelayTuneController` is the rotor-flux-oriented controller of `bench.controllers.foc` with its speed
PI replaced by a relay with hysteresis: the torque reference is +d while the speed error is above
+eps and -d while it is below -eps. Flux and current loops stay in operation, as the thesis requires
("the tuning must be performed with the intended stator current controller in operation"), and the
speed feedback is the same filtered encoder speed the PI will see. The loop then oscillates around
the speed reference; `bench.workflows.tuning.relay_analysis` turns the oscillation into the ultimate gain and
period and the Ziegler-Nichols PI.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from bench.controllers.base import ControllerContext
from bench.controllers.foc import I_MR_FLOOR, SWITCHABLE, FocController
from bench.controllers.schema import Param
from bench.errors import BadInput


class RelaySpeed:
    """Relay with hysteresis in place of `SpeedPI`: same ``update`` signature, returns i_sq_ref (4.7)."""

    def __init__(self, d: float, eps: float, k_torque: float, I_max: float) -> None:
        self.d, self.eps, self.k, self.I_max = d, eps, k_torque, I_max
        self.reset()

    def reset(self) -> None:
        self.sign = 1.0
        self.m_e_ref = 0.0

    def take_over(self, i_sq: float, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> None:
        """The relay's one state, its side, from the torque it takes over (a relay has no bumpless start)."""
        self.sign = 1.0 if i_sq >= 0.0 else -1.0

    def update(self, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> float:
        e = omega_ref - omega
        if e > self.eps:
            self.sign = 1.0
        elif e < -self.eps:
            self.sign = -1.0
        i_mR = max(i_mR, I_MR_FLOOR)
        m_max = self.k * i_mR * max(self.I_max**2 - i_sd_ref**2, 0.0) ** 0.5  # (4.8)
        self.m_e_ref = self.sign * min(self.d, m_max)
        return self.m_e_ref / (self.k * i_mR)  # (4.7)


class RelayTuneController(FocController):
    name = "relay_tune"
    summary = "FOC with a relay (hysteresis) in place of the speed PI: relay-feedback tuning experiment"
    schema: dict[str, Param] = {
        # the relay runs in Python, and its parts stay as they started (the experiment is one configuration)
        **{k: replace(v, tunable=False) if k in SWITCHABLE else v for k, v in FocController.schema.items()
           if k != "engine"},
        "relay_amplitude": Param(4.0, "torque-reference amplitude d of the relay", "N m", gt=0, le=100),
        "relay_hysteresis": Param(0.5, "speed-error hysteresis eps of the relay", "rad/s", ge=0, le=100),
    }

    switchable = ()

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        super().__init__(ctx, **params)
        if self.p["speed_source"] != "encoder":
            raise BadInput("controller.relay_tune.speed_source", "the relay experiment runs on the encoder speed")
        self.speed = RelaySpeed(self.p["relay_amplitude"], self.p["relay_hysteresis"], ctx.motor.torque_constant,
                                ctx.I_max)  # fmt: skip
        self.speed.reset()
