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

Discretely, over the period [t_{k-1}, t_k) in which u_s is held: i_s^* at the mid-point
(i_k + i_{k-1})/2, Im{di_s/dt i_s^*} = Im{i_k i_{k-1}^*}/T, di_m/dt = (i_m,k - i_m,k-1)/T (the current
model is exact for that period, so both models see the same interval).

Adaptation law: a normalised gradient on b = R_r/L_r. In steady state, with r = i_sq/i_mR (the slip
times T_r, (4.5)), Q = L'_m omega_e |i_s|^2/(1 + r^2 (b_hat/b)^2), so d ln Q / d ln b = 2 r^2/(1 + r^2) at
b_hat = b, and

    d ln b_hat/dt = gain (Q_ref - Q_adj)/Q_adj (1 + r^2)/(2 r^2)

converges at the rate ``gain`` [1/s] whatever the operating point, where it is allowed to run:

Gating (the estimate is frozen, and ``rr_gate`` on /ctrl says why, as a sum of bits):
    1  |omega_mR| < w_min: stator frequency too low (standstill, DC steady state; Q -> 0)
    2  |i_sq| < iq_min: no load, zero slip (d Q / d b -> 0)
    4  the current controller is at its voltage limit (the reference voltage is not the applied one)
    8  |i_mR_hat| < imr_min: no flux yet
   16  a non-finite or degenerate quantity (never enters the estimate)
Bounds: 0.5-2.5 x the nominal R_r; the estimate is never NaN.
"""

from __future__ import annotations

import math

from bench.controllers.schema import Param
from bench.params import MotorParams

__all__ = ["RR_MIN", "RR_MAX", "RrMRAS", "SCHEMA"]

RR_MIN, RR_MAX = 0.5, 2.5  # bounds of the estimate, times the nominal R_r

GATE_FREQ, GATE_LOAD, GATE_VLIM, GATE_FLUX, GATE_BAD = 1, 2, 4, 8, 16

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


class RrMRAS:
    """Reactive-power MRAS estimate of R_r (module docstring). ``update`` once per base tick after the
    flux observer; ``R_r`` and ``b`` (= R_r/L_r) are the estimate, ``gate`` the freeze bits."""

    def __init__(self, motor: MotorParams, T_s: float, gain: float, w_min: float, iq_min: float, init: float,
                 imr_min: float = 0.5) -> None:  # fmt: skip
        self.motor, self.T = motor, T_s
        self._inv_T = 1.0 / T_s
        self.Ls_p, self.Lm_p = motor.Ls_p, motor.Lm_p
        self.b_nom = motor.R_r / motor.L_r
        self.b_lo, self.b_hi = RR_MIN * self.b_nom, RR_MAX * self.b_nom
        self.gain, self.w_min, self.iq_min, self.init = gain, w_min, iq_min, init
        self.imr_min = imr_min
        self.reset()

    def reset(self) -> None:
        """Estimate back to ``init`` x nominal, the model's memory cleared."""
        self.set_estimate(self.init)
        self._i_prev: complex | None = None
        self._im_prev: complex | None = None
        self.gate = GATE_FREQ
        self.q_ref = self.q_adj = 0.0

    def set_estimate(self, factor: float) -> None:
        """Put the estimate at ``factor`` x the nominal R_r (clipped to the bounds)."""
        b = factor * self.b_nom
        self.b = self.b_lo if not b >= self.b_lo else self.b_hi if b > self.b_hi else b

    @property
    def R_r(self) -> float:
        """The estimate [Ohm]."""
        return self.b * self.motor.L_r

    def update(self, i_s: complex, u_s: complex, i_m: complex, omega_mR: float, i_sq: float, i_mR: float,
               saturated: bool) -> bool:  # fmt: skip
        """One tick: ``i_s`` at t_k, ``u_s`` held over [t_{k-1}, t_k), ``i_m`` the current model's i_m at t_k
        (computed with the present estimate), ``omega_mR``, ``i_sq``, ``i_mR`` the FOC's flux-frame values.
        Returns True if the estimate changed."""
        i_prev, im_prev = self._i_prev, self._im_prev
        self._i_prev, self._im_prev = i_s, i_m
        gate = 0
        if not abs(omega_mR) >= self.w_min:
            gate |= GATE_FREQ
        if not abs(i_sq) >= self.iq_min:
            gate |= GATE_LOAD
        if saturated:
            gate |= GATE_VLIM
        if not i_mR >= self.imr_min:
            gate |= GATE_FLUX
        if i_prev is None:
            gate |= GATE_BAD
        if gate:
            self.gate = gate
            return False
        inv_T = self._inv_T
        i_mid = 0.5 * (i_s + i_prev)
        c = i_mid.conjugate()
        q_ref = (u_s * c).imag - self.Ls_p * (i_s * i_prev.conjugate()).imag * inv_T  # R_s-free, leakage removed
        q_adj = self.Lm_p * ((i_m - im_prev) * c).imag * inv_T
        self.q_ref, self.q_adj = q_ref, q_adj
        r2 = (i_sq / i_mR) ** 2
        # normalised gradient step on ln b (module docstring); q_adj ~ L'_m omega_mR i_mR^2 is far from 0 here
        step = self.gain * self.T * (q_ref - q_adj) / q_adj * (1.0 + r2) / (2.0 * r2) if q_adj != 0.0 else math.nan
        if not math.isfinite(step):
            self.gate = GATE_BAD
            return False
        step = 0.1 if step > 0.1 else -0.1 if step < -0.1 else step  # one tick never moves it more than 10 %
        b = self.b * (1.0 + step)
        self.b = self.b_lo if not b >= self.b_lo else self.b_hi if b > self.b_hi else b
        self.gate = 0
        return True
