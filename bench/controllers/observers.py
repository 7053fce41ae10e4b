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
``lpv``            the discrete LPV observer of Sec. 5.6, synthesised by ``bench synth
                   flux-observer`` and loaded from an artifact (order 2 complex, scheduled by
                   omega_r/omega_r,max)
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
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy.linalg import expm

from bench.errors import BadInput
from bench.controllers.kernel_math import abs_checked, ccosh, cexp, csinh, csqrt, csquare
from bench.controllers.schema import Param, defaults_of
from bench.params import MotorParams
from synthesis.artifacts import ArtifactError, load_controller, motor_mismatch


class FluxObserver(ABC):
    """i_m estimator: ``update(i_s, u_s, omega_r) -> i_m_hat`` once per base tick.

    ``schema`` declares the observer's parameters (bench.controllers.schema, SI units); the FOC
    controller exposes them as ``<name>_<parameter>``.
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    schema: ClassVar[dict[str, Param]] = {}
    defaults: ClassVar[dict[str, Any]] = {}  # derived from `schema`

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        cls.defaults = defaults_of(cls.schema)
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

    def set_R_r(self, R_r: float) -> None:
        """Use this rotor resistance [Ohm] from the next update on (an on-line estimate,
        `bench.controllers.rr_adapt`). Observers without R_r at run time ignore it."""

    #: the observer's stator-fixed complex states (`rotate`)
    stator_states: ClassVar[tuple[str, ...]] = ()

    def rotate(self, e: complex) -> None:
        """Turn every stator-fixed state by ``e`` (|e| = 1): after a loop stall that the drive rode through by
        turning the voltage at the field's frequency (bench.hal.InverterPort), the field, the currents and so
        every state of an observer in steady state turned by the same angle."""
        turn(self, self.stator_states, e)

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        """Bumpless start (a switch from another observer while running): the state set from the outgoing
        observer's estimate i_m [A] and the last tick's i_s, u_s, speed omega_r and field speed omega_e
        [rad/s], so that the first estimate continues it. An observer that cannot says so (BadInput)."""
        raise BadInput("observer", f"the {self.name} observer cannot take over a running estimate")


def turn(obj: Any, names: tuple[str, ...], e: complex) -> None:
    """Multiply the complex attributes ``names`` of ``obj`` (None: left; a tuple: each item) by ``e``."""
    for name in names:
        v = getattr(obj, name)
        if v is not None:
            setattr(obj, name, tuple(x * e for x in v) if isinstance(v, tuple) else v * e)


class CurrentModelObserver(FluxObserver):
    """Current model (4.15): d/dt i_m = (-R_r/L_r + j omega_r) i_m + (R_r/L_r) i_s.

    Discretised exactly for omega_r constant over a period, with i_s interpolated linearly between
    the previous and the present sample (first-order hold), so the estimate belongs to the
    present sample instant. Needs accurate R_r and omega_r (thesis' remark after (4.15)).
    """

    name = "current_model"
    summary = "current model (4.15): rotor equation driven by i_s and omega_r"
    stator_states = ("i_m", "_i_s_prev")

    def reset(self) -> None:
        self.i_m = 0j
        self._i_s_prev: complex | None = None

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)
        self._b = motor.R_r / motor.L_r
        self.reset()

    def set_R_r(self, R_r: float) -> None:
        self._b = R_r / self.motor.L_r  # (4.15)

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        self.i_m, self._i_s_prev = i_m, i_s  # the state is the estimate itself

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        self.i_m = current_model_step(self.i_m, prev, i_s, omega_r, self._b, self.T_s)
        return self.i_m


def current_model_step(i_m: complex, prev: complex, i_s: complex, omega_r: float, b: float, T_s: float) -> complex:
    """One step of the current model (4.15) with b = R_r/L_r, exact for omega_r held and i_s linear from the previous
    sample's prev: i_m at this sample. Plain Python that numba compiles (`bench.controllers.foc_compiled` calls this
    one)."""
    a = complex(-b, omega_r)
    phi = cmath.exp(a * T_s)
    return phi * i_m + (phi - 1.0) / a * b * 0.5 * (prev + i_s)


class VoltageModelObserver(FluxObserver):
    """Voltage model (4.16)(4.17): psi_s = integral of (u_s - R_s i_s); i_m from psi_s and i_s.

    i_m_hat = (L_r/L_m^2) psi_s + (1 - L_r L_s / L_m^2) i_s                           (4.17)

    The integral is trapezoidal in i_s and exact for the held u_s. It is a pure integrator, so
    any DC offset in u_s - R_s i_s makes psi_s drift linearly (slope = the offset) - the noise
    sensitivity at low frequency the thesis warns about. ``tau`` > 0 replaces 1/s by the low-pass
    tau/(1 + s tau) (a common practical fix, *not* in the thesis; default 0 = pure integration).
    """

    name = "voltage_model"
    stator_states = ("psi_s", "i_m", "_i_s_prev")
    summary = "voltage model (4.16)(4.17): integrated stator equation, no speed needed"
    schema: ClassVar[dict[str, Param]] = {
        "tau": Param(0.0, "low-pass in place of the pure integrator (0: pure, as (4.16))", "s", ge=0, le=10),
    }

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

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        self.psi_s = (i_m - self._c_is * i_s) / self._c_psi  # (4.17) solved for psi_s
        self.i_m, self._i_s_prev = i_m, i_s

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        self.psi_s, self.i_m = voltage_model_step(self.psi_s, prev, i_s, u_s, self.motor.R_s, self._decay, self.T_s,
                                                  self._c_psi, self._c_is)  # fmt: skip
        return self.i_m


# The observers' kernels are written once, as plain Python on complex numbers that numba compiles
# (`bench.controllers.observers_compiled` calls these; numba's complex arithmetic and cmath.exp are CPython 3.11's).
def voltage_model_step(psi_s: complex, prev: complex, i_s: complex, u_s: complex, R_s: float, decay: float,
                       T_s: float, c_psi: float, c_is: float) -> tuple[complex, complex]:  # fmt: skip
    """One step of the voltage model from the previous sample's current prev: (psi_s, i_m) at this sample."""
    e = u_s - R_s * 0.5 * (prev + i_s)  # (4.16): d psi_s/dt = u_s - R_s i_s
    psi_s = decay * psi_s + T_s * e
    return psi_s, c_psi * psi_s + c_is * i_s  # (4.17)


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
    stator_states = ("psi_s", "g", "psi_rc", "i_m", "_i_s_prev", "_w_prev")
    summary = "Jansen-Lorenz (4.3.1): voltage model pulled to the current model by K_1 + K_2/s"
    schema: ClassVar[dict[str, Param]] = {
        "K1_re": Param(32.0, "Re K_1, proportional gain towards the current model (5.6.2: 32)", ge=0, le=1e5),
        "K1_im": Param(3.2, "Im K_1", ge=-1e5, le=1e5),
        "K2_re": Param(2.0, "Re K_2, integral gain (5.6.2: 2)", "1/s", ge=0, le=1e6),
        "K2_im": Param(0.2, "Im K_2", "1/s", ge=-1e6, le=1e6),
    }

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
        self._F = tuple(complex(v) for v in E[:2, :2].ravel())  # (independent of R_r: set_R_r keeps them)
        self._G = tuple(complex(v) for v in E[:2, 2:4].ravel())
        self._L = tuple(complex(v) for v in E[:2, 4:].ravel())
        self.reset()

    def set_R_r(self, R_r: float) -> None:
        self._b = R_r / self.motor.L_r  # the current-model part (4.15)

    def reset(self) -> None:
        self.psi_s = 0j
        self.g = 0j
        self.psi_rc = 0j
        self.i_m = 0j
        self._i_s_prev: complex | None = None
        self._w_prev: tuple[complex, complex] | None = None

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        # the current model at the estimate (psi_rc = L_m i_m), the integral g at the observer's own sinusoidal
        # steady state for it (everything turning at omega_e), rows 1-2 of the class docstring:
        #   (j w + K_1 L_r/L_m) psi_s - K_2 g = u_s - R_s i_s + K_1 (psi_rc + c_is i_s)
        #   (L_r/L_m) psi_s + j w g = psi_rc + c_is i_s,
        # and psi_s from the estimate (the output, C_jl x + D_jl y, continues): the difference between the voltage
        # model's steady state and the estimate then decays at the observer's own pace (K_1 L_r/L_m ~ 33 rad/s)
        # instead of jumping (the steady psi_s: 19 V and 1.2 N m at 297 rad/s, 10 N m; g = 0: 1.4 N m of
        # ringing at 100 rad/s; measured)
        m, w, r = self.motor, omega_e, self._lr_lm
        self.psi_rc = m.L_m * i_m
        e0 = self.psi_rc + self._c_is * i_s
        M = np.array([[1j * w + self.K1 * r, -self.K2], [r, 1j * w]])
        _, g = np.linalg.solve(M, [u_s - m.R_s * i_s + self.K1 * e0, e0])
        self.psi_s, self.g = (m.L_m * i_m + self._c_is * i_s) / r, complex(g)
        self.i_m, self._i_s_prev, self._w_prev = i_m, i_s, None

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        has_w = self._w_prev is not None
        w1p, w2p = self._w_prev if has_w else (0j, 0j)
        self.psi_s, self.g, self.psi_rc, w1, e0, self.i_m = jl_step(
            self.psi_s, self.g, self.psi_rc, prev, w1p, w2p, has_w, i_s, u_s, omega_r, self._b, self.T_s,
            self.motor.L_m, self.motor.R_s, self._c_is, self.K1, self._F, self._G, self._L, self._lr_lm,
            self._inv_Lm)  # fmt: skip
        self._w_prev = (w1, e0)
        return self.i_m


def jl_step(psi_s: complex, g: complex, psi_rc: complex, prev: complex, w1p: complex, w2p: complex, has_w: bool,
            i_s: complex, u_s: complex, omega_r: float, b: float, T_s: float, L_m: float, R_s: float, c_is: float,
            K1: complex, F: tuple, G: tuple, L: tuple, lr_lm: float, inv_Lm: float
            ) -> tuple[complex, complex, complex, complex, complex, complex]:  # fmt: skip
    """One step of the Jansen-Lorenz observer (`JansenLorenzObserver`; w1p, w2p: the inputs of the last sample,
    has_w: whether there was one): (psi_s, g, psi_rc, w1, e0, i_m) at this sample."""
    # current model part (4.15), psi_rc = L_m i_m,c: exact, first-order hold on i_s
    a = complex(-b, omega_r)
    phi = cmath.exp(a * T_s)
    psi_rc = phi * psi_rc + (phi - 1.0) / a * b * L_m * 0.5 * (prev + i_s)
    # inputs of the (psi_s, g) part at this sample; u_s is held over the period
    e0 = psi_rc + c_is * i_s
    w1 = K1 * e0 - R_s * i_s
    if not has_w:
        w1p, w2p = w1, e0
    a1, a2 = u_s + w1p, w2p  # held part
    d1, d2 = w1 - w1p, e0 - w2p  # ramp part
    F00, F01, F10, F11 = F
    G00, G01, G10, G11 = G
    L00, L01, L10, L11 = L
    x1, x2 = psi_s, g
    psi_s = F00 * x1 + F01 * x2 + G00 * a1 + G01 * a2 + L00 * d1 + L01 * d2
    g = F10 * x1 + F11 * x2 + G10 * a1 + G11 * a2 + L10 * d1 + L11 * d2
    return psi_s, g, psi_rc, w1, e0, (lr_lm * psi_s - c_is * i_s) * inv_Lm  # i_m = C_jl x + D_jl y


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
    stator_states = ("i_s_hat", "i_m", "e_is", "_i_s_prev")
    summary = "Kubota (4.20)(4.21): adaptive full-order observer, estimates flux and speed"
    schema: ClassVar[dict[str, Param]] = {
        "pole_ratio": Param(1.1, "observer poles / motor poles (1: G = 0)", gt=0, le=20),
        "lambda_c": Param(1000.0, "speed adaptation gain (4.21)", ge=0, le=1e7),
        "lambda_p": Param(0.0, "proportional term of the speed adaptation (0: the thesis' integral law)", ge=0, le=1e5),
        "adapt": Param(1.0, "1: estimate the speed; 0: use the measured speed (Luenberger)", choices=(0.0, 1.0)),
        "omega0": Param(0.0, "initial speed estimate", "rad/s", ge=-1000, le=1000),
    }
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

    def set_R_r(self, R_r: float) -> None:
        self.motor = self.motor.with_(R_r=R_r)  # A_sc (3.41) and so G follow from the next tick on

    def reset(self) -> None:
        self.i_s_hat = 0j
        self.i_m = 0j
        self.omega_i = float(self.p["omega0"])  # integral part of the speed estimate
        self.omega_hat = self.omega_i
        self.e_is = 0j
        self._i_s_prev: complex | None = None

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        self.i_s_hat, self.i_m, self.e_is, self._i_s_prev = i_s, i_m, 0j, i_s  # no current error to correct
        if self._adapt:  # the speed estimate starts at the speed in use
            self.omega_i = self.omega_hat = omega_r

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        prev = i_s if self._i_s_prev is None else self._i_s_prev
        self._i_s_prev = i_s
        m = self.motor
        self.i_s_hat, self.i_m, self.e_is, self.omega_i, self.omega_hat = kubota_step(
            i_s, u_s, omega_r, prev, self.i_s_hat, self.i_m, self.omega_i, self.omega_hat, self._adapt, self._k,
            self._lam, self._lam_p, self._b1, self.T_s, m.R_r, m.L_r, m.R_s, m.L_m**2,
            m.L_r * (m.L_m**2 - m.L_s * m.L_r), m.L_r**2)  # fmt: skip
        return self.i_m


def kubota_step(i_s: complex, u_s: complex, omega_r: float, prev: complex, x1: complex, x2: complex, omega_i: float,
                omega_hat: float, adapt: bool, k: float, lam: float, lam_p: float, b1: float, T: float, R_r: float,
                L_r: float, R_s: float, Lm2: float, den: float, L_r2: float) -> tuple:  # fmt: skip
    """`KubotaObserver.update` (4.20)(4.21) from the state x1 = i_s_hat, x2 = i_m and the last sample's current prev:
    (i_s_hat, i_m, e_is, omega_i, omega_hat). ``Lm2``, ``den``, ``L_r2``: `sc_matrix`'s motor terms L_m**2,
    L_r (L_m**2 - L_s L_r), L_r**2. Plain Python that numba compiles (`bench.controllers.observers_compiled` calls
    this one); a non-finite argument of its exponentials and square root gives NaN in both engines
    (`bench.controllers.kernel_math`)."""
    w = omega_hat if adapt else omega_r
    # sc_matrix(motor, w), (3.41), by its own expressions
    a11 = complex((Lm2 * R_r + R_s * L_r2) / den, 0.0)
    a12 = Lm2 * complex(-R_r, L_r * w) / den
    a21 = complex(R_r / L_r, 0.0)
    a22 = complex(-R_r / L_r, w)
    g1 = (k - 1.0) * (a11 + a22)  # kubota_gain, inlined
    det_a = a11 * a22 - a12 * a21
    g2 = ((a11 + g1) * a22 - a12 * a21 - k * k * det_a) / a12
    # M = A + G C  (C = [1 0]);  x' = M x + [b1 u - g1 i_s, -g2 i_s]
    m11, m12, m21, m22 = a11 + g1, a12, a21 + g2, a22
    # exact discretisation over one period (held u_s, i_s averaged over the period):
    # Phi = e^{MT} = e^{sT} (cosh(dT) I + sinh(dT)/d (M - sI)),  s = tr M/2,  d^2 = ((m11-m22)/2)^2 + m12 m21
    # Gam = int_0^T e^{M t} dt = M^-1 (Phi - I)
    sm = 0.5 * (m11 + m22)
    d = csqrt(0.25 * csquare(m11 - m22) + m12 * m21)
    es = cexp(sm * T)
    ch = es * ccosh(d * T)
    sh = es * (csinh(d * T) / d if abs_checked(d) > 1e-9 else complex(T, 0.0))
    p11, p12, p21, p22 = ch + sh * (m11 - sm), sh * m12, sh * m21, ch + sh * (m22 - sm)
    det = m11 * m22 - m12 * m21
    i_avg = 0.5 * (prev + i_s)
    w1 = b1 * u_s - g1 * i_avg
    w2 = -g2 * i_avg
    # Gam w = M^-1 (Phi - I) w
    v1 = (p11 - 1.0) * w1 + p12 * w2
    v2 = p21 * w1 + (p22 - 1.0) * w2
    i_s_hat = p11 * x1 + p12 * x2 + (m22 * v1 - m12 * v2) / det
    i_m = p21 * x1 + p22 * x2 + (m11 * v2 - m21 * v1) / det
    # speed adaptation (4.21)
    e = i_s - i_s_hat
    if adapt:
        drive = e.real * i_m.imag - e.imag * i_m.real  # Im{e^* i_m_hat}
        omega_i += lam * drive
        omega_hat = omega_i + lam_p * drive
    else:
        omega_hat = omega_r
    return i_s_hat, i_m, e, omega_i, omega_hat


#: the flux-observer artifact shipped with imbench: thesis 5.6.2 design (full reading), omega_r,max = 400 rad/s
#: (the rigs' over-speed limit), 3 kHz, gamma_a = 1.0014 x the independent lower bound (issue 12); made by
#: ``python3 -m bench synth flux-observer --omega-max 400 --out bench/controllers/artifacts/flux_observer_400rad_3000Hz``
LPV_ARTIFACT_DEFAULT = "flux_observer_400rad_3000Hz"


def default_lpv_artifact() -> Path:
    """Path (without suffix) of the packaged default flux-observer artifact."""
    return Path(str(resources.files("bench.controllers").joinpath("artifacts", LPV_ARTIFACT_DEFAULT)))


class LPVObserver(FluxObserver):
    """The discrete-time LPV flux observer of Sec. 5.6, loaded from a ``bench synth flux-observer`` artifact.

    The artifact is the LFT controller (5.57) with its scheduling function (5.36); its input is
    y = [i_s; u_s] (complex), its output the estimate i_m_hat, and it is scheduled by
    Delta = omega_r/omega_r,max (5.79). Per tick it is the scheduled-signal form of 5.4.4:

        z_c = C_c2 x_c + D_c21 y,   w_c = q(Delta) z_c,   q = Delta_c/(1 - D_c22 Delta_c)   (5.36)
        i_m_hat = C_c1 x_c + D_c11 y + D_c12 w_c,   x_c <- A_c x_c + B_c1 y + B_c2 w_c    (5.63)(5.64)

    With the complex-formed design (5.6.2) Delta_c, D_c22 and so q are complex scalars, and for a
    real scalar Delta, (5.36) is a ratio of two quadratics in Delta; their coefficients are computed
    once at load, so the scheduling costs one complex division per tick, as the thesis notes.
    Everything else is complex scalar arithmetic on the order-2 state.

    Timing: the design is a bilinear (Tustin) discretisation whose inputs are *samples* of i_s and
    u_s at t_k. i_s(t_k) is one. The voltage u_k held over [t_{k-1}, t_k) (observers' convention,
    module docstring) is the value of the fundamental at the middle of that period, half a period
    before t_k, so by default (``u_extrapolate`` = 1) the observer is fed the linear extrapolation
    u(t_k) ~ 1.5 u_k - 0.5 u_{k-1}. Fed u_k itself, the trapezoidal integral inside the design lags
    the true one by T_s u_k / 2: at start-up (307 V, no flux yet) that is a flux error of
    (L_r/L_m^2) T_s u / 2 ~ 0.15 A against the voltage, larger than the flux itself, and the
    FOC trips within 15 ms (measured, docs/RESULTS.md and tests/test_lpv_observer.py).

    Speed beyond the design range: |omega_r| > omega_r,max is outside the range the design
    guarantees anything for, so Delta is clipped to [-1, 1] (the observer then rotates with
    omega_r,max); ``clipped`` counts the ticks where that happened. Clipping is wrong by far at speed
    (measured on an exactly sampled motor, |i_m| = 2.9 A, with the former 200 rad/s design: 0.86 A RMS
    at 250 rad/s, 1.17 A at 297 rad/s; `synthesis.models.flux_observer.flux_error_at_speed`), so a rig
    whose over-speed limit exceeds omega_r,max is refused at session start (`FocController`), and the
    packaged design covers 400 rad/s (4.9 mA at 250, 7.2 mA at 297 rad/s).

    ``artifact`` is the artifact path without suffix ("" = the packaged default). An artifact whose
    sampling period is not the loop's, whose motor data differ from the controller's nominal
    model, or which is not a flux observer is a `BadInput`.
    """

    name = "lpv"
    stator_states = ("x1", "x2", "i_m", "_u_prev")
    summary = "LPV observer (5.6): synthesised, scheduled by omega_r/omega_r,max, loaded from an artifact"
    schema: ClassVar[dict[str, Param]] = {
        "artifact": Param("", "artifact path without suffix ('' = the packaged 5.6.2 design)"),
        "u_extrapolate": Param(1.0, "1: feed 1.5 u_k - 0.5 u_(k-1) (the held voltage extrapolated to t_k); "
                               "0: the held voltage", choices=(0.0, 1.0)),
    }
    FIELD = "lpv_artifact"  # the parameter name users give (``-p lpv_artifact=PATH``)

    def __init__(self, motor: MotorParams, T_s: float, **params: Any) -> None:
        super().__init__(motor, T_s, **params)

        path = Path(self.p["artifact"]) if self.p["artifact"] else default_lpv_artifact()
        try:
            ctrl, doc = load_controller(path)
        except (ArtifactError, OSError, KeyError, ValueError) as exc:
            raise BadInput(self.FIELD, f"cannot load flux-observer artifact {path}: {exc}") from None
        meta = doc.get("meta", {})
        K, S = ctrl.K, ctrl.scheduling
        sizes = (K.n_y, K.n_u, K.n_wc, K.n_zc, S.n_wu, S.n_zu, len(S.lam))
        if meta.get("design") != "flux_observer" or sizes != (2, 1, 1, 1, 1, 1, 2) or not S.lam[0] < 0 < S.lam[1]:
            raise BadInput(self.FIELD, f"{path} is not a flux-observer artifact (made by `bench synth flux-observer`)")
        dt = float(doc["dt"])
        if abs(dt - T_s) > 1e-9 * T_s:
            raise BadInput(self.FIELD, f"artifact {path.name} runs at {1.0 / dt:g} Hz but the loop at {1.0 / T_s:g} Hz; "
                                       f"make one with `bench synth flux-observer --rate {1.0 / T_s:g}`")  # fmt: skip
        diff = motor_mismatch(meta, motor)
        if diff:
            raise BadInput(self.FIELD, f"artifact {path.name} was designed for other motor data ({', '.join(diff)} differ "
                                       "from the rig's nominal model); make one with `bench synth flux-observer --rig "
                                       f"RIG --rate {1.0 / T_s:g} --out PATH`, then -p lpv_artifact=PATH")  # fmt: skip
        self.path, self.doc = path, doc
        self.omega_r_max = float(meta["omega_r_max"])
        self._inv_wmax = 1.0 / self.omega_r_max
        self._extrap = bool(self.p["u_extrapolate"])
        c = lambda M, i, j: complex(M[i, j])  # noqa: E731
        A, B1, B2 = K.A_c, K.B_c1, K.B_c2
        C1, D11, D12, C2, D21, D22 = K.C_c1, K.D_c11, K.D_c12, K.C_c2, K.D_c21, K.D_c22
        if K.n_c > 2:
            raise BadInput(self.FIELD, f"{path} has order {K.n_c}; the runtime handles order <= 2")
        # pad to order 2 (an order-1 or static design then carries zero rows/columns)
        def at(M, i, j):  # noqa: ANN001, ANN202
            return c(M, i, j) if i < M.shape[0] and j < M.shape[1] else 0j
        self._A = (at(A, 0, 0), at(A, 0, 1), at(A, 1, 0), at(A, 1, 1))
        self._B1 = (at(B1, 0, 0), at(B1, 0, 1), at(B1, 1, 0), at(B1, 1, 1))
        self._B2 = (at(B2, 0, 0), at(B2, 1, 0))
        self._C1 = (at(C1, 0, 0), at(C1, 0, 1), c(D11, 0, 0), c(D11, 0, 1), c(D12, 0, 0))
        self._C2 = (at(C2, 0, 0), at(C2, 0, 1), c(D21, 0, 0), c(D21, 0, 1))
        self._num, self._den = _scheduling_polynomials(S.P, S.U, S.lam, complex(D22[0, 0]))
        self.reset()

    def reset(self) -> None:
        self.x1 = self.x2 = 0j
        self.i_m = 0j
        self.delta = 0.0
        self.clipped = 0
        self._u_prev: complex | None = None

    def take_over(self, i_m: complex, i_s: complex, u_s: complex, omega_r: float, omega_e: float) -> None:
        # the state nearest to the frozen observer's sinusoidal steady state at this speed (inputs turning at
        # omega_e, z = e^{j omega_e T}) that continues the estimate i_m, (5.63)(5.64) with Delta frozen
        d = min(max(omega_r * self._inv_wmax, -1.0), 1.0)
        n2, n1, n0 = self._num
        e2, e1, e0 = self._den
        q = ((n2 * d + n1) * d + n0) / ((e2 * d + e1) * d + e0)
        a11, a12, a21, a22 = self._A
        b11, b12, b21, b22 = self._B1
        c1, c2, d1, d2, d12 = self._C1
        f1, f2, g1, g2 = self._C2
        A = np.array([[a11, a12], [a21, a22]]) + q * np.outer(self._B2, [f1, f2])
        B = np.array([[b11, b12], [b21, b22]]) + q * np.outer(self._B2, [g1, g2])
        C = np.array([c1, c2]) + d12 * q * np.array([f1, f2])
        D = np.array([d1, d2]) + d12 * q * np.array([g1, g2])
        # the stored state is the next tick's: its inputs and estimate are this tick's turned by z
        z = cmath.exp(1j * omega_e * self.T_s)
        y = z * np.array([i_s, u_s])
        x = np.linalg.solve(z * np.eye(2) - A, B @ y)
        x = x + C.conj() * ((z * i_m - C @ x - D @ y) / (C @ C.conj()))  # minimum-norm move to the estimate
        self.x1, self.x2 = complex(x[0]), complex(x[1])
        self.i_m, self._u_prev, self.delta = i_m, u_s, d

    def update(self, i_s: complex, u_s: complex, omega_r: float) -> complex:
        u_prev = self._u_prev
        self.i_m, self.x1, self.x2, self.delta, clipped = lpv_observer_step(
            i_s, u_s, omega_r, u_s if u_prev is None else u_prev, self._extrap, self._inv_wmax, self.x1, self.x2,
            self._num, self._den, self._C1, self._C2, self._A, self._B1, self._B2)  # fmt: skip
        if self._extrap:
            self._u_prev = u_s
        self.clipped += clipped
        return self.i_m


def lpv_observer_step(i_s: complex, u_s: complex, omega_r: float, u_prev: complex, extrap: bool, inv_wmax: float,
                      x1: complex, x2: complex, num: tuple, den: tuple, C1: tuple, C2: tuple, A: tuple, B1: tuple,
                      B2: tuple) -> tuple[complex, complex, complex, float, bool]:  # fmt: skip
    """`LPVObserver.update` (5.36)(5.63)(5.64) from the state (x1, x2), with u_prev the last tick's voltage (this
    one's on the first tick): (i_m, x1, x2, Delta, clipped). Plain Python that numba compiles
    (`bench.controllers.observers_compiled` calls this one)."""
    if extrap:  # the held voltage extrapolated to t_k
        u_s = 1.5 * u_s - 0.5 * u_prev
    d = omega_r * inv_wmax  # Delta (5.79)
    clipped = d > 1.0 or d < -1.0
    if clipped:
        d = 1.0 if d > 0.0 else -1.0
    n2, n1, n0 = num
    e2, e1, e0 = den
    q = ((n2 * d + n1) * d + n0) / ((e2 * d + e1) * d + e0)  # Delta_c/(1 - D_c22 Delta_c), (5.36)
    c1, c2, d1, d2, d12 = C1
    wc = q * (C2[0] * x1 + C2[1] * x2 + C2[2] * i_s + C2[3] * u_s)
    i_m = c1 * x1 + c2 * x2 + d1 * i_s + d2 * u_s + d12 * wc
    a11, a12, a21, a22 = A
    b11, b12, b21, b22 = B1
    return (i_m, a11 * x1 + a12 * x2 + b11 * i_s + b12 * u_s + B2[0] * wc,
            a21 * x1 + a22 * x2 + b21 * i_s + b22 * u_s + B2[1] * wc, d, clipped)


def _scheduling_polynomials(P: np.ndarray, U: np.ndarray, lam: np.ndarray, D22: complex
                            ) -> tuple[tuple[complex, ...], tuple[complex, ...]]:  # fmt: skip
    """Coefficients (highest power first) of num(d), den(d) with Delta_c/(1 - D22 Delta_c) = num/den.

    (5.36) for scalar channels, S(d) = [d; 1], d real: v = S^T U = d U[0, :] + U[1, :],
    Delta_c = n_- conj(v_-) v_+ / (S^T P S - n_- |v_-|^2), with n_- the negative eigenvalue of N.
    Both are quadratics in d; closing w_c = Delta_c (z_c + D22 w_c) gives num/(den - D22 num).
    """
    (a, c), (b, e) = (complex(U[0, 0]), complex(U[0, 1])), (complex(U[1, 0]), complex(U[1, 1]))
    n_m = float(lam[0])
    # conj(v_-) v_+ = conj(a d + b)(c d + e)
    num = (n_m * a.conjugate() * c, n_m * (a.conjugate() * e + b.conjugate() * c), n_m * b.conjugate() * e)
    sps = (complex(P[0, 0]), 2.0 * complex(P[0, 1]).real, complex(P[1, 1]))  # S^T P S, P Hermitian
    vv = (abs(a) ** 2, 2.0 * (a.conjugate() * b).real, abs(b) ** 2)  # |v_-|^2
    den = tuple(s - n_m * v - D22 * nn for s, v, nn in zip(sps, vv, num))
    return num, den


OBSERVERS: dict[str, type[FluxObserver]] = {
    cls.name: cls
    for cls in (CurrentModelObserver, VoltageModelObserver, JansenLorenzObserver, KubotaObserver, LPVObserver)
}
