"""On-line rotor-resistance estimation: the reactive-power MRAS, a part of the FOC (``-p rr_adapt=mras``).

Why R_r: thesis 3.4 - the rotor resistance rises up to 50 % as the rotor warms, slowly, and every part
that uses it (the current model (4.15), the slip (4.5), the decoupling (4.13), Kubota's observer (4.20)
and the rotor-equation speed (4.19)) is detuned by it. Why this method: the reactive power does not
depend on R_s (the stator resistance drops out of Im{u_s i_s^*}), needs no signal injection and no
extra state beyond a current model, and is what drives use in practice. It needs the measured speed:
R_r and the speed are not both observable from the fundamental in steady state, so the FOC refuses it
when sensorless.

Stator equation (3.34) with psi_s = L'_s i_s + L'_m i_m (4.1):  u_s = R_s i_s + L'_s di_s/dt + L'_m di_m/dt,
so the reactive power, corrected for the leakage term, is free of R_s:

    Q_ref = Im{u_s i_s^*} - L'_s Im{di_s/dt i_s^*}        (reference model: measured quantities)
    Q_adj = L'_m Im{di_m_hat/dt i_s^*}                    (adjustable model: the current-model flux (4.15)
                                                           with the estimate R_r_hat)

Discretely, over the period [t_{k-1}, t_k) in which u_s is held, both models are exact identities of the
stator equation integrated over the period, weighted with the period's mean current i_av (u_s held, so
Im{u_s i_av^*} is the period's mean reactive power, and the R_s term R_s |i_av|^2 is real and drops out):

    Q_ref = Im{u_s i_av^*} - L'_s Im{(i_k - i_{k-1}) i_av^*}/T,   Q_adj = L'_m Im{(i_m,k - i_m,k-1) i_av^*}/T

The current is not linear between samples: the voltage is held while the back-EMF turns, so i_s bows by
d^2 i_s/dt^2 = -(L'_m d^2 i_m/dt^2 + R_s di_s/dt)/L'_s, and its mean is i_av = (i_k + i_{k-1})/2 -
(T^2/12) d^2 i_s/dt^2 (a parabola). Fed with the chord mid-point instead, the current model's flux is about
0.8 % high at 250 rad/s (measured, the FOC's own current-model observer), which at light load would bias
R_r by several per cent; the estimator therefore runs its own current model (4.15) on i_av (R_s nominal:
its term is 6 % of a 1 % correction).

Adaptation law: a normalised gradient on b = R_r/L_r. In steady state, with r = i_sq/i_mR (the slip
times T_r, (4.5)), Q = L'_m omega_e |i_s|^2/(1 + r^2 (b_hat/b)^2), so d ln Q / d ln b = 2 r^2/(1 + r^2) at
b_hat = b, and

    d ln b_hat/dt = gain (Q_ref - Q_adj)/Q_adj (1 + r^2)/(2 r^2)

converges at the rate ``gain`` [1/s] whatever the operating point, where it is allowed to run. Q_ref - Q_adj,
Q_adj and r^2 enter low-pass filtered (``FILTER_TAU``): the per-tick values fluctuate together (torque ripple,
current noise), and the mean of their per-tick ratio is not the ratio of their means (measured: unfiltered,
the estimate settled 6-12 % high at 30 rad/s and 2 N m, where the mean errors balance at the true R_r).

Gating (the estimate is frozen, and ``rr_gate`` on /ctrl says why, as a sum of bits):
    1  |omega_mR| < w_min: stator frequency too low (standstill, DC steady state; Q -> 0)
    2  |i_sq| < iq_min: no load, zero slip (d Q / d b -> 0)
    4  the current controller is at its voltage limit (the reference voltage is not the applied one); open again
       on the first tick off it. A stale estimate below the true R_r over-excites the motor, which can hold the
       loop at the limit for good near rated speed: the FOC's field weakening (`bench.controllers.foc.FieldWeakening`,
       on with this estimate) lowers the flux until the loop is off it
    8  |i_mR_hat| < imr_min: no flux yet
   16  a non-finite or degenerate quantity (never enters the estimate)
The estimate moves only after the gate has been open for ``3 FILTER_TAU`` (the filters have caught up), and
not within 5 T_r of the own model starting from zero flux (at reset, or after a non-finite input); an
open gate closes only at ``HYSTERESIS`` (80 %) of w_min and iq_min, so it does not flicker at a threshold.
Bounds: 0.5-2.5 x the nominal R_r, at most 1 % per tick, and the normalisation uses r >= 0.1 (``R2_MIN``: with
``iq_min`` = 0, no load gate, the gain stays finite); the estimate is never NaN.
"""

from __future__ import annotations

import cmath
import math
from typing import Any

import numpy as np

from bench.controllers.kernel_math import square
from bench.controllers.observers import turn
from bench.controllers.schema import Param
from bench.params import MotorParams
from bench.core.slots import new_array, slots, with_views

__all__ = ["RR_MIN", "RR_MAX", "RrMRAS", "SCHEMA", "S", "mras_update"]

RR_MIN, RR_MAX = 0.5, 2.5  # bounds of the estimate, times the nominal R_r

GATE_FREQ, GATE_LOAD, GATE_VLIM, GATE_FLUX, GATE_BAD = 1, 2, 4, 8, 16
HYSTERESIS = 0.8  # an open gate closes at this fraction of w_min and iq_min (no flicker at a threshold)
FILTER_TAU = 0.02  # [s] low-pass of the error, Q_adj and r^2 (module docstring); 6 % of the default 1/gain
R2_MIN = 0.01  # r^2 in the normalisation never below this (r = 0.1): with iq_min = 0 the gain stays finite
MAX_STEP = 0.01  # the estimate never moves more than 1 % in one tick (30 %/10 ms; the default moves ~0.01 %)

#: the FOC's parameters of the adaptation (``rr_adapt`` chooses it; the others tune it)
SCHEMA: dict[str, Param] = {
    "rr_adapt": Param("off", "on-line R_r estimate (reactive-power MRAS, Sec. 3.4) feeding every part that uses "
                      "R_r; off: the nominal R_r", choices=("off", "mras")),
    "rr_gain": Param(3.0, "R_r adaptation rate (normalised: the estimate's error decays at this rate)", "1/s",
                     gt=0, le=100, tunable=True),
    "rr_w_min": Param(20.0, "R_r adaptation frozen below this stator frequency omega_mR (in magnitude): "
                      "standstill, DC", "rad/s", ge=0, le=1000, tunable=True),
    "rr_iq_min": Param(0.8, "R_r adaptation frozen below this i_sq (in magnitude): no load, R_r not "
                       "observable", "A", ge=0, le=100, tunable=True),
    "rr_init": Param(1.0, "R_r estimate at start, times the nominal R_r; setting it while running resets the "
                     "estimate to it", ge=RR_MIN, le=RR_MAX, tunable=True),
}  # fmt: skip


#: the estimator's array: its constants, tunables and state by name (`bench.core.slots`); the Python engine runs
#: `mras_update` on the estimator's own array, the compiled FOC on a region of its buffer that the estimator views
S = slots("RrMRASSlots",
          T="f", _inv_T="f", Ls_p="f", Lm_p="f", R_s="f", L_r="f", _bow="f", _alpha="f", _settle="i", _restart="i",
          two="f",  # 2.0, the exponent of r ** 2 given at run time (bench.controllers.kernel_math.square)
          b_nom="f", b_lo="f", b_hi="f", gain="f", w_min="f", iq_min="f", init="f", imr_min="f",  # bounds, tunables
          b="f", gate="i", i_m="c", _i_prev="?c", _t_prev="f", q_ref="f", q_adj="f",  # the estimate, the model
          _e_f="f", _q_f="f", _r2_f="f", _open="i", _warm="i")  # filters, counters  # fmt: skip


@with_views(S, logged=("b", "gate"))  # (the compiled FOC logs R_r and the gate from its buffer)
class RrMRAS:
    """Reactive-power MRAS estimate of R_r (module docstring). ``update`` once per base tick after the
    flux observer; ``R_r`` and ``b`` (= R_r/L_r) are the estimate, ``gate`` the freeze bits. Its numbers live in
    the array ``s`` (`S`), shown as attributes."""

    def __init__(self, motor: MotorParams, T_s: float, gain: float, w_min: float, iq_min: float, init: float,
                 imr_min: float = 0.5) -> None:  # fmt: skip
        self.s = new_array(S)
        self.motor = motor
        self.T = T_s
        self._inv_T = 1.0 / T_s
        self.Ls_p, self.Lm_p, self.R_s, self.L_r = motor.Ls_p, motor.Lm_p, motor.R_s, motor.L_r
        self._bow = T_s * T_s / 12.0 / motor.Ls_p  # i_av = i_mid + (T^2/12)(L'_m d2i_m + R_s di)/L'_s
        self._alpha = 1.0 - math.exp(-T_s / FILTER_TAU)
        self._settle = int(math.ceil(3.0 * FILTER_TAU / T_s))  # ticks the gate is open before the estimate moves
        self._restart = int(math.ceil(5.0 * motor.T_r / T_s))  # ticks the own model needs after starting from 0
        self.two = 2.0
        self.b_nom = motor.R_r / motor.L_r
        self.b_lo, self.b_hi = RR_MIN * self.b_nom, RR_MAX * self.b_nom
        self.gain, self.w_min, self.iq_min, self.init = gain, w_min, iq_min, init
        self.imr_min = imr_min
        self.reset()

    def _logged(self) -> None:
        """A logged value was set from outside (the compiled FOC refreshes its row here)."""

    def view(self, region: np.ndarray | None, logged: Any = None) -> None:
        """Keep the numbers in ``region`` (a slice of another array, e.g. the compiled FOC's buffer) from now on;
        ``logged`` is called after a logged value is set from outside. None: back to an array of its own."""
        if region is None:
            if isinstance(self.s, np.ndarray):
                self.s = self.s.tolist()
            self.__dict__.pop("_logged", None)
            return
        region[:] = np.asarray(self.s, dtype=float)
        self.s = region
        if logged is not None:
            self._logged = logged  # type: ignore[method-assign]

    def rotate(self, e: complex) -> None:
        """Turn the own current model's stator-fixed states by ``e`` after a stall the drive rode through
        (`bench.controllers.observers.FluxObserver.rotate`)."""
        turn(self, ("i_m", "_i_prev"), e)

    def reset(self) -> None:
        """Estimate back to ``init`` x nominal, the model's memory cleared."""
        self.set_estimate(self.init)
        self._i_prev = None
        self._t_prev = 0.0
        self.i_m = 0j  # the estimator's own current model (4.15), fed with the period's mean current
        self.gate = GATE_FREQ
        self.q_ref = self.q_adj = 0.0
        self._e_f = self._q_f = self._r2_f = 0.0  # filtered Q_ref - Q_adj, Q_adj, r^2
        self._open = 0  # ticks since the gate opened
        self._warm = self._restart  # ticks until the own model has built up its flux (from zero)

    def set_estimate(self, factor: float) -> None:
        """Put the estimate at ``factor`` x the nominal R_r (clipped to the bounds)."""
        b = factor * self.b_nom
        self.b = self.b_lo if not b >= self.b_lo else self.b_hi if b > self.b_hi else b

    @property
    def R_r(self) -> float:
        """The estimate [Ohm]."""
        return self.b * self.motor.L_r

    def update(self, t: float, i_s: complex, u_s: complex, omega_r: float, omega_mR: float, i_sq: float, i_mR: float,
               saturated: bool) -> bool:  # fmt: skip
        """One tick: ``i_s`` at t_k = ``t``, ``u_s`` held over [t_{k-1}, t_k), ``omega_r`` the speed over that period
        (the encoder's), and the FOC's ``omega_mR``, ``i_sq``, ``i_mR`` (flux frame) and voltage-limit flag.
        Returns True if the estimate changed. A tick that does not follow the last one by one period (a real-time
        loop that skipped ticks) advances the model over the gap and is not used (``GATE_BAD``)."""
        return mras_update(self.s, t, i_s, u_s, omega_r, omega_mR, i_sq, i_mR, saturated)


def mras_update(s: Any, t: float, i_s: complex, u_s: complex, omega_r: float, omega_mR: float, i_sq: float,
                i_mR: float, saturated: bool) -> bool:  # fmt: skip
    """`RrMRAS.update` on the estimator's array ``s`` (`S`). Plain Python that numba compiles: the compiled FOC tick
    (`bench.controllers.foc_compiled`) calls this one on its buffer. (Reads go through float() and int(): Python
    values in the Python engine, so its complex arithmetic is CPython's, not numpy's.)"""
    has_prev, i_prev, t_prev = s[S.i_prev] != 0.0, complex(s[S.i_prev + 1], s[S.i_prev + 2]), float(s[S.t_prev])
    s[S.i_prev], s[S.i_prev + 1], s[S.i_prev + 2], s[S.t_prev] = 1.0, i_s.real, i_s.imag, t
    if not has_prev:
        s[S.gate] = GATE_BAD
        return False
    T, b, im0 = float(s[S.T]), float(s[S.b]), complex(s[S.i_m], s[S.i_m + 1])
    a = complex(-b, omega_r)
    h = t - t_prev
    if not 0.5 * T < h < 1.5 * T:  # skipped ticks: the model crosses the gap on the mean current
        im1 = cmath.exp(a * h) * im0 + (cmath.exp(a * h) - 1.0) / a * b * 0.5 * (i_s + i_prev) if h > 0 else im0
        if not (im1.real == im1.real and im1.imag == im1.imag):
            im1 = 0j
        s[S.i_m], s[S.i_m + 1] = im1.real, im1.imag
        s[S.gate], s[S.open] = GATE_BAD, 0
        return False
    i_av, im1, warm = own_model(s, i_s, i_prev, a, b, im0, T)
    # the models and their filters run on every tick, gated or not
    c = i_av.conjugate()
    inv_T = float(s[S.inv_T])
    q_ref = (u_s * c).imag - float(s[S.Ls_p]) * ((i_s - i_prev) * c).imag * inv_T  # R_s-free, leakage removed
    q_adj = float(s[S.Lm_p]) * ((im1 - im0) * c).imag * inv_T
    r2 = square(i_sq / i_mR, float(s[S.two])) if i_mR > 0.0 else 0.0
    if not (math.isfinite(q_ref) and math.isfinite(q_adj) and math.isfinite(r2)):
        s[S.gate], s[S.open] = GATE_BAD, 0
        return False
    s[S.q_ref], s[S.q_adj] = q_ref, q_adj
    al = float(s[S.alpha])
    e_f = float(s[S.e_f])
    e_f += al * (q_ref - q_adj - e_f)
    q_f = float(s[S.q_f])
    q_f += al * (q_adj - q_f)
    r2_f = float(s[S.r2_f])
    r2_f += al * (r2 - r2_f)
    s[S.e_f], s[S.q_f], s[S.r2_f] = e_f, q_f, r2_f
    gate = gates(s, omega_mR, i_sq, i_mR, saturated)
    s[S.gate] = gate
    if gate:
        s[S.open] = 0
        return False
    n_open = int(s[S.open]) + 1
    s[S.open] = n_open
    if n_open < int(s[S.settle]) or warm:
        return False
    r2_f = R2_MIN if not r2_f >= R2_MIN else r2_f
    # normalised gradient step on ln b (module docstring); |Q_adj| ~ L'_m omega_mR i_mR^2 is far from 0 here
    step = float(s[S.gain]) * T * e_f / q_f * (1.0 + r2_f) / (2.0 * r2_f) if q_f != 0.0 else math.nan
    if not math.isfinite(step):
        s[S.gate], s[S.open] = GATE_BAD, 0
        return False
    step = MAX_STEP if step > MAX_STEP else -MAX_STEP if step < -MAX_STEP else step
    b = b * (1.0 + step)
    lo, hi = float(s[S.b_lo]), float(s[S.b_hi])
    s[S.b] = lo if not b >= lo else hi if b > hi else b
    return True


def own_model(s: Any, i_s: complex, i_prev: complex, a: complex, b: float, im0: complex, T: float
              ) -> tuple[complex, complex, int]:  # fmt: skip
    """The estimator's own current model (4.15) over the period, exact for omega_r held (a = -b + j omega_r) and
    the input at the period's mean current i_av: (i_av, i_m at this sample, ticks still to warm up), i_m and the
    count stored in ``s``. A NaN restarts the model from zero flux, and the estimate waits until it has built up."""
    inv_T = float(s[S.inv_T])
    phi = cmath.exp(a * T)
    i_mid = 0.5 * (i_s + i_prev)
    di = (i_s - i_prev) * inv_T
    d2im = a * (a * im0 + b * i_mid) + b * di  # d^2 i_m/dt^2 of (4.15)
    i_av = i_mid + float(s[S.bow]) * (float(s[S.Lm_p]) * d2im + float(s[S.R_s]) * di)
    im1 = phi * im0 + (phi - 1.0) / a * b * i_av
    warm = int(s[S.warm])
    if im1.real == im1.real and im1.imag == im1.imag:
        s[S.i_m], s[S.i_m + 1] = im1.real, im1.imag
    else:  # never NaN
        s[S.i_m], s[S.i_m + 1] = 0.0, 0.0
        warm = int(s[S.restart])
    if warm:
        warm -= 1
    s[S.warm] = warm
    return i_av, im1, warm


def gates(s: Any, omega_mR: float, i_sq: float, i_mR: float, saturated: bool) -> int:
    """The freeze bits of this tick (module docstring); an open gate closes 20 % below the thresholds."""
    gate = 0
    hyst = HYSTERESIS if s[S.gate] == 0.0 else 1.0
    if not abs(omega_mR) >= hyst * float(s[S.w_min]):
        gate |= GATE_FREQ
    if not abs(i_sq) >= hyst * float(s[S.iq_min]):
        gate |= GATE_LOAD
    if saturated:
        gate |= GATE_VLIM
    if not i_mR >= float(s[S.imr_min]):
        gate |= GATE_FLUX
    return gate
