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
from dataclasses import dataclass, replace

from numba.extending import register_jitable

from bench.params import MotorParams
from mock_hw.thermal import copper_loss

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
        self._set_coeffs()
        self.reset(omega_r=omega_r0)

    def _set_coeffs(self) -> None:
        # coefficients of (3.41), written with the primed quantities of 4.1
        p = self.params
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

    def set_resistances(self, R_s: float, R_r: float) -> None:
        """Change the winding resistances [Ohm] from the next step on (temperature, `mock_hw.thermal`;
        slowly varying, Sec. 3.4). ``params`` follows, so losses and truth use them too."""
        self.params = replace(self.params, R_s=R_s, R_r=R_r)
        self._set_coeffs()

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

    def winding_losses(self) -> tuple[float, float]:
        """Stator and rotor copper losses (3/2) R_s |i_s|^2, (3/2) R_r |i_rs|^2 [W] (`mock_hw.thermal`)."""
        p = self.params
        i_s, i_r = self.i_s, self.i_rs
        return copper_loss(p.R_s, i_s.real, i_s.imag), copper_loss(p.R_r, i_r.real, i_r.imag)

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
        self.i_s, self.i_m, self.omega_r, self.theta_mech = rk4(
            self.i_s, self.i_m, self.omega_r, self.theta_mech, u, m_L, h, self.hold_speed, self._a11, self._a12,
            self._a12w, self._a21, self._b1, self._k_t, self._zp_j, self._zp_inv, self._b_visc, self._m_c,
            self._w_eps_inv)  # fmt: skip

    def _rk4_coast(self, m_L: float, h: float) -> None:
        self.i_m, self.omega_r, self.theta_mech = rk4_coast(
            self.i_m, self.omega_r, self.theta_mech, m_L, h, self.hold_speed, self._a21, self._zp_j, self._zp_inv,
            self._b_visc, self._m_c, self._w_eps_inv)  # fmt: skip

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


# --- the RK4 steps, written once: plain Python on complex numbers that numba compiles (mock_hw.compiled calls
# the same two; numba's complex arithmetic is CPython 3.11's: a float operand is complex(x, 0.0))
@register_jitable  # called from Python as it is, and compiled into rk4's kernel
def _rates(i_s: complex, i_m: complex, w: float, bu: complex, m_L: float, hold: bool, a11: float, a12: float,
           a12w: float, a21: float, kt: float, zpj: float, zpi: float, bv: float, mc: float, wei: float
           ) -> tuple[complex, complex, float, float]:  # fmt: skip
    # (d i_s, d i_m, d omega_r, d theta_mech)/dt of (3.41)+(3.37), bu = b1 u_s
    a = a11 * i_s + complex(a12, a12w * w) * i_m + bu
    b = a21 * i_s + complex(-a21, w) * i_m
    if hold:
        c = 0.0
    else:
        wm = w * zpi
        c = zpj * (kt * (i_s.imag * i_m.real - i_s.real * i_m.imag) - m_L - bv * wm - mc * math.tanh(wm * wei))
    return a, b, c, w * zpi


def rk4(i_s: complex, i_m: complex, w: float, th: float, u: complex, m_L: float, h: float, hold: bool, a11: float,
        a12: float, a12w: float, a21: float, b1: float, kt: float, zpj: float, zpi: float, bv: float, mc: float,
        wei: float) -> tuple[complex, complex, float, float]:  # fmt: skip
    """One classic RK4 step h [s] of (3.41)+(3.37) with u [V] and m_L [N m] held: (i_s, i_m, omega_r, theta_mech)
    at its end. The coefficients are `InductionMotor`'s (``_set_coeffs``); ``hold``: the speed held."""
    bu = b1 * u
    h2 = 0.5 * h
    k = (m_L, hold, a11, a12, a12w, a21, kt, zpj, zpi, bv, mc, wei)
    a, b, c, d = _rates(i_s, i_m, w, bu, *k)
    a2, b2, c2, d2 = _rates(i_s + h2 * a, i_m + h2 * b, w + h2 * c, bu, *k)
    a3, b3, c3, d3 = _rates(i_s + h2 * a2, i_m + h2 * b2, w + h2 * c2, bu, *k)
    a4, b4, c4, d4 = _rates(i_s + h * a3, i_m + h * b3, w + h * c3, bu, *k)
    h6 = h / 6.0
    return (i_s + h6 * (a + 2.0 * (a2 + a3) + a4), i_m + h6 * (b + 2.0 * (b2 + b3) + b4),
            w + h6 * (c + 2.0 * (c2 + c3) + c4), th + h6 * (d + 2.0 * (d2 + d3) + d4))  # fmt: skip


@register_jitable  # called from Python as it is, and compiled into rk4_coast's kernel
def _coast_dw(w: float, m_L: float, hold: bool, zpj: float, zpi: float, bv: float, mc: float, wei: float) -> float:
    # (3.37) with m_e = 0
    if hold:
        return 0.0
    wm = w * zpi
    return -zpj * (m_L + bv * wm + mc * math.tanh(wm * wei))


def rk4_coast(i_m: complex, w: float, th: float, m_L: float, h: float, hold: bool, a21: float, zpj: float,
              zpi: float, bv: float, mc: float, wei: float) -> tuple[complex, float, float]:  # fmt: skip
    """One RK4 step h [s] while coasting (inverter off): i_s = 0, d i_m/dt = (-R_r/L_r + j omega_r) i_m (4.15),
    m_e = 0 in (3.37); (i_m, omega_r, theta_mech) at its end."""
    h2 = 0.5 * h
    b, c = complex(-a21, w) * i_m, _coast_dw(w, m_L, hold, zpj, zpi, bv, mc, wei)
    w2 = w + h2 * c
    b2, c2 = complex(-a21, w2) * (i_m + h2 * b), _coast_dw(w2, m_L, hold, zpj, zpi, bv, mc, wei)
    w3 = w + h2 * c2
    b3, c3 = complex(-a21, w3) * (i_m + h2 * b2), _coast_dw(w3, m_L, hold, zpj, zpi, bv, mc, wei)
    w4 = w + h * c3
    b4, c4 = complex(-a21, w4) * (i_m + h * b3), _coast_dw(w4, m_L, hold, zpj, zpi, bv, mc, wei)
    h6 = h / 6.0
    return (i_m + h6 * (b + 2.0 * (b2 + b3) + b4), w + h6 * (c + 2.0 * (c2 + c3) + c4),
            th + h6 * zpi * (w + 2.0 * (w2 + w3) + w4))  # fmt: skip


# --- main-flux saturation (Sec. 3.4: "L_m ... affected by magnetic saturation") ------------------------
PSI_M_RATED = 0.88  # rated main (air-gap) flux |psi_m| [Wb]; see `Saturation`


@dataclass(frozen=True)
class Saturation:
    """Static main-flux saturation curve: the secant inductance of the magnetising branch,

        L_m(psi) = L_m0 / (1 + (psi/psi_sat)^a),   psi = |psi_m|,   i_mu(psi) = psi / L_m(psi),

    normalised so that L_m(psi_rated) equals the rated L_m of (3.57):
    L_m0 = L_m (1 + (psi_rated/psi_sat)^a) is the unsaturated (small-flux) value. The flux-current
    curve i_mu(psi) = psi (1 + (psi/psi_sat)^a)/L_m0 is odd, smooth and strictly increasing for
    a >= 1, so every flux has one current and the field stores the energy (3/2) int_0^psi i_mu dpsi
    (amplitude-invariant vectors, 3.17). The incremental (dynamic) inductance is
    d psi/d i_mu = L_m0 / (1 + (a + 1)(psi/psi_sat)^a) < L_m(psi).

    Rated flux: the steady state (3.54)-(3.55) of the (3.57) machine at its nameplate point (380 V,
    50 Hz, 1420 rpm, 3.6 A) has |psi_m| = 0.885 Wb (psi_r = 0.884 Wb, 5.3 A peak), so psi_rated
    = 0.88 Wb: L_m is the identified 0.341 H where the motor runs at rated voltage and speed. (The
    bench's default i_mR_ref = 2.5 A is psi_r = 0.85 Wb, just below.) Defaults psi_sat = 1.1 Wb and
    a = 7 make L_m0 = 1.21 L_m (0.413 H) at small flux and L_m = 0.86 L_m at 1.1 psi_rated: a
    typical shape for a small cage motor, an assumption (the thesis gives no curve).
    """

    L_m: float  # rated mutual inductance (3.57) [H]
    psi_rated: float = PSI_M_RATED  # [Wb] where L_m(psi) = L_m
    psi_sat: float = 1.1  # [Wb] knee of the curve
    exponent: float = 7.0  # a, sharpness of the knee (>= 1)

    def __post_init__(self) -> None:
        if not (self.L_m > 0 and self.psi_rated > 0 and self.psi_sat > 0 and self.exponent >= 1):
            raise ValueError("saturation needs L_m, psi_rated, psi_sat > 0 and exponent >= 1")

    @property
    def L_m0(self) -> float:
        """Unsaturated mutual inductance L_m(0) [H]."""
        return self.L_m * (1.0 + (self.psi_rated / self.psi_sat) ** self.exponent)

    def L_m_of(self, psi: float) -> float:
        """Secant inductance L_m(|psi_m|) [H]."""
        return self.L_m0 / (1.0 + (abs(psi) / self.psi_sat) ** self.exponent)

    def L_dyn(self, psi: float) -> float:
        """Incremental inductance d psi/d i_mu at |psi_m| [H]."""
        return self.L_m0 / (1.0 + (self.exponent + 1.0) * (abs(psi) / self.psi_sat) ** self.exponent)

    def i_mu(self, psi: float) -> float:
        """Magnetising current for the main flux |psi_m| [A]."""
        return psi / self.L_m_of(psi)

    def energy(self, psi: float) -> float:
        """Energy in the magnetising field (3/2) int_0^psi i_mu dpsi [J]."""
        a, x = self.exponent, abs(psi)
        return 1.5 / self.L_m0 * (0.5 * x * x + x ** (a + 2.0) / ((a + 2.0) * self.psi_sat**a))

    def solve(self, w: float, g: float, x: float = 0.0) -> float:
        """The x >= 0 with i_mu(x) + g x = w (w >= 0, g >= 0 a leakage conductance 1/L_sigma sum):
        the main flux of the T circuit (`SaturatedInductionMotor`). Newton from the warm start x;
        the left side is convex and increasing, so from any start it converges, monotonically
        after the first step."""
        x = solve_main_flux(w, g, x, 1.0 / self.L_m0, 1.0 / self.psi_sat, self.exponent)
        if x < 0.0:
            raise ArithmeticError(f"saturation: no convergence for w={w!r}, g={g!r}")
        return x


class SaturatedInductionMotor(InductionMotor):
    """The motor of (3.34)-(3.37) with a saturating main flux, integrated in flux linkages.

    With L_m depending on the flux, the current state of (3.41) would need the derivative of L_m
    ("modelling this uncertainty is more complicated than simply assuming the inductances to be
    time-varying", Sec. 3.4). So this model integrates the voltage equations themselves, (3.26) and
    (3.27) in stator-fixed coordinates::

        d psi_s/dt = u_s - R_s i_s,     d psi_r/dt = -R_r i_rs + j omega_r psi_r      (psi_r: (3.40))

    and gets the currents from the fluxes through the T equivalent circuit: constant leakages
    L_ss = L_s - L_m, L_rs = L_r - L_m (rated L_m; leakage saturation neglected) and the main flux
    psi_m = L_m(|psi_m|) i_mu, i_mu = i_s + i_rs, psi_s = L_ss i_s + psi_m, psi_r = L_rs i_rs + psi_m.
    Eliminating the currents, psi_m is parallel to w = psi_s/L_ss + psi_r/L_rs with
    |psi_m| (1/L_m(|psi_m|) + 1/L_ss + 1/L_rs) = |w| (`Saturation.solve`). This is the full static
    saturation of the magnetising branch: the dynamic (incremental) inductance enters exactly,
    through the flux state, nothing is neglected but leakage saturation, cross-saturation with the
    leakage paths, hysteresis and iron losses. With psi_sat -> infinity it is the linear (3.41)
    model again (tests/test_plant_models.py). Torque (3.36): m_e = 3/2 Z_p Im{psi_r i_rs^*}.

    Outputs: ``i_s`` [A]; ``i_m`` = psi_r / L_m with the rated L_m, so that psi_r = L_m i_m (3.40)
    holds as for the linear model and i_m is what a controller with the nominal model estimates;
    ``psi_m`` the main flux, ``L_m_now`` its secant inductance. Coasting (i_s = 0): psi_r decays
    through the rotor circuit alone; the terminal voltage is d psi_s/dt with psi_s = psi_m.
    """

    def __init__(self, params: MotorParams, saturation: Saturation, **kw: object) -> None:
        if not (params.L_m < params.L_s and params.L_m < params.L_r):
            raise ValueError("saturation needs positive leakages, L_m < L_s and L_m < L_r")
        self.sat = saturation
        self._L_ss, self._L_rs = params.L_s - params.L_m, params.L_r - params.L_m
        self._gs, self._gr = 1.0 / self._L_ss, 1.0 / self._L_rs
        self._x = 0.0  # |psi_m| of the last solve (Newton's warm start)
        self._curve = (1.0 / saturation.L_m0, 1.0 / saturation.psi_sat, saturation.exponent)  # the kernels' l0i, ...
        super().__init__(params, **kw)  # type: ignore[arg-type]

    # --- state: fluxes; i_s, i_m follow them ------------------------------------------------
    def reset(self, *, i_s: complex = 0j, i_m: complex = 0j, omega_r: float = 0.0,
              theta_mech: float = 0.0) -> None:  # fmt: skip
        """Set the state from currents, as `InductionMotor.reset` (i_m = psi_r / L_m)."""
        super().reset(i_s=i_s, i_m=i_m, omega_r=omega_r, theta_mech=theta_mech)
        pr = self.params.L_m * self.i_m
        # i_mu = i_s + i_rs with i_rs = (psi_r - psi_m)/L_rs: psi_m parallel to i_s + psi_r/L_rs
        self._pr = pr
        self._ps = self._L_ss * self.i_s + self._main_flux(self.i_s + pr * self._gr, self._gr)
        self._sync()

    def _main_flux(self, w: complex, g: float) -> complex:
        pm, self._x = main_flux(w, g, self._x, *self._curve)
        return pm

    def _sync(self) -> None:
        # currents and main flux of the present flux state
        if self.coast:
            self._pm = pm = self._main_flux(self._pr * self._gr, self._gr)
            self.i_s = 0j
        else:
            self._pm = pm = self._main_flux(self._ps * self._gs + self._pr * self._gr, self._gs + self._gr)
            self.i_s = (self._ps - pm) * self._gs
        self.i_m = self._pr / self.params.L_m

    @property
    def psi_m(self) -> complex:
        """Main (air-gap) flux psi_m [Wb]."""
        return self._pm

    @property
    def L_m_now(self) -> float:
        """Secant mutual inductance at the present main flux [H]."""
        return self.sat.L_m_of(abs(self._pm))

    @property
    def psi_r(self) -> complex:
        return self._pr

    @property
    def psi_s(self) -> complex:
        return self._pm if self.coast else self._ps

    @property
    def i_rs(self) -> complex:
        return (self._pr - self._pm) * self._gr

    @property
    def m_e(self) -> float:
        """Electromagnetic torque (3.36) 3/2 Z_p Im{psi_r i_rs^*} [N m] (0 while coasting)."""
        if self.coast:
            return 0.0
        pr, ir = self._pr, self.i_rs
        return 1.5 * self.params.Z_p * (pr.imag * ir.real - pr.real * ir.imag)

    def magnetic_energy(self) -> float:
        """Leakage fields (3/4)(L_ss |i_s|^2 + L_rs |i_rs|^2) plus the main field [J]."""
        return (0.75 * (self._L_ss * abs(self.i_s) ** 2 + self._L_rs * abs(self.i_rs) ** 2)
                + self.sat.energy(abs(self._pm)))  # fmt: skip

    # --- integration ---------------------------------------------------------------------------
    def flux_derivatives(self, psi_s: complex, psi_r: complex, omega_r: float, u_s: complex,
                         m_L: float) -> tuple[complex, complex, float, float]:  # fmt: skip
        """(d psi_s, d psi_r, d omega_r, d theta_mech)/dt: (3.26), (3.27), (3.36), (3.37)."""
        d_ps, d_pr, d_w, wm, self._x = sat_rates(psi_s, psi_r, omega_r, self._x, u_s, m_L, self.coast, self.hold_speed,
                                                 *self._constants())  # fmt: skip
        return d_ps, d_pr, d_w, wm

    def _constants(self) -> tuple[float, ...]:
        # the kernels' motor constants (`sat_rates`), R_s and R_r as they are now (mock_hw.thermal)
        p = self.params
        return (self._gs, self._gr, p.R_s, p.R_r, p.Z_p, self._zp_inv, self._zp_j, self._b_visc, self._m_c,
                self._w_eps_inv, *self._curve)  # fmt: skip

    def derivatives(self, u_s: complex, m_L: float) -> tuple[complex, complex, float, float]:
        raise NotImplementedError("the saturated model's state is (psi_s, psi_r): use flux_derivatives")

    def step(self, u_s: complex, m_L: float, h: float) -> None:
        """Advance by h [s] with u_s [V] and m_L [N m] held (RK4 on the fluxes, `substeps` steps)."""
        (self._ps, self._pr, self._pm, self.i_s, self.i_m, self.omega_r, self.theta_mech, self.u_s,
         self._x) = sat_step(self._ps, self._pr, self.omega_r, self.theta_mech, u_s, m_L, h, self.substeps, self.coast,
                             self.hold_speed, self._x, self.params.L_m, *self._constants())  # fmt: skip
        self.m_L = m_L


# --- the saturated motor's kernels, written once: plain Python on complex numbers that numba compiles
# (mock_hw.compiled calls sat_step; numba's complex arithmetic is CPython 3.11's)
@register_jitable  # called from Python as it is, and compiled into the kernels that call it
def solve_main_flux(w: float, g: float, x: float, l0i: float, psi_inv: float, a: float) -> float:
    """`Saturation.solve`'s Newton iteration: the x >= 0 with x (1 + (x psi_inv)^a) l0i + g x = w, from the warm
    start x (the unsaturated solution where x <= 0); -1.0 where 100 steps do not converge."""
    if w <= 0.0:
        return 0.0
    if not x > 0.0:
        x = w / (l0i + g)  # the unsaturated solution, to the right of the root
    for _ in range(100):
        r = (x * psi_inv) ** a
        dx = (x * (1.0 + r) * l0i + g * x - w) / ((1.0 + (a + 1.0) * r) * l0i + g)
        x -= dx
        if abs(dx) <= 1e-13 * x:
            return x
    return -1.0


@register_jitable
def main_flux(w: complex, g: float, x: float, l0i: float, psi_inv: float, a: float) -> tuple[complex, float]:
    """The main flux psi_m, parallel to w = psi_s/L_ss + psi_r/L_rs with |psi_m| from `solve_main_flux` (g: the
    leakage conductances), and the new warm start."""
    n = abs(w)  # libm hypot in CPython and numba (CPython's math.hypot is its own, not libm's)
    if n == 0.0:
        return 0j, x
    x = solve_main_flux(n, g, x, l0i, psi_inv, a)
    if x < 0.0:
        raise ArithmeticError("saturation: the main flux's Newton iteration did not converge")
    return w * (x / n), x


@register_jitable
def sat_rates(ps: complex, pr: complex, w: float, x: float, u: complex, m_L: float, coast: bool, hold: bool,
              gs: float, gr: float, R_s: float, R_r: float, Z_p: float, zpi: float, zpj: float, bv: float, mc: float,
              wei: float, l0i: float, psi_inv: float, a: float
              ) -> tuple[complex, complex, float, float, float]:  # fmt: skip
    """(d psi_s, d psi_r, d omega_r, d theta_mech)/dt of (3.26), (3.27), (3.36), (3.37), and the warm start."""
    wm = w * zpi
    fric = bv * wm + mc * math.tanh(wm * wei)
    m_e = 0.0
    if coast:
        pm, x = main_flux(pr * gr, gr, x, l0i, psi_inv, a)
        d_ps = 0j
    else:
        pm, x = main_flux(ps * gs + pr * gr, gs + gr, x, l0i, psi_inv, a)
        d_ps = u - R_s * ((ps - pm) * gs)
    i_r = (pr - pm) * gr
    if not coast:
        m_e = 1.5 * Z_p * (pr.imag * i_r.real - pr.real * i_r.imag)
    d_pr = -R_r * i_r + 1j * w * pr
    d_w = 0.0 if hold else zpj * (m_e - m_L - fric)
    return d_ps, d_pr, d_w, wm, x


def sat_step(ps: complex, pr: complex, w: float, th: float, u: complex, m_L: float, h: float, n: int, coast: bool,
             hold: bool, x: float, L_m: float, gs: float, gr: float, R_s: float, R_r: float, Z_p: float, zpi: float,
             zpj: float, bv: float, mc: float, wei: float, l0i: float, psi_inv: float, a: float
             ) -> tuple[complex, complex, complex, complex, complex, float, float, complex, float]:  # fmt: skip
    """`SaturatedInductionMotor.step`: n RK4 steps of h/n [s] on (psi_s, psi_r, omega_r, theta_mech) with u [V] and
    m_L [N m] held, then the currents; (psi_s, psi_r, psi_m, i_s, i_m, omega_r, theta_mech, u_s, warm start)."""
    hs = h / n
    if coast:  # i_s = 0 from the start: the stator flux is the main flux of the rotor flux alone
        ps, x = main_flux(pr * gr, gr, x, l0i, psi_inv, a)
    ps0 = ps
    h2 = 0.5 * hs
    k = (u, m_L, coast, hold, gs, gr, R_s, R_r, Z_p, zpi, zpj, bv, mc, wei, l0i, psi_inv, a)
    for _ in range(n):
        a1, b1, c1, d1, x = sat_rates(ps, pr, w, x, *k)
        a2, b2, c2, d2, x = sat_rates(ps + h2 * a1, pr + h2 * b1, w + h2 * c1, x, *k)
        a3, b3, c3, d3, x = sat_rates(ps + h2 * a2, pr + h2 * b2, w + h2 * c2, x, *k)
        a4, b4, c4, d4, x = sat_rates(ps + hs * a3, pr + hs * b3, w + hs * c3, x, *k)
        h6 = hs / 6.0
        ps = ps + h6 * (a1 + 2.0 * (a2 + a3) + a4)
        pr = pr + h6 * (b1 + 2.0 * (b2 + b3) + b4)
        w = w + h6 * (c1 + 2.0 * (c2 + c3) + c4)
        th = th + h6 * (d1 + 2.0 * (d2 + d3) + d4)
    if coast:  # the currents and the main flux of the new state
        pm, x = main_flux(pr * gr, gr, x, l0i, psi_inv, a)
        i_s = 0j
    else:
        pm, x = main_flux(ps * gs + pr * gr, gs + gr, x, l0i, psi_inv, a)
        i_s = (ps - pm) * gs
    i_m = pr / L_m
    if coast:
        ps = pm
        u_s = (ps - ps0) / h  # back-EMF d psi_s/dt, mean over the step
    else:
        u_s = u
    return ps, pr, pm, i_s, i_m, w, th, u_s, x


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
