"""Flux observers (thesis Sec. 4.3) and Kubota's adaptive flux and speed observer (Sec. 4.4.2).

A flux observer estimates the magnetising current i_m (rotor flux / L_m, (3.40)) in stator-fixed
coordinates from the stator current, the stator voltage and the speed. Observers are swappable
inside the rotor-flux-oriented controller and selected by name from `OBSERVERS`:

=================  ==========================================================================
``current_model``  (4.15): open-loop rotor equation, needs R_r and omega_r
``voltage_model``  (4.16)(4.17): integrated stator equation, needs R_s, no omega_r
``jl``             Jansen-Lorenz (4.3.1): voltage model pulled towards the current model by
                   the complex PI weighting K_1 + K_2/s
``kubota``         Kubota et al. (4.20)(4.21): full-order observer of (i_s, i_m) with observer
                   poles at ``pole_ratio`` x the model poles and adaptive speed estimate
=================  ==========================================================================

Timing convention (shared by all observers): ``update`` is called at sample t_k with the measured
stator current i_s(t_k) and the stator voltage u_s applied over [t_{k-1}, t_k) (the inverter holds
it: zero-order hold). The observer advances its state from t_{k-1} to t_k and returns the estimate
at t_k. The stator current is taken as linear between samples (first-order hold).

Per-tick code uses Python floats and complex numbers only (no small numpy arrays).
"""

from __future__ import annotations

import cmath
import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from scipy.linalg import expm

from bench.params import MotorParams


class FluxObserver(ABC):
    """i_m estimator: ``update(i_s, u_s, omega_r) -> i_m_hat`` once per base tick.

    ``defaults`` lists the observer's tunable parameters (floats, SI units); the FOC controller
    exposes them as ``<name>_<parameter>``.
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    #: True if the observer estimates the speed itself and ignores the omega_r given to update()
    estimates_speed: ClassVar[bool] = False

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        unknown = set(params) - set(self.defaults)
        if unknown:
            raise ValueError(f"{self.name}: unknown parameter(s) {sorted(unknown)}")
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
    summary = "current model (4.15): rotor equation driven by i_s and omega_r"

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


class VoltageModelObserver(FluxObserver):
    """Voltage model (4.16)(4.17): psi_s = integral of (u_s - R_s i_s); i_m from psi_s and i_s.

    i_m_hat = (L_r/L_m^2) psi_s + (1 - L_r L_s / L_m^2) i_s                           (4.17)

    The integral is trapezoidal in i_s and exact for the held u_s. It is a pure integrator, so
    any DC offset in u_s - R_s i_s makes psi_s drift linearly (slope = the offset) - the noise
    sensitivity at low frequency the thesis warns about. ``tau`` > 0 replaces 1/s by the low-pass
    tau/(1 + s tau) (a common practical fix, *not* in the thesis; default 0 = pure integration).
    """

    name = "voltage_model"
    summary = "voltage model (4.16)(4.17): integrated stator equation, no speed needed"
    defaults: ClassVar[dict[str, Any]] = {"tau": 0.0}

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        m = motor
        self._c_psi = m.L_r / m.L_m**2  # (4.17)
        self._c_is = 1.0 - m.L_r * m.L_s / m.L_m**2
        tau = float(self.p["tau"])
        self._decay = math.exp(-T_s / tau) if tau > 0 else 1.0
        self.reset()

    def reset(self) -> None:
        self.psi_s = 0j
        self.i_m = 0j
        self._i_s_prev: complex | None = None

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        e = u_s - self.motor.R_s * 0.5 * (prev + i_s)  # (4.16): d psi_s/dt = u_s - R_s i_s
        self.psi_s = self._decay * self.psi_s + self.T_s * e
        self.i_m = self._c_psi * self.psi_s + self._c_is * i_s  # (4.17)
        return self.i_m


class JansenLorenzObserver(FluxObserver):
    """Jansen-Lorenz observer (Sec. 4.3.1, state space (A_jl, B_jl, C_jl, D_jl)).

    With x_jl = [psi_s, g, psi_rc] the thesis' matrices read, written out:

        d/dt psi_rc = (-R_r/L_r + j omega_r) psi_rc + (L_m R_r/L_r) i_s      current model (4.15)
        psi_rv      = (L_r/L_m) psi_s - (L_r L_s/L_m - L_m) i_s               voltage-model rotor flux
        d/dt g      = psi_rc - psi_rv                                         (row 2 of A_jl, B_jl)
        d/dt psi_s  = u_s - R_s i_s + K_1 (psi_rc - psi_rv) + K_2 g           (row 1)
        i_m_hat     = psi_rv / L_m = C_jl x_jl + D_jl y_m                     (output; INDEX errata)

    i.e. the voltage model corrected towards the current model by the complex PI K_1 + K_2/s.
    K_1 -> infinity gives the current model, K_1 = K_2 = 0 the voltage model. The thesis' hand
    tuning (5.6.2) is K_1 = 32(1+0.1j), K_2 = 2(1+0.1j).

    Discretisation: psi_rc exactly as `CurrentModelObserver`; the constant 2x2 (psi_s, g) part
    exactly for a held u_s and the other inputs linear between samples (matrices computed once).
    """

    name = "jl"
    summary = "Jansen-Lorenz (4.3.1): voltage model pulled to the current model by K_1 + K_2/s"
    defaults: ClassVar[dict[str, Any]] = {"K1_re": 32.0, "K1_im": 3.2, "K2_re": 2.0, "K2_im": 0.2}

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        m, T = motor, T_s
        K1 = complex(self.p["K1_re"], self.p["K1_im"])
        K2 = complex(self.p["K2_re"], self.p["K2_im"])
        self.K1, self.K2 = K1, K2
        self._b = m.R_r / m.L_r
        self._lr_lm = m.L_r / m.L_m
        self._c_is = m.L_r * m.L_s / m.L_m - m.L_m  # psi_rv = (L_r/L_m) psi_s - c_is i_s
        self._inv_Lm = 1.0 / m.L_m
        # continuous 2x2 part: d/dt [psi_s, g] = Mc [psi_s, g] + [u + w1, w2], with
        #   Mc = [[-K1 L_r/L_m, K2], [-L_r/L_m, 0]],  w1 = K1 e0 - R_s i_s,  w2 = e0,
        #   e0 = psi_rc + c_is i_s  (the part of the flux error not depending on psi_s).
        # Exact discretisation, u held, w linear between samples (first-order hold); computed once:
        #   expm([[Mc, I, 0], [0, 0, I/T], [0, 0, 0]] T) = [[Phi, Gam, Lam], ...],
        #   x+ = Phi x + Gam (u + w(t_{k-1})) + Lam (w(t_k) - w(t_{k-1}))
        Mc = np.array([[-K1 * self._lr_lm, K2], [-self._lr_lm, 0.0]], dtype=complex)
        aug = np.zeros((6, 6), dtype=complex)
        aug[:2, :2], aug[:2, 2:4], aug[2:4, 4:] = Mc * T, np.eye(2) * T, np.eye(2)
        E = expm(aug)
        self._F = tuple(complex(v) for v in E[:2, :2].ravel())
        self._G = tuple(complex(v) for v in E[:2, 2:4].ravel())
        self._L = tuple(complex(v) for v in E[:2, 4:].ravel())
        self.reset()

    def reset(self) -> None:
        self.psi_s = 0j
        self.g = 0j
        self.psi_rc = 0j
        self.i_m = 0j
        self._i_s_prev: complex | None = None
        self._w_prev: tuple[complex, complex] | None = None

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        # current model part (4.15), psi_rc = L_m i_m,c: exact, first-order hold on i_s
        a = complex(-self._b, omega_r)
        phi = cmath.exp(a * self.T_s)
        self.psi_rc = phi * self.psi_rc + (phi - 1.0) / a * self._b * self.motor.L_m * 0.5 * (prev + i_s)
        # inputs of the (psi_s, g) part at this sample; u_s is held over the period
        e0 = self.psi_rc + self._c_is * i_s
        w1 = self.K1 * e0 - self.motor.R_s * i_s
        w1p, w2p = (w1, e0) if self._w_prev is None else self._w_prev
        self._w_prev = (w1, e0)
        a1, a2 = u_s + w1p, w2p  # held part
        d1, d2 = w1 - w1p, e0 - w2p  # ramp part
        F00, F01, F10, F11 = self._F
        G00, G01, G10, G11 = self._G
        L00, L01, L10, L11 = self._L
        x1, x2 = self.psi_s, self.g
        self.psi_s = F00 * x1 + F01 * x2 + G00 * a1 + G01 * a2 + L00 * d1 + L01 * d2
        self.g = F10 * x1 + F11 * x2 + G10 * a1 + G11 * a2 + L10 * d1 + L11 * d2
        self.i_m = (self._lr_lm * self.psi_s - self._c_is * i_s) * self._inv_Lm  # C_jl x + D_jl y
        return self.i_m


def kubota_gain(motor: MotorParams, omega_r: float, k: float) -> tuple[complex, complex]:
    """Observer gain G = [g1, g2] of (4.20) with eig(A_sc(omega_r) + G C) = k eig(A_sc(omega_r)).

    C = [1 0]. Matching trace and determinant of the 2x2 complex matrices:
        g1 = (k - 1)(a11 + a22),   g2 = ((a11 + g1) a22 - a12 a21 - k^2 det A_sc) / a12.
    k = 1 gives G = 0 (open-loop model).
    """
    a11, a12, a21, a22 = sc_matrix(motor, omega_r)
    g1 = (k - 1.0) * (a11 + a22)
    det = a11 * a22 - a12 * a21
    g2 = ((a11 + g1) * a22 - a12 * a21 - k * k * det) / a12
    return g1, g2


def sc_matrix(motor: MotorParams, omega_r: float) -> tuple[complex, complex, complex, complex]:
    """Entries (a11, a12, a21, a22) of A_sc in (3.41) at speed omega_r."""
    m = motor
    den = m.L_r * (m.L_m**2 - m.L_s * m.L_r)
    a11 = complex((m.L_m**2 * m.R_r + m.R_s * m.L_r**2) / den, 0.0)
    a12 = m.L_m**2 * complex(-m.R_r, m.L_r * omega_r) / den
    a21 = complex(m.R_r / m.L_r, 0.0)
    a22 = complex(-m.R_r / m.L_r, omega_r)
    return a11, a12, a21, a22


class KubotaObserver(FluxObserver):
    """Adaptive flux and speed observer of Kubota et al. (4.20)(4.21).

        d/dt x_hat = A_sc(omega_hat) x_hat + B_sc u_s + G (i_s_hat - i_s),  x = [i_s, i_m]   (4.20)
        d/dt omega_hat = lambda_c Im{e_is^* i_m_hat},   e_is = i_s - i_s_hat               (4.21)

    G places the observer poles at ``pole_ratio`` times the poles of A_sc(omega_hat) (`kubota_gain`,
    recomputed every tick since A_sc depends on omega_hat); pole_ratio = 1 is G = 0.
    ``lambda_p`` adds an optional proportional term lambda_p Im{e_is^* i_m_hat} to omega_hat
    (Kubota's original PI adaptation; 0 = the thesis' pure integral law).

    With ``adapt`` = 0 the speed is not estimated and the omega_r given to ``update`` is used
    (a full-order Luenberger flux observer with measured speed). Otherwise that argument is ignored.

    Discretisation: the observer dynamics x' = (A + G C) x + B u - G i_s exactly over one period
    (closed-form 2x2 matrix exponential every tick, held u_s, i_s averaged over the period), then
    one Euler step of the speed law with the a posteriori current error. (A bilinear rule was tried
    first: its O((lambda T)^3) model error alone moved the speed equilibrium by 4 rad/s at 150 rad/s.)
    """

    name = "kubota"
    summary = "Kubota (4.20)(4.21): adaptive full-order observer, estimates flux and speed"
    defaults: ClassVar[dict[str, Any]] = {"pole_ratio": 1.1, "lambda_c": 1000.0, "lambda_p": 0.0,
                                          "adapt": 1.0, "omega0": 0.0}  # fmt: skip
    estimates_speed = True

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        self._k = float(self.p["pole_ratio"])
        self._lam = float(self.p["lambda_c"]) * T_s
        self._lam_p = float(self.p["lambda_p"])
        self._adapt = bool(self.p["adapt"])
        self.estimates_speed = self._adapt  # type: ignore[misc]
        m = motor
        self._b1 = m.L_r / (m.L_s * m.L_r - m.L_m**2)  # B_sc[0]
        self.reset()

    def reset(self) -> None:
        self.i_s_hat = 0j
        self.i_m = 0j
        self.omega_i = float(self.p["omega0"])  # integral part of the speed estimate
        self.omega_hat = self.omega_i
        self.e_is = 0j
        self._i_s_prev: complex | None = None

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        w = self.omega_hat if self._adapt else omega_r
        a11, a12, a21, a22 = sc_matrix(self.motor, w)
        k = self._k
        g1 = (k - 1.0) * (a11 + a22)  # kubota_gain, inlined
        det_a = a11 * a22 - a12 * a21
        g2 = ((a11 + g1) * a22 - a12 * a21 - k * k * det_a) / a12
        # M = A + G C  (C = [1 0]);  x' = M x + [b1 u - g1 i_s, -g2 i_s]
        m11, m12, m21, m22 = a11 + g1, a12, a21 + g2, a22
        # exact discretisation over one period (held u_s, i_s averaged over the period):
        # Phi = e^{MT} = e^{sT} (cosh(dT) I + sinh(dT)/d (M - sI)),  s = tr M/2,  d^2 = ((m11-m22)/2)^2 + m12 m21
        # Gam = int_0^T e^{M t} dt = M^-1 (Phi - I)
        T = self.T_s
        sm = 0.5 * (m11 + m22)
        d = cmath.sqrt(0.25 * (m11 - m22) ** 2 + m12 * m21)
        es = cmath.exp(sm * T)
        ch = es * cmath.cosh(d * T)
        sh = es * (cmath.sinh(d * T) / d if abs(d) > 1e-9 else T)
        p11, p12, p21, p22 = ch + sh * (m11 - sm), sh * m12, sh * m21, ch + sh * (m22 - sm)
        det = m11 * m22 - m12 * m21
        i_avg = 0.5 * (prev + i_s)
        w1 = self._b1 * u_s - g1 * i_avg
        w2 = -g2 * i_avg
        # Gam w = M^-1 (Phi - I) w
        v1 = (p11 - 1.0) * w1 + p12 * w2
        v2 = p21 * w1 + (p22 - 1.0) * w2
        x1, x2 = self.i_s_hat, self.i_m
        self.i_s_hat = p11 * x1 + p12 * x2 + (m22 * v1 - m12 * v2) / det
        self.i_m = p21 * x1 + p22 * x2 + (m11 * v2 - m21 * v1) / det
        # speed adaptation (4.21)
        e = i_s - self.i_s_hat
        self.e_is = e
        if self._adapt:
            im = self.i_m
            drive = e.real * im.imag - e.imag * im.real  # Im{e^* i_m_hat}
            self.omega_i += self._lam * drive
            self.omega_hat = self.omega_i + self._lam_p * drive
        else:
            self.omega_hat = omega_r
        return self.i_m


OBSERVERS: dict[str, type[FluxObserver]] = {
    cls.name: cls for cls in (CurrentModelObserver, VoltageModelObserver, JansenLorenzObserver, KubotaObserver)
}
