"""Referred motor quantities of thesis Sec. 4.1 (rotor-flux-oriented model), in one place.

A mixin for any record with the fields L_s, L_r, L_m, R_r: the bench's `bench.params.MotorParams`
and the synthesis models' `synthesis.models.motor.MotorData` both derive these from it. It lives in
`synthesis` because the synthesis library must not import the bench (the bench may import it).
"""

from __future__ import annotations


class ReferredQuantities:
    """sigma, L'_s, L'_m, R'_r, T_r from L_s, L_r, L_m, R_r (4.1)-(4.4)."""

    __slots__ = ()
    L_s: float
    L_r: float
    L_m: float
    R_r: float

    @property
    def sigma(self) -> float:
        """Leakage factor sigma = 1 - L_m^2/(L_r L_s)."""
        return 1.0 - self.L_m**2 / (self.L_r * self.L_s)

    @property
    def Ls_p(self) -> float:
        """Transient inductance L'_s = sigma L_s."""
        return self.sigma * self.L_s

    @property
    def Lm_p(self) -> float:
        """L'_m = L_m^2 / L_r."""
        return self.L_m**2 / self.L_r

    @property
    def Rr_p(self) -> float:
        """R'_r = (L_m/L_r)^2 R_r."""
        return (self.L_m / self.L_r) ** 2 * self.R_r

    @property
    def T_r(self) -> float:
        """Rotor time constant T_r = L_r/R_r (4.4)."""
        return self.L_r / self.R_r
