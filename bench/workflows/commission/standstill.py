"""Standstill identification as a controller plugin (thesis 3.6: "auto-commissioning at standstill").

`StandstillIdController` plays the `bench.workflows.commission.signals.Plan` - a DC current staircase, then a
multisine on a DC bias - as *current* references on the stator α axis (the axis of phase a), with
i_β held at 0, through two PI current controllers on the measured currents. It runs through the
ordinary session path (`bench.runtime.session.run`: supervisor, log, shutdown), so it works on the mock,
emulated and real rigs alike; `bench.workflows.commission.identify` fits the log afterwards.

Why no torque: at standstill a current along one axis builds a flux along the same axis, and the
torque (3.41), 3 Z_p L_m²/(2 L_r) Im{i_s i_m*}, of collinear vectors is zero; a pulsating
(single-axis) excitation has no rotating field to drag the rotor along.

The current PIs are designed on the nominal model (``ctx.motor``) for a crossover ``current_bw``:
K_p = ω_c L'_s, K_i = ω_c (R_s + R'_r) (the high-frequency part of the standstill impedance (*)
of `bench.workflows.commission.circuit`), with conditional integration at the voltage limit ``u_max``. The
reference moves at most ``slew`` A/s, so level steps do not overshoot, except that it crosses the band
|i| < `CROSS_BAND` around zero in one tick (a dead time's error flips with the noise there).

Safety, checked on every tick; each raises `StandstillViolation`, which the loop turns into a
supervisor trip (one line, safe command, the ordinary shutdown):

* the shaft has moved more than ``max_counts`` encoder counts from where the test began;
* |i_s| exceeds the test's own peak by more than `I_MARGIN` (x1.25 + 0.3 A): a current the test
  did not ask for. (The supervisor's rig-wide over-current trip stays armed as well.)
* voltage headroom: the PI's output has been at its limit - ``u_max`` or the SVPWM linear range
  u_dc/√3 of the measured DC link, whichever is lower - for more than `HEADROOM_TICKS` ticks in a
  row: the rig cannot drive the current the test asks for (a motor with a larger R_s, a low DC
  link), and a fit of such a run would be a fit of the voltage limit.

Parameters that would ask for more than the rig's ``I_max`` are refused at construction.

Logged each tick on ``/ident`` (the controller's `topic`): the plan's segment index and stage
(1 DC, 2 multisine, 3 warming check, 4 the saturation check's multisine on the second bias, 0 after), the α current reference, the encoder counts the
shaft has moved since the start, the ticks the voltage has been at its limit, and the running
estimates: R_s (slope of the finished DC levels, `fits.dc_line`, on the chosen voltages), the
inverter voltage error seen at the last finished level (reference minus measured voltage; NaN with
``voltages = "reference"``), the warming check's statistic at the start and at the end, and after
the multisine's analysis window the impedance of every line (a running DFT over the window: Z =
U/I; with reference voltages the reference held over the period, uncompensated - a constant
inverter error has no AC content). NaN until known.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.workflows.commission import fits
from bench.workflows.commission.signals import EPS, Plan
from bench.controllers.base import Controller, ControllerContext
from bench.controllers.schema import Param
from bench.errors import BadInput
from bench.hal import Measurement

I_MARGIN = (1.25, 0.3)  # trip above 1.25 x the test's peak current + 0.3 A
# the slewed reference jumps across |i| < CROSS_BAND in one tick: near zero current a dead time's error
# flips with the current's noise, the loop chatters, and the voltage vector's jumps by pi look like a
# rotating field to the supervisor's encoder-stuck check
CROSS_BAND = 0.5  # [A]
HEADROOM_TICKS = 5  # trip when the voltage has been at its limit for more ticks than this in a row
SQRT3 = math.sqrt(3.0)


STAGES = {"dc": 1, "ac": 2, "chk0": 3, "chk1": 3, "sat": 4}  # logged stage per segment kind (0: after the plan)
SAT_MIN_STEP = 0.2  # sat_bias must differ from ac_bias by at least this fraction of ac_bias


class StandstillViolation(RuntimeError):
    """The standstill test saw something it must not continue with (one line)."""


class StandstillIdController(Controller):
    name = "standstill_id"
    topic = "/ident"
    summary = ("standstill identification: DC staircase + multisine on the alpha axis, current-controlled "
               "(bench identify)")
    schema: dict[str, Param] = {
        "voltages": Param("measured", "voltages the running estimate and the fit use",
                          choices=("measured", "reference")),
        "dc_current": Param(4.0, "largest DC test current", "A", gt=0, le=50),
        "dc_levels": Param(4, "DC levels per polarity (equal steps up to dc_current)", ge=2, le=20),
        # 1 s and 2 s: 5 and 10 rotor time constants L'_m/R'_r of the slowest rotor within +-40 % of (3.57) (0.2 s);
        # at 0.45 s the rest of the rotor transient lifted R_s 0.4 % and L'_m came out 4 % low (bench perf identify)
        "dc_settle": Param(1.0, "settling time per DC level", "s", ge=0.01, le=10),
        "dc_average": Param(0.15, "averaging window per DC level", "s", ge=0.01, le=10),
        "ac_bias": Param(2.0, "DC bias under the multisine", "A", ge=0, le=50),
        "ac_amplitude": Param(1.0, "peak of the multisine", "A", gt=0, le=50),
        "ac_f_min": Param(1.0, "lowest line and frequency resolution of the multisine", "Hz", ge=0.1, le=100),
        "ac_f_max": Param(100.0, "highest line of the multisine", "Hz", gt=0, le=1000),
        "ac_lines": Param(10, "lines of the multisine (log-spaced)", ge=2, le=60),
        "ac_grid": Param("odd", "harmonics of ac_f_min the lines may take: odd (the quadratic part of a saturating "
                         "flux falls between them) or all", choices=("odd", "all")),
        "ac_periods": Param(2, "common periods 1/ac_f_min analysed", ge=1, le=100),
        "ac_settle": Param(2.0, "settling time of the multisine before analysis", "s", ge=0.1, le=10),
        # the saturation check: the multisine again on a second bias (bench.workflows.commission.signals); 1 A is
        # about 0.4 Wb on (3.57), half the rated flux, the unsaturated part of a typical curve
        "sat_bias": Param(1.0, "second DC bias of the multisine, the saturation check (its amplitude scaled by "
                          "sat_bias/ac_bias); 0: no check", "A", ge=0, le=50),  # fmt: skip
        "sat_settle": Param(1.0, "settling time of the second multisine before analysis", "s", ge=0.1, le=10),
        "current_bw": Param(150.0, "current PI crossover", "Hz", gt=1, le=1000),
        "u_max": Param(100.0, "voltage reference limit", "V", gt=0, le=1000),
        "slew": Param(100.0, "reference slew-rate limit", "A/s", gt=0, le=1e5),
        "check_settle": Param(0.45, "warming check (start and end): settling per level (the first: twice this)", "s",
                              ge=0.01, le=10),
        "check_average": Param(0.3, "warming check: averaging window per level (+-dc_current)", "s", ge=0.01, le=10),
        "max_counts": Param(4, "encoder counts the shaft may move before the test trips", ge=1, le=10000),
        "dc_fit_from": Param(0.0, "DC levels below this current are left out of the R_s slope (fit; the inverter "
                             "error's knee bends the reference voltages there); 0: all levels with measured voltages, "
                             "the levels above the knee, found from the data, with reference voltages", "A", ge=0,
                             le=50),  # fmt: skip
        "delay_samples": Param(1, "inverter delay from reference to applied voltage (fit)", "samples", ge=0, le=3),
        "u_filter_fc": Param(1000.0, "natural frequency of the voltage channel's 2nd-order filter (fit)", "Hz",
                             gt=0, le=1e6),  # fmt: skip
        "u_filter_zeta": Param(1.0 / math.sqrt(2.0), "damping of the voltage channel's filter (fit)", gt=0, le=10),
    }
    fields = ("segment", "stage", "i_ref", "shaft_counts", "u_sat_ticks", "r_s_hat", "u_err_hat", "r_chk_start",
              "r_chk_end")  # + z<n>_re, z<n>_im per multisine line (n: its harmonic of ac_f_min)

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        super().__init__(ctx, **params)
        p = self.p
        k = 3 if p["ac_grid"] == "odd" else 2  # two lines at least: 1 and 3 (odd grid) or 1 and 2
        if p["ac_f_max"] < k * p["ac_f_min"]:
            raise BadInput("controller.standstill_id.ac_f_max", f"must be at least {k} x ac_f_min = "
                           f"{k * p['ac_f_min']:g} Hz with ac_grid = {p['ac_grid']}, got {p['ac_f_max']:g}")  # fmt: skip
        if p["ac_f_max"] > 0.1 / ctx.T_s:
            raise BadInput("controller.standstill_id.ac_f_max", f"must be <= {0.1 / ctx.T_s:g} Hz (a tenth of the "
                           f"loop rate), got {p['ac_f_max']:g}")  # fmt: skip
        if p["ac_amplitude"] > p["ac_bias"] and p["ac_bias"] > 0:
            raise BadInput("controller.standstill_id.ac_amplitude", f"must be <= ac_bias = {p['ac_bias']:g} A (the "
                           f"current must not cross zero), got {p['ac_amplitude']:g}")  # fmt: skip
        if p["sat_bias"] > 0 and p["ac_bias"] > 0 and abs(p["sat_bias"] - p["ac_bias"]) < SAT_MIN_STEP * p["ac_bias"]:
            raise BadInput("controller.standstill_id.sat_bias", f"must differ from ac_bias = {p['ac_bias']:g} A by at "
                           f"least {SAT_MIN_STEP:.0%} (or be 0: no saturation check), got {p['sat_bias']:g}")  # fmt: skip
        self.plan = Plan.from_params(p)
        self.fields = self.fields + tuple(f"z{n}_{part}" for n in self.plan.multisine.harmonics for part in ("re", "im"))
        self._w = 2.0 * math.pi * self.plan.multisine.freqs
        kept = [s for s in self.plan.dc if abs(s.level) >= p["dc_fit_from"] - 1e-9]
        if len(kept) < 1 + len({s.level > 0 for s in kept}) + 1:
            raise BadInput("controller.standstill_id.dc_fit_from", f"leaves {len(kept)} DC levels for the slope and "
                           f"its intercepts; allowed: at most {sorted(abs(s.level) for s in self.plan.dc)[-2]:.3g} A "
                           f"(the second-largest level), got {p['dc_fit_from']:g}")  # fmt: skip
        peak = self.plan.peak_current
        if peak > ctx.I_max:
            raise BadInput("controller.standstill_id", f"the test asks for {peak:.2f} A, more than the rig's "
                           f"I_max = {ctx.I_max:g} A: lower dc_current, ac_bias or ac_amplitude")  # fmt: skip
        self.i_limit = I_MARGIN[0] * peak + I_MARGIN[1]
        m = ctx.motor
        R = m.R_s + m.Rr_p
        w_c = 2.0 * math.pi * p["current_bw"]
        self.Kp, self.Ki = w_c * m.Ls_p, w_c * R  # IMC tuning on the high-frequency part of (*)
        self.reset()

    def reset(self) -> None:
        self.x = 0j  # PI integrators (alpha + j beta) [V]
        self.i_dc = 0.0  # slewed DC reference [A]
        self.i_ref = 0.0
        self.count0: int | None = None
        self.shaft_counts = 0  # encoder counts moved since the test began
        self.seg = -1
        self.stage = 0
        self.r_s_hat = math.nan
        self.u_err_hat = math.nan
        self.u_prev = 0j  # the reference written last tick
        self._acc = [0, 0.0, 0.0, 0.0]  # n, sum i, sum u (chosen), sum (u_ref - u_meas)
        self._levels: list[tuple[float, float]] = []
        self.u_sat_ticks = 0
        self.r_chk = [math.nan, math.nan]  # warming check's statistic, start and end [Ω]
        self._chk: list[tuple[float, float]] = []  # (mean i, mean u) of the current check's finished levels
        K = self._w.size
        self._I, self._U = np.zeros(K, complex), np.zeros(K, complex)  # running DFT sums of the multisine
        self.z = np.full(K, complex(math.nan, math.nan))

    def _safety(self, m: Measurement) -> None:
        mod = self.ctx.enc_modulus
        if self.count0 is None:
            self.count0 = m.enc_count
        d = self.shaft_counts = (m.enc_count - self.count0 + mod // 2) % mod - mod // 2
        if abs(d) > self.p["max_counts"]:
            raise StandstillViolation(f"the shaft moved {d:+d} encoder counts (> {self.p['max_counts']}) during the "
                                      "standstill test")  # fmt: skip
        i = abs(m.i_s)
        if i > self.i_limit:
            raise StandstillViolation(f"|i_s| = {i:.2f} A above the test's limit {self.i_limit:.2f} A")

    def _finish_level(self, kind: str) -> None:
        n, si, su, se = self._acc
        self._acc = [0, 0.0, 0.0, 0.0]
        if not n:
            return
        if kind == "dc":
            self._levels.append((si / n, su / n))
            self.u_err_hat = se / n if self.p["voltages"] == "measured" else math.nan
            if len(self._levels) >= 1 + len({lv[0] > 0 for lv in self._levels}):  # slope + an intercept per polarity
                i, u = np.array(self._levels).T
                self.r_s_hat = fits.dc_line(i, u).R_s
        elif kind in ("chk0", "chk1"):
            self._chk.append((si / n, su / n))
            if len(self._chk) == 2:
                (i1, u1), (i2, u2) = self._chk
                self.r_chk[kind == "chk1"] = (u1 - u2) / (i1 - i2)
                self._chk = []

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        self._safety(meas)
        T = self.ctx.T_s
        t = meas.t
        plan = self.plan
        seg, target, ac = plan.reference(t)
        if seg != self.seg:
            if self.seg >= 0:
                prev = plan.segments[self.seg]
                self._finish_level(prev.kind)
                if prev.kind == "ac":
                    self.z = self._U / self._I
            self.seg = seg
            self.stage = 0 if seg < 0 else STAGES.get(plan.segments[seg].kind, 0)
        step_max = self.p["slew"] * T
        if target and (self.i_dc > 0) != (target > 0) and abs(self.i_dc) <= CROSS_BAND:  # through zero at once
            self.i_dc = math.copysign(min(CROSS_BAND, abs(target)), target)
        else:
            self.i_dc += min(max(target - self.i_dc, -step_max), step_max)
        self.i_ref = self.i_dc + ac
        i_s = meas.i_s
        if self.stage and t >= plan.segments[seg].a0 - EPS:  # inside an analysis window
            u_meas = meas.u_s.real
            u_used = u_meas if self.p["voltages"] == "measured" else self.u_prev.real
            if self.stage == 4:  # the saturation check's multisine: fitted from the log only
                pass
            elif self.stage == 2:  # running DFT of the multisine's lines (whole common periods: the lock-in)
                ph = np.exp(-1j * self._w * t)
                self._I += i_s.real * ph
                self._U += u_used * ph
            else:
                acc = self._acc
                acc[0] += 1
                acc[1] += i_s.real
                acc[2] += u_used
                acc[3] += self.u_prev.real - u_meas
        e = complex(self.i_ref, 0.0) - i_s
        u = self.Kp * e + self.x
        lim = min(self.p["u_max"], meas.u_dc / SQRT3) if meas.u_dc > 0 else self.p["u_max"]
        if abs(u) > lim:  # saturated: hold the integrators (conditional integration)
            u *= lim / abs(u)
            self.u_sat_ticks += 1
            if self.u_sat_ticks > HEADROOM_TICKS:
                raise StandstillViolation(f"voltage headroom exceeded: the current controller has been at its limit "
                                          f"{lim:.1f} V for {self.u_sat_ticks} ticks (u_max {self.p['u_max']:g} V, "
                                          f"u_dc/sqrt(3) {meas.u_dc / SQRT3:.1f} V) at i_ref = {self.i_ref:+.2f} A")
        else:
            self.u_sat_ticks = 0
            self.x += self.Ki * T * e
        self.u_prev = u
        return u

    def internals(self) -> tuple[float, ...]:
        z = self.z
        zz = tuple(float(v) for pair in zip(z.real, z.imag) for v in pair)
        return (float(self.seg), float(self.stage), self.i_ref, float(self.shaft_counts), float(self.u_sat_ticks),
                self.r_s_hat, self.u_err_hat, self.r_chk[0], self.r_chk[1]) + zz  # fmt: skip
