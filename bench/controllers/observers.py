"""Flux observers (thesis Sec. 4.3).

A flux observer estimates the magnetising current i_m (rotor flux / L_m, (3.40)) in stator-fixed
coordinates from the stator current, the stator voltage and the speed. Observers are swappable
inside the rotor-flux-oriented controller and selected by name from `OBSERVERS`.
"""

from __future__ import annotations

import cmath
from abc import ABC, abstractmethod
from typing import Any, ClassVar

from bench.params import MotorParams


class FluxObserver(ABC):
    """i_m estimator: ``update(i_s, u_s, omega_r) -> i_m_hat`` once per base tick."""

    name: ClassVar[str]
    defaults: ClassVar[dict[str, Any]] = {}

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        self.motor = motor
        self.T_s = T_s
        self.p = {**self.defaults, **params}

    @abstractmethod
    def reset(self) -> None: ...

    @abstractmethod
    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        """Advance to the current sample; return i_m_hat [A], stator-fixed."""


class CurrentModelObserver(FluxObserver):
    """Current model (4.15): d/dt i_m = (-R_r/L_r + j omega_r) i_m + (R_r/L_r) i_s.

    Discretised exactly for omega_r constant over a period, with i_s interpolated linearly between
    the previous and the present sample (first-order hold), so the estimate belongs to the
    present sample instant. Needs accurate R_r and omega_r (thesis' remark after (4.15)).
    """

    name = "current_model"

    def reset(self) -> None:
        self.i_m = 0j
        self._i_s_prev: complex | None = None

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        self._b = motor.R_r / motor.L_r
        self.reset()

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        a = complex(-self._b, omega_r)
        phi = cmath.exp(a * self.T_s)
        self.i_m = phi * self.i_m + (phi - 1.0) / a * self._b * 0.5 * (prev + i_s)
        return self.i_m


OBSERVERS: dict[str, type[FluxObserver]] = {
    CurrentModelObserver.name: CurrentModelObserver,
}
