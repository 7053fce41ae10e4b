"""Induction-motor model of the mock plant: stator-fixed state space (3.41) plus mechanics (3.37).

State (all Python scalars, for speed): ``i_s`` stator current and ``i_m`` magnetising current
(3.39), both complex stator-fixed space vectors (3.17) [A]; ``omega_r`` electrical speed
[rad/s]; ``theta_mech`` mechanical shaft angle [rad] (unbounded). Rotor flux psi_r = L_m i_m
(3.40).

Mechanics (3.37) with the friction that the thesis lumps into m_L kept separate::

    d omega_r/dt = Z_p/J (m_e - m_L - m_friction),   omega_mech = omega_r/Z_p
    m_friction   = B_visc omega_mech + m_coulomb tanh(omega_mech/omega_eps)

The Coulomb term is regularised by tanh: it is smooth (so RK4 keeps its order) and reaches 99.5 %
of m_coulomb at 3 omega_eps. Its price is creep: a torque |m| < m_coulomb turns the shaft at
omega_eps atanh(|m|/m_coulomb) instead of holding it. With the default omega_eps = 0.01 rad/s
(mechanical) the creep under 80 % of m_coulomb is 0.011 rad/s, far below the encoder's resolution,
and the friction pole m_coulomb/(J omega_eps) = 400 1/s is comfortably inside RK4's stability
region at h = 1/3000 s.

Integration: fixed-step classic RK4 with the input voltage and the load torque held over the step
(the inverter is a zero-order hold). With the thesis' data the fastest electrical pole is about
-380 1/s, so |lambda h| ~ 0.15 at 3 kHz and one RK4 step per period is already accurate;
``substeps`` (default 1) subdivides the step when wanted. See tests/test_motor.py for the bound
against a 100x finer step.

Modes:
- ``hold_speed``: omega_r is held at its value (the shaft is driven by an ideal speed source);
  theta_mech still integrates. For steady-state and fixed-speed tests.
- ``coast`` (inverter disabled): i_s is forced to 0, the rotor flux decays by the current model
  (4.15) with i_s = 0 and m_e = 0. This simplifies diode freewheeling, which in the real bridge
  drives the stator current to zero within a few ms through the DC link. The terminal voltage is
  then the back-EMF u_s = L'_m d i_m/dt (from psi_s = L'_s i_s + L'_m i_m with i_s = 0); `u_s`
  reports its average over the last step.
"""

from __future__ import annotations

import math

from bench.params import MotorParams

OMEGA_EPS_DEFAULT = 0.01  # Coulomb-friction regularisation [rad/s mechanical]


class InductionMotor:
    """The 5th-order induction-motor model (3.41)+(3.37), stepped by fixed-step RK4."""

    def __init__(
        self,
        params: MotorParams,
        *,
        substeps: int = 1,
        omega_eps: float = OMEGA_EPS_DEFAULT,
        omega_r0: float = 0.0,
        hold_speed: bool = False,
    ) -> None:
        params.validate()
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        if not omega_eps > 0:
            raise ValueError(f"omega_eps must be > 0, got {omega_eps!r}")
        self.params = params
        self.substeps = int(substeps)
        self.omega_eps = float(omega_eps)
        self.hold_speed = hold_speed
        self.coast = False
        # coefficients of (3.41), written with the primed quantities of 4.1
        p = params
        Ls_p, Lm_p, Rr_p = p.Ls_p, p.Lm_p, p.Rr_p
        self._a11 = -(p.R_s + Rr_p) / Ls_p  # A_sc[0,0] = (L_m^2 R_r + R_s L_r^2)/(L_r(L_m^2 - L_s L_r))
        self._a12 = Rr_p / Ls_p  # real part of A_sc[0,1]
        self._a12w = -Lm_p / Ls_p  # A_sc[0,1] imaginary part per unit omega_r
        self._b1 = 1.0 / Ls_p  # B_sc[0] = L_r/(L_s L_r - L_m^2)
        self._a21 = p.R_r / p.L_r  # A_sc[1,0] = R_r/L_r;  A_sc[1,1] = j omega_r - R_r/L_r
        self._k_t = 1.5 * p.Z_p * Lm_p  # m_e = 3 Z_p L_m^2/(2 L_r) Im{i_s i_m^*}  (3.41)
        self._zp_j = p.Z_p / p.J
        self._zp_inv = 1.0 / p.Z_p
        self._b_visc = p.B_visc
        self._m_c = p.m_coulomb
        self._w_eps_inv = 1.0 / self.omega_eps
        self.reset(omega_r=omega_r0)

    # --- state ---------------------------------------------------------------------------
    def reset(self, *, i_s: complex = 0j, i_m: complex = 0j, omega_r: float = 0.0,
              theta_mech: float = 0.0) -> None:  # fmt: skip
        """Set the state (default: at rest, de-energised)."""
        self.i_s = complex(i_s)
        self.i_m = complex(i_m)
        self.omega_r = float(omega_r)
        self.theta_mech = float(theta_mech)
        self.u_s = 0j  # stator voltage over the last step [V] (input, or back-EMF when coasting)
        self.m_L = 0.0  # load torque over the last step [N m]

    # --- derived outputs -----------------------------------------------------------------
    @property
    def m_e(self) -> float:
        """Electromagnetic torque (3.41): 3 Z_p L_m^2/(2 L_r) Im{i_s i_m^*} [N m]."""
        i_s, i_m = self.i_s, self.i_m
        return self._k_t * (i_s.imag * i_m.real - i_s.real * i_m.imag)

    @property
    def i_rs(self) -> complex:
        """Stator-fixed rotor current (3.33), from i_m = i_s + (L_r/L_m) i_rs (3.39) [A]."""
        p = self.params
        return (self.i_m - self.i_s) * (p.L_m / p.L_r)

    @property
    def psi_r(self) -> complex:
        """Stator-fixed rotor flux psi_rs = L_m i_m (3.40) [Wb]."""
        return self.params.L_m * self.i_m

    @property
    def psi_s(self) -> complex:
        """Stator flux psi_s = L_s i_s + L_m i_rs = L'_s i_s + L'_m i_m [Wb]."""
        p = self.params
        return p.Ls_p * self.i_s + p.Lm_p * self.i_m

    @property
    def omega_mech(self) -> float:
        """Mechanical speed omega_r/Z_p (3.32) [rad/s]."""
        return self.omega_r * self._zp_inv

    @property
    def theta_r(self) -> float:
        """Electrical rotor angle Z_p theta_mech (3.32) [rad], unbounded."""
        return self.params.Z_p * self.theta_mech

    @property
    def m_friction(self) -> float:
        """Viscous + regularised Coulomb friction torque on the shaft [N m]."""
        w = self.omega_r * self._zp_inv
        return self._b_visc * w + self._m_c * math.tanh(w * self._w_eps_inv)

    @property
    def p_in(self) -> float:
        """Electrical input power (3/2) Re{u_s i_s^*} with u_s of the last step [W]."""
        u, i = self.u_s, self.i_s
        return 1.5 * (u.real * i.real + u.imag * i.imag)

    def magnetic_energy(self) -> float:
        """Stored magnetic energy (3/4) Re{i_s^* psi_s + i_rs^* psi_rs} [J]."""
        p = self.params
        i_s, i_rs = self.i_s, self.i_rs
        psi_s = p.L_s * i_s + p.L_m * i_rs
        psi_rs = p.L_m * i_s + p.L_r * i_rs
        return 0.75 * ((i_s.conjugate() * psi_s).real + (i_rs.conjugate() * psi_rs).real)

    def copper_losses(self) -> float:
        """Stator + rotor copper losses (3/2)(R_s|i_s|^2 + R_r|i_rs|^2) [W]."""
        p = self.params
        return 1.5 * (p.R_s * abs(self.i_s) ** 2 + p.R_r * abs(self.i_rs) ** 2)

    # --- integration ---------------------------------------------------------------------
    def step(self, u_s: complex, m_L: float, h: float) -> None:
        """Advance by h [s] with u_s [V] and m_L [N m] held constant (RK4, `substeps` steps)."""
        n = self.substeps
        hs = h / n
        if self.coast:
            i_m0 = self.i_m
            for _ in range(n):
                self._rk4_coast(m_L, hs)
            self.i_s = 0j
            self.u_s = self.params.Lm_p * (self.i_m - i_m0) / h  # back-EMF, mean over the step
        else:
            for _ in range(n):
                self._rk4(u_s, m_L, hs)
            self.u_s = u_s
        self.m_L = m_L

    def _rk4(self, u: complex, m_L: float, h: float) -> None:
        # Inlined right-hand side of (3.41) and (3.37); locals only, for speed.
        a11, a12, a12w, a21 = self._a11, self._a12, self._a12w, self._a21
        bu = self._b1 * u
        kt, zpj, zpi, bv, mc, wei = self._k_t, self._zp_j, self._zp_inv, self._b_visc, self._m_c, self._w_eps_inv
        hold = self.hold_speed
        tanh = math.tanh
        i_s, i_m, w, th = self.i_s, self.i_m, self.omega_r, self.theta_mech
        h2 = 0.5 * h

        # k1
        a = a11 * i_s + complex(a12, a12w * w) * i_m + bu
        b = a21 * i_s + complex(-a21, w) * i_m
        if hold:
            c = 0.0
        else:
            wm = w * zpi
            c = zpj * (kt * (i_s.imag * i_m.real - i_s.real * i_m.imag) - m_L - bv * wm - mc * tanh(wm * wei))
        d = w * zpi
        # k2
        i_s2, i_m2, w2 = i_s + h2 * a, i_m + h2 * b, w + h2 * c
        a2 = a11 * i_s2 + complex(a12, a12w * w2) * i_m2 + bu
        b2 = a21 * i_s2 + complex(-a21, w2) * i_m2
        if hold:
            c2 = 0.0
        else:
            wm = w2 * zpi
            c2 = zpj * (kt * (i_s2.imag * i_m2.real - i_s2.real * i_m2.imag) - m_L - bv * wm - mc * tanh(wm * wei))
        d2 = w2 * zpi
        # k3
        i_s3, i_m3, w3 = i_s + h2 * a2, i_m + h2 * b2, w + h2 * c2
        a3 = a11 * i_s3 + complex(a12, a12w * w3) * i_m3 + bu
        b3 = a21 * i_s3 + complex(-a21, w3) * i_m3
        if hold:
            c3 = 0.0
        else:
            wm = w3 * zpi
            c3 = zpj * (kt * (i_s3.imag * i_m3.real - i_s3.real * i_m3.imag) - m_L - bv * wm - mc * tanh(wm * wei))
        d3 = w3 * zpi
        # k4
        i_s4, i_m4, w4 = i_s + h * a3, i_m + h * b3, w + h * c3
        a4 = a11 * i_s4 + complex(a12, a12w * w4) * i_m4 + bu
        b4 = a21 * i_s4 + complex(-a21, w4) * i_m4
        if hold:
            c4 = 0.0
        else:
            wm = w4 * zpi
            c4 = zpj * (kt * (i_s4.imag * i_m4.real - i_s4.real * i_m4.imag) - m_L - bv * wm - mc * tanh(wm * wei))
        d4 = w4 * zpi

        h6 = h / 6.0
        self.i_s = i_s + h6 * (a + 2.0 * (a2 + a3) + a4)
        self.i_m = i_m + h6 * (b + 2.0 * (b2 + b3) + b4)
        self.omega_r = w + h6 * (c + 2.0 * (c2 + c3) + c4)
        self.theta_mech = th + h6 * (d + 2.0 * (d2 + d3) + d4)

    def _rk4_coast(self, m_L: float, h: float) -> None:
        # i_s = 0: d i_m/dt = (-R_r/L_r + j omega_r) i_m  (4.15);  m_e = 0 in (3.37).
        a21, zpj, zpi, bv, mc, wei = self._a21, self._zp_j, self._zp_inv, self._b_visc, self._m_c, self._w_eps_inv
        hold, tanh = self.hold_speed, math.tanh
        i_m, w, th = self.i_m, self.omega_r, self.theta_mech
        h2 = 0.5 * h

        def dw(w_: float) -> float:
            if hold:
                return 0.0
            wm = w_ * zpi
            return -zpj * (m_L + bv * wm + mc * tanh(wm * wei))

        b, c = complex(-a21, w) * i_m, dw(w)
        w2 = w + h2 * c
        b2, c2 = complex(-a21, w2) * (i_m + h2 * b), dw(w2)
        w3 = w + h2 * c2
        b3, c3 = complex(-a21, w3) * (i_m + h2 * b2), dw(w3)
        w4 = w + h * c3
        b4, c4 = complex(-a21, w4) * (i_m + h * b3), dw(w4)
        h6 = h / 6.0
        self.i_m = i_m + h6 * (b + 2.0 * (b2 + b3) + b4)
        self.omega_r = w + h6 * (c + 2.0 * (c2 + c3) + c4)
        self.theta_mech = th + h6 * zpi * (w + 2.0 * (w2 + w3) + w4)

    def derivatives(self, u_s: complex, m_L: float) -> tuple[complex, complex, float, float]:
        """Right-hand side (d i_s, d i_m, d omega_r, d theta_mech)/dt at the current state.

        Reference implementation of (3.41)+(3.37) (not used per tick; for tests and tools).
        """
        p = self.params
        i_s, i_m, w = self.i_s, self.i_m, self.omega_r
        if self.coast:
            i_s = 0j
        denom = p.L_r * (p.L_m**2 - p.L_s * p.L_r)
        a11 = (p.L_m**2 * p.R_r + p.R_s * p.L_r**2) / denom
        a12 = p.L_m**2 * (1j * p.L_r * w - p.R_r) / denom
        b1 = p.L_r / (p.L_s * p.L_r - p.L_m**2)
        di_s = 0j if self.coast else a11 * i_s + a12 * i_m + b1 * u_s
        di_m = p.R_r / p.L_r * i_s + (1j * w - p.R_r / p.L_r) * i_m
        m_e = 0.0 if self.coast else 1.5 * p.Z_p * p.L_m**2 / p.L_r * (i_s * i_m.conjugate()).imag
        dw = 0.0 if self.hold_speed else p.Z_p / p.J * (m_e - m_L - self.m_friction)
        return di_s, di_m, dw, w / p.Z_p


def steady_state(
    params: MotorParams, u_ss: complex, omega_mR: float, omega_r: float
) -> tuple[complex, complex, float]:
    """Steady state of (3.41) for a voltage u_ss e^{j omega_mR t} at speed omega_r.

    Returns (i_ss, i_ms, m_e): stator and magnetising current in the frame rotating at omega_mR
    ((3.54), (3.55)) and the torque (3.56), written exactly as in the thesis.
    """
    R_s, R_r, L_s, L_r, L_m = params.R_s, params.R_r, params.L_s, params.L_r, params.L_m
    w_sl = omega_mR - omega_r
    den = (R_s * R_r + 1j * w_sl * R_s * L_r + 1j * omega_mR * L_s * R_r
           + omega_mR * w_sl * (L_m**2 - L_r * L_s))  # fmt: skip
    i_ss = (R_r + 1j * w_sl * L_r) * u_ss / den  # (3.54)
    i_ms = R_r * u_ss / den  # (3.55)
    m_e = 3.0 * params.Z_p * L_m**2 / (2.0 * R_r) * abs(i_ms) ** 2 * w_sl  # (3.56)
    return i_ss, i_ms, m_e
