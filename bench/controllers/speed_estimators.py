"""Speed estimators for sensorless control (thesis Sec. 4.4), selected by name from `SPEED_ESTIMATORS`.

A speed estimator runs once per base tick *after* the flux observer:
``update(i_s, u_s, i_m_hat) -> omega_hat`` with the present stator current, the voltage held over
the last period and the flux observer's present i_m estimate. It exposes

* ``omega_hat`` - the estimate to feed back into the flux observer's rotation term (next tick);
* ``omega_r``  - the same, low-pass filtered with ``tau`` for the speed controller.

=================  ==========================================================================
``rotor_equation``  (4.19): omega_r = omega_mR - (R_r/L_r) i_sq/i_mR from the flux estimate,
                    low-pass filtered (the thesis filters all three variants of Fig. 4.8)
``kubota``          the speed of Kubota's adaptive observer (4.20)(4.21); when the flux observer
                    is itself ``kubota`` the two share one observer instance
=================  ==========================================================================
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

from bench.controllers.observers import FluxObserver, KubotaObserver
from bench.controllers.schema import Param, defaults_of
from bench.params import MotorParams


class SpeedEstimator(ABC):
    name: ClassVar[str]
    summary: ClassVar[str] = ""
    schema: ClassVar[dict[str, Param]] = {}  # bench.controllers.schema; the FOC exposes <name>_<parameter>
    defaults: ClassVar[dict[str, Any]] = {}  # derived from `schema`

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        cls.defaults = defaults_of(cls.schema)

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        unknown = set(params) - set(self.defaults)
        if unknown:
            raise ValueError(f"{self.name}: unknown parameter(s) {sorted(unknown)}")
        self.motor, self.T_s = motor, T_s
        self.p = {**self.defaults, **params}
        tau = float(self.p.get("tau", 0.0))
        self._alpha = 1.0 - math.exp(-T_s / tau) if tau > 0 else 1.0

    def reset(self) -> None:
        self.omega_hat = 0.0
        self.omega_r = 0.0

    def set_R_r(self, R_r: float) -> None:
        """Use this rotor resistance [Ohm] from the next update on (`bench.controllers.rr_adapt`)."""

    def rotate(self, e: complex) -> None:
        """Turn the stator-fixed states by ``e`` after a stall the drive rode through (`FluxObserver.rotate`)."""

    def _filter(self, w: float) -> float:
        self.omega_r += self._alpha * (w - self.omega_r)
        return self.omega_r

    @abstractmethod
    def update(self, i_s: complex, u_s: complex, i_m_hat: complex) -> float:
        """Return the filtered speed estimate omega_r [rad/s, electrical]."""


class RotorEquationSpeed(SpeedEstimator):
    """Speed from the rotor equation in flux coordinates (4.19): omega_r = omega_mR - (R_r/L_r) i_sq/i_mR.

    omega_mR is the flux angle's increment per sample, angle(i_m,k conj(i_m,k-1))/T_s. The raw value
    is noisy (a differentiated angle), so the estimate is low-pass filtered with ``tau`` and the
    filtered value is also what goes back into the flux observer (``omega_hat``).
    The estimate is only as good as the flux: with a current-model flux it returns whatever speed
    the flux was computed with (thesis after (4.19)). ``i_mR_min`` [A] freezes it below that flux.
    """

    name = "rotor_equation"
    summary = "rotor equation (4.19) on the flux estimate, low-pass filtered"
    schema: ClassVar[dict[str, Param]] = {
        "tau": Param(0.01, "low-pass of the estimate", "s", ge=0, le=10),
        "i_mR_min": Param(0.2, "below this |i_mR| estimate the division in (4.19) is not made", "A", gt=0, le=10),
    }

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        self._inv_Tr = motor.R_r / motor.L_r
        self._inv_T = 1.0 / T_s
        self._min = float(self.p["i_mR_min"])
        self.reset()

    def set_R_r(self, R_r: float) -> None:
        self._inv_Tr = R_r / self.motor.L_r  # the slip term of (4.19)

    def reset(self) -> None:
        super().reset()
        self._prev = 0j
        self.omega_raw = 0.0

    def rotate(self, e: complex) -> None:
        self._prev *= e

    def update(self, i_s: complex, u_s: complex, i_m_hat: complex) -> float:
        prev, self._prev = self._prev, i_m_hat
        ok, raw = rotor_equation_speed(prev, i_s, i_m_hat, self._min, self._inv_T, self._inv_Tr)
        if not ok:
            return self.omega_r
        self.omega_raw = raw
        self.omega_hat = self._filter(raw)
        return self.omega_r


def rotor_equation_speed(prev: complex, i_s: complex, i_m_hat: complex, i_mR_min: float, inv_T: float,
                         inv_Tr: float) -> tuple[bool, float]:  # fmt: skip
    """(4.19) from the flux estimate now (i_m_hat) and one sample before (prev): (made, omega_r unfiltered). Not
    made where |i_m_hat| < i_mR_min or there is no previous estimate. Plain Python that numba compiles
    (`bench.controllers.observers_compiled` calls this one)."""
    i_mR = abs(i_m_hat)
    if i_mR < i_mR_min or prev == 0j:
        return False, 0.0
    d = i_m_hat * prev.conjugate()
    omega_mR = math.atan2(d.imag, d.real) * inv_T
    i_sq = (i_s * i_m_hat.conjugate()).imag / i_mR  # Im{i_s e^{-j rho}}
    return True, omega_mR - inv_Tr * i_sq / i_mR  # (4.19)


class KubotaSpeed(SpeedEstimator):
    """The speed estimate of Kubota's observer (4.21), optionally low-pass filtered (``tau``).

    Owns a `KubotaObserver` built from ``observer_params``, or uses ``shared`` (the flux observer
    of the same controller) without stepping it a second time.
    """

    name = "kubota"
    summary = "speed of Kubota's adaptive observer (4.20)(4.21)"
    schema: ClassVar[dict[str, Param]] = {"tau": Param(0.0, "low-pass of the estimate", "s", ge=0, le=10)}

    def __init__(self, motor: MotorParams, T_s: float, *, shared: FluxObserver | None = None,
                 observer_params: dict[str, Any] | None = None, **params: Any) -> None:  # fmt: skip
        super().__init__(motor, T_s, **params)
        if shared is not None and not isinstance(shared, KubotaObserver):
            raise ValueError("kubota speed estimator: shared observer must be a KubotaObserver")
        self.shared = shared is not None
        self.obs = shared if shared is not None else KubotaObserver(motor, T_s, **(observer_params or {}))
        self.reset()

    def set_R_r(self, R_r: float) -> None:
        if not self.shared:  # a shared observer is the FOC's flux observer: it gets the estimate itself
            self.obs.set_R_r(R_r)

    def reset(self) -> None:
        super().reset()
        if not self.shared:
            self.obs.reset()
        self.omega_r = self.omega_hat = self.obs.omega_hat

    def rotate(self, e: complex) -> None:
        if not self.shared:  # a shared observer is the FOC's flux observer: turned as such
            self.obs.rotate(e)

    def update(self, i_s: complex, u_s: complex, i_m_hat: complex) -> float:
        if not self.shared:
            self.obs.update(i_s, u_s, 0.0)
        self.omega_hat = self.obs.omega_hat
        return self._filter(self.omega_hat)


SPEED_ESTIMATORS: dict[str, type[SpeedEstimator]] = {cls.name: cls for cls in (RotorEquationSpeed, KubotaSpeed)}
