"""Induction-motor parameters and the quantities derived from them (thesis 3.7, 4.1).

One `MotorParams` describes the machine in the thesis' nomenclature. The mock plant uses it as
the *true* machine; controllers use their own (possibly mismatched) copy as the *nominal* model.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

from synthesis.models.referred import ReferredQuantities

T_S_DEFAULT = 1.0 / 3000.0  # lab PC sample period [s] (App. A.7)


@dataclass(frozen=True, slots=True)
class MotorParams(ReferredQuantities):
    """Electrical data (3.57) plus mechanical assumptions.

    The thesis gives no inertia or friction data (App. A). The defaults below are *assumptions*
    for a 1.5 kW, 4-pole machine coupled to a similar-size PM DC load motor:
    J = 0.0125 kg m^2 (about 0.004 motor rotor + 0.008 load rotor + coupling),
    viscous friction 1e-3 N m s/rad and Coulomb friction 0.05 N m, both on the mechanical shaft.
    """

    L_s: float = 0.352  # stator inductance [H]
    L_r: float = 0.352  # rotor inductance [H]
    L_m: float = 0.341  # mutual inductance [H]
    R_s: float = 5.0  # stator resistance [Ohm]
    R_r: float = 3.3  # rotor resistance [Ohm] (20 degC; may rise 50 % hot, Sec. 3.4)
    Z_p: int = 2  # pole pairs
    J: float = 0.0125  # total inertia [kg m^2] (assumed)
    B_visc: float = 1.0e-3  # viscous friction [N m s/rad], mechanical speed (assumed)
    m_coulomb: float = 0.05  # Coulomb friction [N m] (assumed)

    # derived quantities of thesis 4.1 (sigma, Ls_p, Lm_p, Rr_p, T_r): `ReferredQuantities`
    @property
    def torque_constant(self) -> float:
        """k in m_e = k * i_mR * i_sq, i.e. 3/2 Z_p L'_m (4.6)."""
        return 1.5 * self.Z_p * self.Lm_p

    def with_(self, **changes: float) -> "MotorParams":
        """A copy with some fields changed (e.g. a hot rotor: R_r=1.5*3.3)."""
        return replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    # physical ranges (both ends inclusive) of a machine this bench can drive: a 1e308 typo is caught,
    # and so is a 5e-324 (a denormal: zero to every equation, a division by it overflows). The lower
    # ends are far below any 1.5 kW-class machine: 0.1 mH, 1 mOhm, 1e-6 kg m^2 (a bare small rotor).
    RANGES = {"L_s": (1e-4, 10.0), "L_r": (1e-4, 10.0), "L_m": (1e-4, 10.0), "R_s": (1e-3, 1000.0),
              "R_r": (1e-3, 1000.0), "J": (1e-6, 100.0)}  # fmt: skip

    def validate(self) -> None:
        """Raise ValueError naming the first physically impossible field."""
        for name, (lo, hi) in self.RANGES.items():
            v = getattr(self, name)
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"motor.{name} must be in [{lo:g}, {hi:g}], got {v!r}")
        if self.L_m**2 >= self.L_s * self.L_r:
            raise ValueError("motor.L_m must satisfy L_m^2 < L_s*L_r (positive leakage)")
        if int(self.Z_p) != self.Z_p or self.Z_p < 1:
            raise ValueError(f"motor.Z_p must be a positive integer, got {self.Z_p!r}")
        if not (0 <= self.B_visc <= 100 and 0 <= self.m_coulomb <= 1000):
            raise ValueError("motor.B_visc and motor.m_coulomb must be in [0, 100] N m s/rad and [0, 1000] N m")
