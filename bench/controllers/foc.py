"""Rotor-flux-oriented speed control with encoder feedback (thesis Sec. 4.2, Fig. 4.1).

Signal path of one tick, top-down:

    encoder count -> EncoderSpeed -> omega_hat
    i_s, u_s, omega_hat -> flux observer (4.15) -> i_m_hat -> rho = angle(i_m_hat), i_mR_hat = |i_m_hat|
    omega_ref - omega_hat -> SpeedPI -> m_e_ref (limited by (4.8)) -> i_sq_ref (4.7)
    i_mR_ref -> FluxP (premultiplied by (K_m+1)/K_m) -> i_sd_ref
    i_sr_ref - i_s e^{-j rho} -> CurrentPI + decoupling (4.13)(4.14) -> u_sr -> u_s_ref = u_sr e^{j rho}

Each part is its own small class so that later work can swap the observer, the speed controller or
the current controller. Parts may run at an integer divisor of the base rate.

Tuning (documented defaults, for the nominal motor (3.57) and J = 0.0125 kg m^2):
- current PI: pole-zero cancellation of the decoupled plant 1/(R_s + L'_s s): K_p = L'_s w_cc,
  T_i = L'_s / R_s, w_cc = 1000 rad/s. With 1.5 samples of effective delay at 3 kHz this leaves
  about 60 deg phase margin.
- magnetising current: P gain K_m = 4, i.e. closed-loop pole (1+K_m)/T_r = 47 rad/s (4.4).
- speed PI: crossover w_s = K_p Z_p / J ~ 100 rad/s -> K_p = 0.6 N m s/rad, T_i = 0.04 s; the
  encoder speed is low-pass filtered with tau = 3 ms (16 deg lag at crossover). Its load-step dips on
  the mock rig: docs/results/bench-core.md 1.2.
- `bench tune speed` (bench/workflows/tuning.py) runs the thesis' relay-feedback experiment and suggests a
  Ziegler-Nichols speed PI (faster load rejection, more ringing; docs/results/bench-core.md 1.5).
- the voltage reference is rotated by 1.5 periods of omega_mR to compensate the computation delay
  plus the zero-order hold (not in the thesis; set delay_comp = 0 to switch off).

Current controller: ``current_controller = "pi"`` (default, above) or ``"lpv"``, the quasi-LPV
controller of thesis 6.2 (`bench.controllers.lpv_current`), loaded from the artifact for
``lpv_current_rate`` (600 or 3000 Hz) or ``lpv_current_artifact``; it runs at the artifact's rate (the
current divisor follows from it). A current loop slower than the base rate (LPV, or the PI with
``current_divisor`` > 1) holds its voltage in the rotor-flux frame between updates.

Speed controller: ``speed_controller = "pi"`` (default, above) or ``"lpv"``, the LPV speed controller of
thesis 6.4.3 / 7.2 (`bench.controllers.lpv_speed`) from ``lpv_speed_artifact`` (shipped "nominal",
"robust", "nominal_3000Hz", or a path); it runs at the artifact's rate, on the encoder speed through the
model's 100 Hz data filter (which replaces ``speed_filter_tau``), and logs its scheduling (``lpv_*`` fields).

Field weakening (``field_weakening``, `FieldWeakening`; on with the R_r estimate, else off by default): once the
current loop has reached its voltage limit, an integrator on the voltage use |u_sr|/u_max scales the i_mR
reference down until the loop holds ``fw_u`` of the limit, and back up to the full reference when the voltage
allows (thesis 4.2.2 names the need above rated speed and leaves it out). Until the limit is first reached the
reference is untouched, to the bit.

Observers and sensorless mode (Secs 4.3-4.4, 5.6.3):
- ``observer`` picks the flux observer from `bench.controllers.observers.OBSERVERS`; its parameters
  appear here as ``<observer>_<parameter>`` (e.g. ``jl_K1_re``, ``kubota_pole_ratio``).
- ``speed_estimator`` (default "none") runs a speed estimator from
  `bench.controllers.speed_estimators.SPEED_ESTIMATORS` after the flux observer; its parameters are
  ``<estimator>_<parameter>`` (``kubota`` shares the ``kubota_*`` observer parameters). With
  ``speed_source = "encoder"`` (default) it only runs alongside and is logged (``omega_est``), as in
  Figs 4.9-4.12; with ``speed_source = "estimate"`` the controller is sensorless: the speed PI,
  omega_mR (4.5) and the flux observer's rotation term all use the estimate, and the speed PI takes
  its own parameter set ``sensorless_speed_Kp``/``sensorless_speed_Ti`` (the thesis retuned it, 5.6.3).
  The estimate fed to the flux observer is the previous tick's (the estimator runs after it).

On-line R_r (``rr_adapt = "mras"``, `bench.controllers.rr_adapt`): the reactive-power MRAS estimates R_r
each tick (frozen where R_r is not observable) and hands it to every part that uses R_r: the flux observer
(current model (4.15), JL's current model, Kubota's A_sc), the speed estimator (4.19), the slip (4.5) and the
decoupling R'_r (4.13); /ctrl gets ``rr_hat`` [Ohm] and ``rr_gate`` (why it is frozen, 0: adapting).
``rr_init`` sets (resets) the estimate while running. Needs the encoder speed.

Engines (``engine``): "python" runs the tick as written here (the reference); "compiled" runs the same
tick in one numba call (`bench.controllers.foc_compiled`), equal to the reference to the last bit, for
the current-model observer with the PI speed and current controllers and no speed estimator, with or without
the R_r adaptation (any divisors, voltage source, gains); "auto" is compiled where that applies and numba imports,
else python. The default is python; `bench run` takes auto for a real-time run and from 25 s of simulated time
(`bench.runtime.session.default_engines`: the start-up is paid back), sweeps always.
"""

from __future__ import annotations

import cmath
import contextlib
import math
from collections.abc import Iterator, Mapping
from typing import Any

from bench.controllers.base import Controller, ControllerContext
from bench.controllers.kernel_math import abs_checked, crect, square
from bench.controllers.schema import Param, prefixed
from bench.controllers.observers import OBSERVERS, KubotaObserver
from bench.controllers.rr_adapt import SCHEMA as RR_SCHEMA, RrMRAS
from bench.controllers.speed_estimators import SPEED_ESTIMATORS, KubotaSpeed
from bench.core.encoder import EncoderSpeed
from bench.errors import BadInput
from bench.hal import Measurement

SWITCHABLE = ("observer", "speed_controller", "current_controller", "speed_source")  # parts switched while running
I_MR_FLOOR = 0.1  # [A] below this i_mR_hat is not trusted: the floor in divisions (4.5)(4.7), and the field
# angle is held (start-up from zero flux, where an observer's estimate is noise)
# ... and from zero flux the field frame first follows the estimate once it holds this share of i_mR_ref: until then
# i_sd builds the flux along the held axis. An estimate that started from noise can flip its sign from tick to tick
# at a few % of the reference (an LPV observer on measured voltages under the first ticks' saturated voltage, on a
# 7.5 kW motor: 0.1-0.5 A at i_mR_ref = 8 A), and a frame that follows it drives the flux back: over-current in 15 ms
FRAME_REL = 0.1


class SpeedPI:
    """PI speed controller with the current-limited torque bound (4.8) and anti-windup."""

    def __init__(self, K_p: float, T_i: float, k_torque: float, I_max: float, T: float) -> None:
        self.k, self.I_max, self.T = k_torque, I_max, T
        self.set_gains(K_p, T_i)
        self.reset()

    def set_gains(self, K_p: float, T_i: float) -> None:
        """New gains; the integrator state (a torque) carries over, so the output does not jump."""
        self.K_p, self.k_i = K_p, K_p * self.T / T_i

    def reset(self) -> None:
        self.x = 0.0
        self.m_e_ref = 0.0

    def take_over(self, i_sq: float, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> None:
        """Bumpless start (a switch from another speed part): the integrator preloaded so that, at the last
        tick's inputs, the output is the outgoing part's i_sq_ref (the torque m = k i_mR i_sq, within (4.8))."""
        i_mR = I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR
        r = self.I_max**2 - i_sd_ref**2
        m_max = self.k * i_mR * math.sqrt(0.0 if 0.0 > r else r)
        m = self.k * i_mR * i_sq
        self.x = min(max(m - self.K_p * (omega_ref - omega), -m_max), m_max)
        self.m_e_ref = m

    def update(self, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> float:
        """Return i_sq_ref [A]."""
        i_sq, self.x, self.m_e_ref = speed_pi(omega_ref, omega, i_mR, i_sd_ref, self.x, self.K_p, self.k_i, self.k,
                                              self.I_max, 2.0)  # fmt: skip
        return i_sq


def speed_pi(omega_ref: float, omega: float, i_mR: float, i_sd_ref: float, x: float, K_p: float, k_i: float,
             k: float, I_max: float, two: float) -> tuple[float, float, float]:  # fmt: skip
    """`SpeedPI.update` with the integrator x (a torque): (i_sq_ref, x, the torque reference m_e_ref). ``two`` is
    2.0, the exponent of the squares given at run time, so that the compiled kernel calls the C pow as CPython's
    float ** does. Plain Python that numba compiles: the compiled FOC tick (`bench.controllers.foc_compiled`)
    calls this one."""
    # (clamps written as comparisons: the same values as min/max, NaN included, at a third of the cost
    # on the per-tick path)
    if I_MR_FLOOR > i_mR:
        i_mR = I_MR_FLOOR
    r = square(I_max, two) - square(i_sd_ref, two)
    m_max = k * i_mR * math.sqrt(0.0 if 0.0 > r else r)  # (4.8)
    e = omega_ref - omega
    u = K_p * e + x
    m = -m_max if -m_max > u else u
    if m > m_max:
        m = m_max
    # anti-windup: conditional integration, and the integrator never exceeds the bound
    if m == u or (u > m_max and e < 0.0) or (u < -m_max and e > 0.0):
        x += k_i * e
    x = -m_max if -m_max > x else x
    x = m_max if m_max < x else x
    return m / (k * i_mR), x, m  # (4.7)


class FluxP:
    """P control of i_mR (Sec. 4.2.2), reference premultiplied by (K_m+1)/K_m."""

    def __init__(self, K_m: float, I_max: float) -> None:
        self.K_m, self.I_max = K_m, I_max

    def update(self, i_mR_ref: float, i_mR: float) -> float:
        """Return i_sd_ref [A]."""
        return flux_p(self.K_m, self.I_max, i_mR_ref, i_mR)


def flux_p(K_m: float, I_max: float, i_mR_ref: float, i_mR: float) -> float:
    """`FluxP.update`: i_sd_ref [A] = K_m ((K_m + 1)/K_m i_mR_ref - i_mR) within +-I_max. Plain Python that numba
    compiles: the compiled FOC tick (`bench.controllers.foc_compiled`) calls this one."""
    i_sd = K_m * ((K_m + 1.0) / K_m * i_mR_ref - i_mR)
    i_sd = -I_max if -I_max > i_sd else i_sd  # min(max(i_sd, -lim), lim), as SpeedPI.update
    return I_max if I_max < i_sd else i_sd


class FieldWeakening:
    """Voltage-feedback field weakening: the i_mR reference times a factor in [``lo``, 1] (thesis 4.2.2: "At speeds
    above rated speed it may be necessary to reduce this value in order to avoid saturation of the voltage supply").

    Idle, the factor exactly 1 and the reference untouched, until the current loop first reaches its voltage limit.
    From then on an integrator moves the factor by ``k`` (the gain times the period) times (``u_fw`` - |u_sr|/u_max)
    each tick: down while the voltage is above the fraction ``u_fw`` of the limit (at the limit by ``k (1 - u_fw)``),
    back up to 1 below it. Less flux, less back-EMF (4.10): the current loop leaves the limit and holds
    |u_sr| = u_fw u_max while the reference needs more than it can have. (A stale R_r estimate below the true R_r
    over-excites the motor, and at the voltage limit it stays frozen: `bench.controllers.rr_adapt`.)
    """

    def __init__(self, u_fw: float, gain: float, lo: float, T: float) -> None:
        self.T = T
        self.set_gains(u_fw, gain, lo)
        self.reset()

    def set_gains(self, u_fw: float, gain: float, lo: float) -> None:
        self.u_fw, self.k, self.lo = u_fw, gain * self.T, lo

    def reset(self) -> None:
        self.factor = 1.0

    def update(self, saturated: bool, u_sr: complex, u_max: float) -> None:
        """One base tick, after the current loop (``saturated``, its output ``u_sr``, the limit ``u_max``)."""
        self.factor = field_weakening(self.factor, saturated, u_sr, u_max, self.k, self.u_fw, self.lo)


def field_weakening(f: float, saturated: bool, u_sr: complex, u_max: float, k: float, u_fw: float, lo: float
                    ) -> float:  # fmt: skip
    """`FieldWeakening.update`: the factor f after one tick. Plain Python that numba compiles: the compiled FOC
    tick (`bench.controllers.foc_compiled`) calls this one."""
    if saturated or f < 1.0:
        v = 1.0  # no DC link: as at the limit
        if u_max > 0.0:
            v = abs_checked(u_sr) / u_max
        f += k * (u_fw - v)
        f = 1.0 if f > 1.0 else f if f >= lo else lo  # (NaN: the floor)
    return f


class CurrentPI:
    """Complex PI stator-current control in rotor-flux coordinates with decoupling (4.13)(4.14).

    One complex integrator serves d and q. At the voltage limit |u_sr| <= u_max the integrator is
    back-calculated from the limited output (anti-windup).
    """

    def __init__(self, K_p: float, T_i: float, T: float, Ls_p: float, Lm_p: float, Rr_p: float) -> None:
        self.T = T
        self.set_gains(K_p, T_i)
        self.Ls_p, self.Lm_p, self.Rr_p = Ls_p, Lm_p, Rr_p
        self.reset()

    def set_gains(self, K_p: float, T_i: float) -> None:
        """New gains; the integrator state (a voltage) carries over, so the output does not jump."""
        self.K_p, self.k_i = K_p, K_p * self.T / T_i

    def reset(self) -> None:
        self.x = 0j
        self.saturated = False

    def feedforward(self, i_sr: complex, omega_mR: float, i_mR: float) -> complex:
        """The decoupling voltage u_ff."""
        return decoupling(i_sr, omega_mR, i_mR, self.Ls_p, self.Lm_p, self.Rr_p)

    def take_over(self, u_sr: complex, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float) -> None:
        """Bumpless start: the integrator preloaded so that, at the last tick's inputs, the output is the
        outgoing part's u_sr."""
        self.x = u_sr - self.K_p * (i_ref - i_sr) - self.feedforward(i_sr, omega_mR, i_mR)
        self.saturated = False

    def update(self, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float, u_max: float) -> complex:
        """Return the rotor-flux-frame voltage u_sr [V], |u_sr| <= u_max."""
        u, self.x, self.saturated = current_pi(i_ref, i_sr, omega_mR, i_mR, u_max, self.x, self.K_p, self.k_i,
                                               self.Ls_p, self.Lm_p, self.Rr_p)  # fmt: skip
        return u


def decoupling(i_sr: complex, omega_mR: float, i_mR: float, Ls_p: float, Lm_p: float, Rr_p: float) -> complex:
    """The decoupling voltage u_ff of (4.13)(4.14) in the rotor-flux frame. Plain Python that numba compiles
    (`bench.controllers.foc_compiled` registers it for the kernels that call it)."""
    i_sd, i_sq = i_sr.real, i_sr.imag
    # (written a - b, not -b + a: the same bits, but LLVM folds the latter into the former, and the sign of a NaN
    # then differs between the engines)
    return complex(Rr_p * (i_sd - i_mR) - omega_mR * Ls_p * i_sq,  # (4.13)
                   omega_mR * Ls_p * i_sd + Lm_p * omega_mR * i_mR)  # (4.14)


def current_pi(i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float, u_max: float, x: complex, K_p: float,
               k_i: float, Ls_p: float, Lm_p: float, Rr_p: float) -> tuple[complex, complex, bool]:  # fmt: skip
    """`CurrentPI.update` with the integrator x (a voltage): (u_sr, x, saturated). Plain Python that numba
    compiles: the compiled FOC tick (`bench.controllers.foc_compiled`) calls this one."""
    e = i_ref - i_sr
    u = K_p * e + x + decoupling(i_sr, omega_mR, i_mR, Ls_p, Lm_p, Rr_p)
    mag = abs_checked(u)
    if mag > u_max:
        if mag == 0.0:  # u_max < 0: CPython's message (numba's differs)
            raise ZeroDivisionError("float division by zero")
        u_lim = u * (u_max / mag)
        # back-calculation with tracking time constant T_i: the integrator follows the
        # limited output instead of winding up
        return u_lim, x + k_i * (e + (u_lim - u) / K_p), True
    return u, x + k_i * e, False


def field_frame(i_m: complex, i_mR_ref: float, oriented: bool, rot: complex) -> tuple[float, bool, complex]:
    """The field frame from the flux estimate i_m: (|i_m|, oriented, e^{-j rho}). Below `I_MR_FLOOR` the estimate's
    angle is noise (an observer started from zero flux); from there the frame stays where it was (at start-up: the
    a axis, along which i_sd builds the flux) until the estimate holds `FRAME_REL` of its reference. Plain Python
    that numba compiles: the compiled FOC tick (`bench.controllers.foc_compiled`) calls this one."""
    i_mR = abs_checked(i_m)
    if i_mR <= I_MR_FLOOR:
        oriented = False
    elif i_mR > FRAME_REL * abs(i_mR_ref):
        oriented = True
    if oriented:
        rot = i_m.conjugate() / i_mR
    return i_mR, oriented, rot


def stator_voltage(u_sr: complex, rot: complex, omega_mR: float, advance: float) -> complex:
    """The stator-frame reference u_s = u_sr e^{j rho} e^{j omega_mR advance}: the flux-frame voltage turned back, and
    on by the field's travel over the delay ``advance`` [s] (delay compensation). Plain Python that numba compiles."""
    # u_sr * rot.conjugate(), written out: the same bits for every number (x - (-y) is x + y), and no negation that
    # LLVM would fold into another NaN sign than CPython's
    a, b, c, d = u_sr.real, u_sr.imag, rot.real, rot.imag
    return complex(a * c + b * d, b * c - a * d) * crect(1.0, omega_mR * advance)


class FocController(Controller):
    name = "foc"
    summary = "rotor-flux-oriented speed control, encoder speed, current-model observer (Sec. 4.2)"
    schema: dict[str, Param] = {
        "observer": Param("current_model", "flux observer (Secs 4.3, 5.6); switchable while running",
                          choices=tuple(OBSERVERS), tunable=True),
        "voltage_source": Param("reference", "the observer's voltage input", choices=("reference", "measured")),
        "inverter_comp": Param("auto", "auto: with voltage_source = reference the observers get the reference less "
                               "the rig's [inverter_error] at the measured phase currents (none given: nothing "
                               "subtracted); off: the reference as it is", choices=("auto", "off")),
        "speed_Kp": Param(0.6, "speed PI gain (per electrical rad/s)", "N m s/rad", gt=0, le=100, tunable=True),
        "speed_Ti": Param(0.04, "speed PI integral time", "s", gt=0, le=10, tunable=True),
        "speed_divisor": Param(1, "speed loop runs every N base ticks", ge=1, le=100),
        "speed_filter_tau": Param(0.003, "encoder speed low-pass", "s", ge=0, le=1),
        "flux_Km": Param(4.0, "i_mR P gain K_m (4.4)", gt=0, le=1000, tunable=True),
        "flux_divisor": Param(1, "flux loop runs every N base ticks", ge=1, le=100),
        "current_wc": Param(1000.0, "current-PI bandwidth (pole-zero cancellation)", "rad/s", gt=0, le=1e4,
                            tunable=True),
        "current_divisor": Param(1, "current loop runs every N base ticks (PI)", ge=1, le=100),
        "current_controller": Param("pi", "pi: (4.13)(4.14); lpv: the quasi-LPV controller of 6.2; switchable "
                                    "while running", choices=("pi", "lpv"), tunable=True),
        "lpv_current_rate": Param(600.0, "rate of the shipped LPV current artifact", "Hz", choices=(600.0, 3000.0)),
        "lpv_current_artifact": Param("", "another LPV current artifact (`bench synth current-controller`)"),
        "speed_controller": Param("pi", "pi: (4.7)(4.8); lpv: the LPV speed controller of 6.4.3 / 7.2 (no integral "
                                  "action: a steady speed offset under load, 2.4 rad/s at 4 N m with the shipped "
                                  "design, about 10 rad/s with the README's identification chain); switchable while "
                                  "running", choices=("pi", "lpv"), tunable=True),
        "lpv_speed_artifact": Param("nominal", "shipped nominal, robust or nominal_3000Hz, or an artifact path"),
        "lpv_speed_iterations": Param(0, "re-evaluations of the scheduling with u_k (0: u_(k-1), as 6.4.3)",
                                      ge=0, le=10),
        "u_margin": Param(0.95, "fraction of the linear-range voltage u_dc/sqrt(3) the current loop may use",
                          gt=0, le=1),
        "field_weakening": Param("auto", "lower the i_mR reference while the current loop is at its voltage limit "
                                 "(voltage feedback, thesis 4.2.2), until the loop's voltage is back at fw_u of the "
                                 "limit, and restore it when the voltage allows; auto: on with rr_adapt = mras (a stale "
                                 "R_r estimate over-excites the motor, and the estimate is frozen at the limit)",
                                 choices=("auto", "on", "off")),
        "fw_u": Param(0.98, "fraction of the current loop's voltage limit the field weakening holds its voltage at",
                      gt=0.5, lt=1, tunable=True),
        "fw_gain": Param(100.0, "field-weakening integrator gain (the flux factor moves at fw_gain x (fw_u - the "
                         "voltage's fraction of the limit) per second)", "1/s", gt=0, le=1000, tunable=True),
        "fw_min": Param(0.5, "the field weakening never scales the i_mR reference below this", ge=0.1, le=1,
                        tunable=True),
        "delay_comp": Param(1.5, "angle advance of the voltage reference (computation delay + hold)", "periods",
                            ge=0, le=5, tunable=True),
        "speed_source": Param("encoder", "speed feedback (estimate: sensorless); switchable while running (the "
                              "estimator must run from the start)", choices=("encoder", "estimate"), tunable=True),
        "handover": Param("bumpless", "a part switched in while running starts from the outgoing one's state "
                          "(bumpless) or from its reset state (cold: for comparison)", choices=("bumpless", "cold")),
        "speed_estimator": Param("none", "speed estimator run after the flux observer",
                                 choices=("none", *SPEED_ESTIMATORS)),
        "sensorless_speed_Kp": Param(0.3, "speed PI gain when speed_source = estimate", "N m s/rad", gt=0, le=100,
                                     tunable=True),
        "sensorless_speed_Ti": Param(0.1, "speed PI integral time when speed_source = estimate", "s", gt=0, le=10,
                                     tunable=True),
        "engine": Param("python", "python: the reference; compiled: the same tick in numba, bit for bit (every "
                        "observer, speed estimator, PI and LPV part, rr_adapt; not with a rig's [inverter_error] "
                        "compensation); auto: compiled where it applies",
                        choices=("python", "compiled", "auto")),
        **RR_SCHEMA,  # on-line R_r estimate (bench.controllers.rr_adapt)
        # observer and estimator parameters, "<name>_<parameter>"
        **{k: v for n, c in OBSERVERS.items() for k, v in prefixed(c.schema, n, f"{n} observer").items()},
        **{k: v for n, c in SPEED_ESTIMATORS.items() for k, v in prefixed(c.schema, n, f"{n} speed estimator").items()},
    }  # fmt: skip
    switchable = SWITCHABLE  # the parts `bench switch` and the operator change while running (`_switch`)
    fields = ("omega_hat", "i_m_hat_re", "i_m_hat_im", "i_mR_hat", "rho", "omega_mR", "i_sd",
              "i_sq", "i_sd_ref", "i_sq_ref", "m_e_ref", "u_sd", "u_sq", "u_sat")  # fmt: skip

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        super().__init__(ctx, **params)
        p, m, T = self.p, ctx.motor, ctx.T_s  # every value already checked against `schema`
        est_name = p["speed_estimator"]
        if p["speed_source"] == "estimate" and est_name == "none":
            raise BadInput("controller.foc.speed_estimator", "speed_source = estimate needs a speed estimator")
        self.observer = self._build("observer", p["observer"])
        self.estimator = None
        if est_name == "kubota":
            shared = self.observer if isinstance(self.observer, KubotaObserver) else None
            self.estimator = KubotaSpeed(m, T, shared=shared, observer_params=self._sub(KubotaObserver.defaults, "kubota"),
                                         **self._sub(KubotaSpeed.defaults, "kubota"))  # fmt: skip
        elif est_name != "none":
            cls = SPEED_ESTIMATORS[est_name]
            self.estimator = cls(m, T, **self._sub(cls.defaults, est_name))
        self._sensorless = p["speed_source"] == "estimate"
        if self.estimator is not None:
            self.fields = self.fields + ("omega_enc", "omega_est")
        self.rr: RrMRAS | None = None  # on-line R_r estimate (rr_adapt = mras)
        if p.get("rr_adapt", "off") == "mras":
            if self._sensorless:
                raise BadInput("controller.foc.rr_adapt", "needs the encoder speed (speed_source = encoder): R_r and "
                               "the speed are not both observable from the stator's fundamental in steady state")
            self.rr = RrMRAS(m, T, p["rr_gain"], p["rr_w_min"], p["rr_iq_min"], p["rr_init"])
        self.speed = self._build("speed_controller", p["speed_controller"])
        self._speed_logs = p["speed_controller"] == "lpv"  # the LPV speed part logs its scheduling (fixed per run)
        if self._speed_logs:
            self.fields = self.fields + self.speed.fields
        self.encoder = EncoderSpeed(ctx.counts_per_rev, ctx.enc_modulus, m.Z_p, T, self._speed_tau(self.speed))
        self.flux = FluxP(p["flux_Km"], ctx.I_max)
        self.current = self._build("current_controller", p["current_controller"])
        div_w, div_c = self._divisor(self.speed), self._divisor(self.current)
        self._running = {part: p[part] for part in SWITCHABLE}  # the parts in use (p changes first, see _switch)
        self._spare: dict[tuple[str, str], Any] = {}  # prepared parts to switch to, or why one cannot be had
        self._omega_ref = 0.0  # the last tick's speed reference (a speed part's hand-over needs it)
        self._use_measured_u = p["voltage_source"] == "measured"
        # the inverter's error per phase, subtracted from the reference the observers get (bench.core.inverter_error)
        comp = p.get("inverter_comp", "off") == "auto" and not self._use_measured_u
        self._inv = ctx.inverter_error if comp else None
        self._div = (div_w, p["flux_divisor"], div_c)
        self._inv_Tr = 1.0 / m.T_r
        self._advance = p["delay_comp"] * T
        self._t_stall = 1.5 * T  # a tick later than this after the last one follows a stall (_ride_through)
        self._u_scale = p["u_margin"] / math.sqrt(3.0)
        fw = p.get("field_weakening", "off")
        self.fw: FieldWeakening | None = None  # voltage-feedback field weakening (FieldWeakening)
        if fw == "on" or (fw == "auto" and self.rr is not None):
            self.fw = FieldWeakening(p["fw_u"], p["fw_gain"], p["fw_min"], T)
            self.fields = self.fields + ("fw",)
        if self.rr is not None:
            self.fields = self.fields + ("rr_hat", "rr_gate")
        self._kernel = None  # engine compiled: the tick's numba kernel, the state in a buffer (foc_compiled.attach)
        self._tails: list[Any] = []  # the parts the compiled tick holds in tail regions (foc_compiled.attach)
        self._in_python = 0  # (inside _parts_in_python)
        compiled = self._compiled_engine()
        if compiled is not None:
            compiled.attach(self)
        self.reset()

    # ------------------------------------------------------------------ parts, and switching them while running
    def _build(self, part: str, choice: str) -> Any:
        """A new observer, speed or current controller part (BadInput naming why it cannot be had)."""
        p, m, T, ctx = self.p, self.ctx.motor, self.ctx.T_s, self.ctx
        if part == "observer":
            cls = OBSERVERS[choice]
            obs = cls(m, T, **self._sub(cls.defaults, choice))
            w_obs = getattr(obs, "omega_r_max", None)
            if w_obs is not None and ctx.omega_max is not None and ctx.omega_max > w_obs:
                # refused, not warned: the observer would clip Delta above omega_r,max, and the flux error is then
                # ~0.9-1.2 A RMS at 250-300 rad/s (|i_m| = 2.9 A) while the over-speed trip lets the run go there
                raise BadInput(getattr(obs, "FIELD", "controller.foc.observer"),
                               f"the flux observer covers |omega_r| <= {w_obs:g} rad/s but the rig's over-speed limit "
                               f"is {ctx.omega_max:g} rad/s; make one with `bench synth flux-observer --omega-max "
                               f"{ctx.omega_max:g}` or lower [limits] omega_max")  # fmt: skip
            return obs
        if part == "speed_controller":
            if choice == "lpv":
                # the LPV law runs at its artifact's rate on the speed filtered like its model's data (6.4.3)
                from bench.controllers.lpv_speed import LPVSpeedController, artifact_path as speed_artifact

                ctl = LPVSpeedController(speed_artifact(p["lpv_speed_artifact"]), m, ctx.I_max,
                                         iterations=p["lpv_speed_iterations"])  # fmt: skip
                ctl.divisor(T)  # an artifact at a rate the loop cannot run is refused here
                return ctl
            pre = "sensorless_" if p["speed_source"] == "estimate" else ""
            return SpeedPI(p[pre + "speed_Kp"], p[pre + "speed_Ti"], m.torque_constant, ctx.I_max,
                           T * p["speed_divisor"])  # fmt: skip
        if choice == "lpv":  # current controller
            # the LPV law runs at its artifact's rate and holds u_sr in the rotor-flux frame (6.2)
            from bench.controllers.lpv_current import LPVCurrentController, artifact_path

            ctl = LPVCurrentController(artifact_path(p["lpv_current_rate"], p["lpv_current_artifact"]), m)
            ctl.divisor(T)
            return ctl
        return CurrentPI(m.Ls_p * p["current_wc"], m.Ls_p / m.R_s, T * p["current_divisor"], m.Ls_p, m.Lm_p, m.Rr_p)

    def _divisor(self, part: Any) -> int:
        """Base ticks per update of a speed or current part."""
        if isinstance(part, SpeedPI):
            return self.p["speed_divisor"]
        if isinstance(part, CurrentPI):
            return self.p["current_divisor"]
        return part.divisor(self.ctx.T_s)  # an LPV law: its artifact's rate

    def _speed_tau(self, speed: Any) -> float:
        """The encoder-speed low-pass a speed part wants (the LPV law: its model's data filter)."""
        return speed.speed_filter_tau if not isinstance(speed, SpeedPI) else self.p["speed_filter_tau"]

    def prepare_switching(self) -> dict[str, str]:
        """Build every part this run may switch to, before the loop starts, so that a switch between two ticks
        is only the hand-over (no artifact loading in the loop). Returns the ones that cannot be had, with why
        (a switch to them is refused with that reason). The compiled engine runs until the first switch, and
        the Python engine from there (`foc_compiled.detach`: the same state, exactly)."""
        unavailable = {}
        for part in ("observer", "speed_controller", "current_controller"):
            for choice in self.schema[part].choices or ():
                if choice == self._running[part] or (part, choice) in self._spare:
                    continue
                try:
                    self._spare[(part, choice)] = self._build(part, choice)
                except BadInput as exc:
                    self._spare[(part, choice)] = str(exc)
                    unavailable[f"{part}={choice}"] = str(exc)
        return unavailable

    def _detach_kernel(self) -> None:
        if self._kernel is not None:
            from bench.controllers import foc_compiled

            foc_compiled.detach(self)

    def _switch(self, part: str) -> None:
        """Put ``self.p[part]`` in place of the running part, between two ticks; the incoming part takes over
        the outgoing one's state (`handover` = bumpless) or starts from reset (cold). BadInput: refused, the
        running part stays."""
        new, old = self.p[part], self._running[part]
        if new == old:
            return
        why = self._switch_refusal(part, new)
        if why:
            raise BadInput(f"controller.{self.name}.{part}", why)
        est = self.estimator
        incoming = None if part == "speed_source" else self._spare.pop((part, new))
        self._detach_kernel()
        cold = self.p["handover"] == "cold"
        div_w, div_f, div_c = self._div
        if part == "observer":
            if self.rr is not None:
                incoming.set_R_r(self.rr.R_r)
            incoming.reset()
            if not cold:
                self._hand_over(part, incoming)
            outgoing, self.observer = self.observer, incoming
        elif part == "current_controller":
            if isinstance(incoming, CurrentPI):  # the gains and R'_r in force now
                m = self.ctx.motor
                incoming.set_gains(m.Ls_p * self.p["current_wc"], m.Ls_p / m.R_s)
                if self.rr is not None:
                    incoming.Rr_p = (m.L_m / m.L_r) ** 2 * self.rr.R_r
            incoming.reset()
            if not cold:
                self._hand_over(part, incoming)
            outgoing, self.current = self.current, incoming
            div_c = self._divisor(incoming)
        else:
            if part == "speed_source":
                self._sensorless = new == "estimate"
                incoming, outgoing = self.speed, None
            else:
                incoming.reset()
                outgoing, self.speed = self.speed, incoming
                self.encoder.set_tau(self._speed_tau(incoming))
                div_w = self._divisor(incoming)
            if isinstance(incoming, SpeedPI):  # the gains in force now, of the feedback in use
                pre = "sensorless_" if self._sensorless else ""
                incoming.set_gains(self.p[pre + "speed_Kp"], self.p[pre + "speed_Ti"])
            self.omega = est.omega_r if self._sensorless else self.encoder.omega_r
            if not cold:
                self._hand_over("speed_controller", incoming, self.omega)
            elif outgoing is None:
                incoming.reset()
        self._div = (div_w, div_f, div_c)
        if outgoing is not None:
            self._spare[(part, old)] = outgoing  # kept: a switch back needs no new build
        self._running[part] = new

    def _switch_refusal(self, part: str, new: str) -> str | None:
        """Why `_switch` would refuse ``part`` -> ``new`` now, or None; an incoming part not yet prepared (a library
        call in lockstep) is built here and kept for the switch, or why it cannot be had."""
        est = self.estimator
        if part == "speed_source":
            if new == "estimate" and est is None:
                return "no speed estimator runs (start the run with -p speed_estimator=...)"
            if new == "estimate" and self.rr is not None:
                return "R_r adaptation needs the encoder speed (rr_adapt = mras)"
            return None
        if part == "observer" and isinstance(est, KubotaSpeed) and est.shared:
            return "the kubota speed estimator runs on the kubota flux observer; it cannot switch"
        incoming = self._spare.get((part, new))
        if incoming is None:
            try:
                incoming = self._build(part, new)
            except BadInput as exc:
                incoming = str(exc)
            self._spare[(part, new)] = incoming
        return f"{new} cannot be had: {incoming}" if isinstance(incoming, str) else None

    def check_switches(self, changes: Mapping[str, Any]) -> None:
        """Check several part switches of one request as a whole before any is applied: `BadInput` naming the
        first part `_switch` would refuse (bench.operate.operator then applies none). No rule today depends on another
        part of the same request, so each part is checked as `_switch` checks it."""
        for part, new in changes.items():
            if part in SWITCHABLE and new != self._running[part]:
                why = self._switch_refusal(part, new)
                if why:
                    raise BadInput(f"controller.{self.name}.{part}", why)

    def _hand_over(self, part: str, incoming: Any, omega: float = math.nan) -> None:
        """Start ``incoming`` (an observer, current or speed part) from this controller's last tick, by the part's
        own hand-over (``take_over``); ``omega``: the speed feedback the incoming speed part gets."""
        if part == "observer":
            w_obs = self.estimator.omega_hat if self._sensorless else self.encoder.omega_raw
            i_s = self.i_sr * self._rot.conjugate()  # the last tick's stator current, stator-fixed
            incoming.take_over(self.i_m_hat, i_s, self.u_s_obs, w_obs, self.omega_mR)
        elif part == "current_controller":
            incoming.take_over(self.u_sr, complex(self.i_sd_ref, self.i_sq_ref), self.i_sr, self.omega_mR,
                               self.i_mR_hat)  # fmt: skip
        else:
            incoming.take_over(self.i_sq_ref, self._omega_ref, omega, self.i_mR_hat, self.i_sd_ref)

    def take_over_from(self, other: Controller) -> None:
        """A whole-controller switch from another FOC (this plugin with other parameters, or a plugin built on
        it, relay_tune): the encoder's count history, the references and the field frame carried over, each part
        started from the outgoing controller's state by its own hand-over (as `_switch`)."""
        if not isinstance(other, FocController):
            super().take_over_from(other)
        self._detach_kernel()
        with other._parts_in_python():  # (the outgoing one's parts as Python objects, if its compiled tick holds them)
            self._take_over_from(other)

    def _take_over_from(self, other: FocController) -> None:
        enc, src = self.encoder, other.encoder
        for name in ("_prev", "d", "_prev_t", "omega_r", "omega_raw", "theta_r"):  # the same encoder, counted on
            setattr(enc, name, getattr(src, name))
        for name in ("k", "i_sd_ref", "i_sq_ref", "u_sr", "u_s_ref", "_u_hist", "i_m_hat", "i_mR_hat", "omega_mR",
                     "_rot", "_oriented", "omega", "u_s_obs", "i_sr", "_omega_ref",
                     "_t_last"):  # fmt: skip (_t_last: no stall)
            setattr(self, name, getattr(other, name))
        if self.fw is not None and other.fw is not None:  # the flux as far weakened as it was
            self.fw.factor = other.fw.factor
        rr, est = self.rr, self.estimator
        if rr is not None:  # the estimate carries over where the other had one
            if other.rr is not None:
                rr.set_estimate(other.rr.R_r)
            self._use_R_r()
        if est is not None:  # its estimate starts at the speed in use
            est.omega_hat = est.omega_r = other.estimator.omega_r if other.estimator is not None else enc.omega_r
        other._hand_over("observer", self.observer)
        other._hand_over("current_controller", self.current)
        other._hand_over("speed_controller", self.speed, est.omega_r if self._sensorless else enc.omega_r)

    def _compiled_engine(self) -> Any:
        """`bench.controllers.foc_compiled` if ``engine`` runs the tick compiled, else None: "compiled" needs a
        configuration the kernel covers and numba (else BadInput), "auto" takes it where it can (a kernel numba
        cannot load or compile here: Python, with a note for the run's warnings). A subclass without the parameter
        (relay_tune) runs Python."""
        engine = self.p.get("engine", "python")
        if engine == "python":
            return None
        try:
            from bench.controllers import foc_compiled  # compiles, or loads the cached machine code

            why = foc_compiled.uncovered(self)
            if why is None:
                return foc_compiled
            why = f"compiled {why}; use engine = 'python' or 'auto'" + (
                ", or inverter_comp = 'off'" if self._inv is not None else "")
        except ImportError:
            why = "compiled needs numba (pip install numba); use engine = 'python' or 'auto'"
        except Exception as exc:  # noqa: BLE001 - numba's cache or compiler failed (bench.core.jit_cache): Python runs
            failed = " ".join(f"{type(exc).__name__}: {exc}".split())
            if engine == "compiled":
                raise BadInput(f"controller.{self.name}.engine", f"compiled cannot load here ({failed}); use "
                                                                  "engine = 'python' or 'auto'") from None  # fmt: skip
            from bench.core.jit_cache import note

            note(f"controller: the Python engine ran, the compiled one failed to load ({failed})")
            return None
        if engine == "compiled":
            raise BadInput(f"controller.{self.name}.engine", why)
        return None

    def retune(self, name: str) -> None:
        """Apply a tunable parameter changed while running (`Controller.set_param`)."""
        p, field = self.p, f"controller.{self.name}.{name}"
        if name in SWITCHABLE:
            self._switch(name)
        elif name in ("speed_Kp", "speed_Ti", "sensorless_speed_Kp", "sensorless_speed_Ti"):
            if not isinstance(self.speed, SpeedPI):
                raise BadInput(field, "the speed controller is not a PI (speed_controller = lpv)")
            if name.startswith("sensorless") == self._sensorless:  # the set in use; the other waits
                pre = "sensorless_" if self._sensorless else ""
                self.speed.set_gains(p[pre + "speed_Kp"], p[pre + "speed_Ti"])
        elif name == "current_wc":
            if not isinstance(self.current, CurrentPI):
                raise BadInput(field, "the current controller is not the PI (current_controller = lpv)")
            m = self.ctx.motor
            self.current.set_gains(m.Ls_p * p["current_wc"], m.Ls_p / m.R_s)
        elif name == "flux_Km":
            self.flux.K_m = p["flux_Km"]
        elif name == "delay_comp":
            self._advance = p["delay_comp"] * self.ctx.T_s
        elif name in ("fw_u", "fw_gain", "fw_min"):
            if self.fw is None:
                raise BadInput(field, "field weakening is off (start the run with -p field_weakening=on)")
            self.fw.set_gains(p["fw_u"], p["fw_gain"], p["fw_min"])
        elif name in RR_SCHEMA:
            rr = self.rr
            if rr is None:
                raise BadInput(field, "R_r adaptation is off (start the run with -p rr_adapt=mras)")
            rr.gain, rr.w_min, rr.iq_min, rr.init = p["rr_gain"], p["rr_w_min"], p["rr_iq_min"], p["rr_init"]
            if name == "rr_init":  # a reset of the estimate (the Parameters panel, `bench set rr_init=1`)
                rr.set_estimate(p["rr_init"])
                self._use_R_r()
        else:
            super().retune(name)

    def _sub(self, defaults: dict[str, Any], prefix: str) -> dict[str, Any]:
        """This controller's values of an observer's or estimator's parameters."""
        return {k: self.p[f"{prefix}_{k}"] for k in defaults}

    def _use_R_r(self) -> None:
        """Hand the R_r estimate to every part that uses R_r at run time: the flux observer (4.15) (JL's current
        model, Kubota's A_sc), the speed estimator (4.19), the slip (4.5) and the PI's decoupling R'_r (4.13).
        (The LPV observer and the LPV current controller keep their design R_r.)"""
        rr = self.rr
        R_r = rr.R_r
        with self._parts_in_python():
            self.observer.set_R_r(R_r)
            if self.estimator is not None:
                self.estimator.set_R_r(R_r)
        self._inv_Tr = rr.b
        if isinstance(self.current, CurrentPI):
            m = self.ctx.motor
            self.current.Rr_p = (m.L_m / m.L_r) ** 2 * R_r

    @contextlib.contextmanager
    def _parts_in_python(self) -> Iterator[None]:
        """The parts the compiled tick holds in its buffer's tail regions (`foc_compiled.attach`: an observer other
        than the current model, a speed estimator, the LPV parts) as their Python objects for the block: their state
        unpacked before, packed back after. Nothing to do on the Python engine."""
        if not self._tails or self._in_python:
            yield
            return
        from bench.controllers import foc_compiled

        self._in_python = 1
        foc_compiled.unpack_tails(self)
        try:
            yield
        finally:
            foc_compiled.pack_tails(self)
            self._in_python = 0

    def reset(self) -> None:
        with self._parts_in_python():
            self._reset()

    def _reset(self) -> None:
        if self.rr is not None:
            self.rr.reset()
            self._use_R_r()
        self.observer.reset()
        if self.estimator is not None:
            self.estimator.reset()
        self.encoder.reset()
        self.speed.reset()
        self.current.reset()
        if self.fw is not None:
            self.fw.reset()
        self.k = 0
        self.i_sd_ref = self.i_sq_ref = 0.0
        self.u_sr = 0j
        self.u_s_ref = 0j
        self._u_hist = (0j, 0j)  # references of the last two ticks: the older one is being applied now
        self.i_m_hat = 0j
        self.i_mR_hat = self.rho = self.omega_mR = self.omega_u = 0.0
        self._rot = 1.0 + 0j  # e^{-j rho} of the field frame
        self._oriented = False  # the frame follows the estimate (`FRAME_REL`)
        self.omega = 0.0
        self.u_s_obs = 0j
        self.i_sr = 0j
        self._t_last = math.inf  # loop time of the last tick (a later tick more than a period on: a stall)

    def _ride_through(self, gap: float) -> None:
        """Resynchronise after a loop stall of ``gap`` seconds since the last tick. The drive turned the last
        reference at omega_mR while no new one came, so the field, the currents and every stator-fixed state
        turned with it: the observer's (and the speed estimator's, the R_r model's) states and the reference
        history turn by the angle of the periods missed; the next update adds the present one. Integrators
        in the field frame (the PIs, the LPV laws) and the encoder speed (it divides by the real elapsed time)
        need nothing. Every loop updates at the first tick back (the tick counter starts again): a loop slower than
        the base rate (an LPV law at 600 Hz, a divisor > 1) would otherwise hold the output it computed before the
        stall for up to a period of its own more, while the current it was forcing ran on through the stall."""
        e = cmath.rect(1.0, self.omega_mR * (gap - self.ctx.T_s))
        with self._parts_in_python():
            self.observer.rotate(e)
            if self.estimator is not None:
                self.estimator.rotate(e)
        if self.rr is not None:
            self.rr.rotate(e)
        h0, h1 = self._u_hist
        self._u_hist = (h0 * e, h1 * e)
        self.k = 0

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        self._omega_ref = omega_ref
        t = meas.t
        if t - self._t_last > self._t_stall:  # ticks were skipped: the drive rode through the stall
            self._ride_through(t - self._t_last)
        self._t_last = t
        if self._kernel is not None:  # engine compiled: this method's tick in one call (foc_compiled.step)
            u = self._kernel(self._buf, meas.t, meas.i_a, meas.i_b, meas.i_c, meas.u_a, meas.u_b, meas.u_c,
                             meas.enc_count, meas.u_dc, omega_ref, i_mR_ref)  # fmt: skip
            self.omega_u = self._buf.item(self._w_slot)
            return u
        k = self.k
        self.k = k + 1
        omega = self.encoder.update(meas.enc_count, meas.t)
        i_s = meas.i_s
        u_s = meas.u_s if self._use_measured_u else self._u_hist[1]
        inv = self._inv
        if inv is not None:  # the reference less the inverter's error at the phase currents, per phase, (3.17)
            u_s = u_s - inv.vector(meas.i_a, meas.i_b, meas.i_c)
        self.u_s_obs = u_s  # the voltage the observers get this tick (for passive add-ons)
        est = self.estimator
        if self._sensorless:
            # sensorless: the observer's rotation term uses the estimate of the previous tick
            i_m = self.observer.update(i_s, u_s, est.omega_hat)
            omega = est.update(i_s, u_s, i_m)
        else:
            # the observer gets the unfiltered per-sample speed: its rotation term then integrates to
            # the encoder angle exactly, with none of the filter's lag during fast speed changes
            i_m = self.observer.update(i_s, u_s, self.encoder.omega_raw)
            if est is not None:
                est.update(i_s, u_s, i_m)
        self.omega = omega
        i_mR, self._oriented, self._rot = field_frame(i_m, i_mR_ref, self._oriented, self._rot)
        rot = self._rot
        i_sr = i_s * rot
        self.i_m_hat, self.i_mR_hat, self.i_sr = i_m, i_mR, i_sr
        self.omega_mR = omega + self._inv_Tr * i_sr.imag / (I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR)  # (4.5)
        rr = self.rr
        if rr is not None:  # the R_r estimate from this period; the parts use it from the next tick on
            if rr.update(meas.t, i_s, u_s, self.encoder.omega_raw, self.omega_mR, i_sr.imag, i_mR,
                         self.current.saturated):  # fmt: skip
                self._use_R_r()
        div_w, div_f, div_c = self._div
        fw = self.fw
        if k % div_f == 0:
            self.i_sd_ref = self.flux.update(i_mR_ref if fw is None else i_mR_ref * fw.factor, i_mR)
        if k % div_w == 0:
            self.i_sq_ref = self.speed.update(omega_ref, omega, i_mR, self.i_sd_ref)
        if k % div_c == 0:
            u_max = meas.u_dc * self._u_scale
            self.u_sr = self.current.update(complex(self.i_sd_ref, self.i_sq_ref), i_sr, self.omega_mR, i_mR, u_max)
        if fw is not None:  # (a slower current loop: its output and flag held between its updates)
            fw.update(self.current.saturated, self.u_sr, meas.u_dc * self._u_scale)
        # u_sr is held in the rotor-flux frame and re-rotated every tick: a current loop slower than the
        # base rate (the LPV law at 600 Hz, or current_divisor > 1) must not hold the stator-frame
        # voltage, which would turn against the flux by omega_mR * T_c per update
        # the field's frequency (4.5), sent with the reference: the drive turns it at that through a loop stall
        self.omega_u = self.omega_mR
        self.u_s_ref = stator_voltage(self.u_sr, rot, self.omega_mR, self._advance)
        self._u_hist = (self.u_s_ref, self._u_hist[0])
        return self.u_s_ref

    def internals(self) -> tuple[float, ...]:
        if self._kernel is not None:  # the row the kernel (or a change of a logged value) left in the buffer
            return tuple(self._buf[self._row].tolist())
        i_m, i_sr, u = self.i_m_hat, self.i_sr, self.u_sr
        row = (self.omega if self.estimator is not None else self.encoder.omega_r, i_m.real, i_m.imag, self.i_mR_hat,
               math.atan2(i_m.imag, i_m.real), self.omega_mR, i_sr.real, i_sr.imag, self.i_sd_ref, self.i_sq_ref,
               self.speed.m_e_ref, u.real, u.imag, float(self.current.saturated))  # fmt: skip
        if self.estimator is not None:
            row += (self.encoder.omega_r, self.estimator.omega_r)
        if self._speed_logs:  # NaN while a PI switched in runs
            row += self.speed.internals() if not isinstance(self.speed, SpeedPI) else (math.nan,) * 4
        if self.fw is not None:
            row += (self.fw.factor,)
        return row if self.rr is None else row + (self.rr.R_r, float(self.rr.gate))
