"""Thermal state of the mock motor: winding temperatures from the copper losses, and R(T) (Sec. 3.4).

Sec. 3.4: "The rotor resistance R_r can change as much as 50 % due to heating ... both R_r and R_s
will be *slowly* varying." This module makes them vary. Two first-order thermal nodes, the stator
and the rotor winding, each with a thermal resistance to ambient and a heat capacity, optionally
coupled through the air gap (conductance G_sr)::

    C_s dT_s/dt = P_s - (T_s - T_amb)/R_th_s - G_sr (T_s - T_r)
    C_r dT_r/dt = P_r - (T_r - T_amb)/R_th_r - G_sr (T_r - T_s)
    C_x = tau_x / R_th_x

P_s = 3/2 R_s |i_s|^2 and P_r = 3/2 R_r |i_rs|^2 are the copper losses (amplitude-invariant space
vectors, 3.17); iron and friction losses are not modelled. tau_x is the node's own time constant
(exactly the time constant when G_sr = 0); a constant loss P raises an uncoupled node by P R_th at
steady state. The resistances follow the temperatures linearly from their 20 degC values (3.57 was
identified at 20 degC)::

    R_s(T_s) = R_s20 (1 + alpha_Cu (T_s - 20 degC)),   alpha_Cu = 0.00393 1/K (copper stator winding)
    R_r(T_r) = R_r20 (1 + alpha_Al (T_r - 20 degC)),   alpha_Al = 0.00403 1/K (die-cast aluminium cage)

so R_r is +50 % at T_r = 144 degC, the hot rotor of Sec. 3.4.

``time_scale`` k compresses time: both derivatives are multiplied by k (the capacities divided by
k), so every thermal time constant is tau/k while the steady-state rises stay P R_th. With the
defaults (tau_r = 900 s) and k = 100 the rotor's time constant is 9 s, and a test sees R_r
+40 % within tens of simulated seconds instead of half an hour (rigs/mock-warm.toml).

The network is linear, so it is stepped exactly for losses held over a step (zero-order hold,
matrix exponential of the 2x2 system, computed once per step size).

Default values (assumptions for a 1.5 kW TEFC cage motor; the thesis gives none): R_th_s = 0.35 K/W
(the rated 211 W stator copper loss, thesis 3.7's nameplate point, gives a 74 K rise), tau_s =
1200 s (C_s = 3.4 kJ/K, about 9 kg of copper and iron), R_th_r = 0.8 K/W (the rated 100 W rotor
loss gives 80 K), tau_r = 900 s, G_sr = 0 (no coupling), T_amb = 20 degC: a motor that starts at
ambient has the cold resistances of (3.57).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

ALPHA_CU = 0.00393  # temperature coefficient of copper at 20 degC [1/K]
ALPHA_AL = 0.00403  # temperature coefficient of aluminium at 20 degC [1/K]
T_REF = 20.0  # temperature of the (3.57) resistances [degC]


def resistance(R_20: float, alpha: float, T: float) -> float:
    """R(T) = R_20 (1 + alpha (T - 20 degC)) [Ohm]."""
    return R_20 * (1.0 + alpha * (T - T_REF))


class ThermalModel:
    """Stator and rotor winding temperatures [degC] and the resistances they give [Ohm]."""

    def __init__(
        self,
        R_s20: float,
        R_r20: float,
        *,
        T_amb: float = 20.0,
        R_th_s: float = 0.35,
        tau_s: float = 1200.0,
        R_th_r: float = 0.8,
        tau_r: float = 900.0,
        G_sr: float = 0.0,
        time_scale: float = 1.0,
        rise_s0: float = 0.0,
        rise_r0: float = 0.0,
    ) -> None:
        if not (R_s20 > 0 and R_r20 > 0 and R_th_s > 0 and R_th_r > 0 and tau_s > 0 and tau_r > 0):
            raise ValueError("resistances, thermal resistances and time constants must be > 0")
        if not (G_sr >= 0 and time_scale > 0 and math.isfinite(T_amb)):
            raise ValueError("G_sr must be >= 0, time_scale > 0 and T_amb finite")
        self.R_s20, self.R_r20 = float(R_s20), float(R_r20)
        self.T_amb = float(T_amb)
        self.R_th_s, self.R_th_r = float(R_th_s), float(R_th_r)
        self.C_s, self.C_r = tau_s / R_th_s, tau_r / R_th_r  # heat capacities [J/K]
        self.G_sr = float(G_sr)
        self.time_scale = float(time_scale)
        self.rise0 = (float(rise_s0), float(rise_r0))
        k = self.time_scale
        g = self.G_sr
        # d x/dt = A x + B P, x = T - T_amb (per node), P = (P_s, P_r)
        self.A = k * np.array([[-(1.0 / R_th_s + g) / self.C_s, g / self.C_s],
                               [g / self.C_r, -(1.0 / R_th_r + g) / self.C_r]])  # fmt: skip
        self.B = k * np.diag([1.0 / self.C_s, 1.0 / self.C_r])
        self._h = -1.0
        self.reset()

    def reset(self) -> None:
        """Temperatures back to their initial values (ambient + rise_s0, rise_r0)."""
        self.T_s = self.T_amb + self.rise0[0]
        self.T_r = self.T_amb + self.rise0[1]
        self._update_r()

    def _update_r(self) -> None:
        self.R_s = resistance(self.R_s20, ALPHA_CU, self.T_s)
        self.R_r = resistance(self.R_r20, ALPHA_AL, self.T_r)

    def steady_state(self, P_s: float, P_r: float) -> tuple[float, float]:
        """Temperatures [degC] that constant losses P_s, P_r [W] settle at (A x + B P = 0)."""
        x = np.linalg.solve(self.A, -self.B @ np.array([P_s, P_r]))
        return self.T_amb + float(x[0]), self.T_amb + float(x[1])

    def _coefficients(self, h: float) -> None:
        # x(t + h) = Phi x(t) + Gamma P for P held over [t, t + h]
        self._h = h
        # e^{Ah} by scaling and squaring around scipy's expm: scipy < 1.12's closed form for 2x2 overflows in
        # cosh and returns NaN once h |lambda| exceeds about 700 (a long step, or a compressed time scale);
        # for ||A h|| <= 1 (every per-tick step) this is expm itself
        k = max(0, math.ceil(math.log2(max(float(np.abs(self.A * h).sum(axis=0).max()), 1e-300))))
        phi = expm(self.A * (h / 2.0**k))
        for _ in range(k):
            phi = phi @ phi
        gam = np.linalg.solve(self.A, (phi - np.eye(2)) @ self.B)  # int_0^h e^{A t} dt B
        (self._p00, self._p01), (self._p10, self._p11) = phi.tolist()
        (self._g00, self._g01), (self._g10, self._g11) = gam.tolist()

    def advance(self, P_s: float, P_r: float, h: float) -> None:
        """Advance by h [s] with the losses [W] held over the step (exact for the linear network)."""
        if h != self._h:
            self._coefficients(h)
        self.T_s, self.T_r = thermal_step(self.T_amb, self.T_s, self.T_r, self._p00, self._p01, self._p10,
                                          self._p11, self._g00, self._g01, self._g10, self._g11, P_s, P_r)  # fmt: skip
        self._update_r()


def copper_loss(R: float, i_re: float, i_im: float) -> float:
    """(3/2) R |i|^2 [W] of a winding with resistance R [Ohm] and current space vector i [A] (3.17), |i|^2 as a
    product (plain Python that numba compiles: both engines call it)."""
    return 1.5 * R * (i_re * i_re + i_im * i_im)


# The network's step, plain Python that numba compiles: the compiled plant (mock_hw.compiled) calls the same one.
def thermal_step(T_amb: float, T_s: float, T_r: float, p00: float, p01: float, p10: float, p11: float, g00: float,
                 g01: float, g10: float, g11: float, P_s: float, P_r: float) -> tuple[float, float]:  # fmt: skip
    """(T_s, T_r) [degC] after one step: x(t + h) = Phi x(t) + Gamma P with x = T - T_amb, Phi = [[p00, p01],
    [p10, p11]] and Gamma = [[g00, g01], [g10, g11]] (`ThermalModel._coefficients`), the losses P [W] held."""
    xs, xr = T_s - T_amb, T_r - T_amb
    return (T_amb + (p00 * xs + p01 * xr + g00 * P_s + g01 * P_r),
            T_amb + (p10 * xs + p11 * xr + g10 * P_s + g11 * P_r))  # fmt: skip
