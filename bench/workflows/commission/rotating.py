"""Rotating identification (`bench identify --rotating`): the no-load test at several flux levels and
the mechanics (J, viscous and Coulomb friction), with a free shaft, as one session.

**The drive.** Rotor-flux-oriented speed control (thesis 4.2: speed PI (4.7)(4.8), P control of
i_mR (4.4), current PIs with the decoupling (4.13)(4.14), the current-model observer (4.15); the
parts of `bench.controllers.foc`), on the *model* of the standstill test: its inverse-Γ parameters
R_s, L'_s, R'_r, L'_m (``model_*``; 0: the rig's ``[motor]``). Everything the controller needs of the
machine is inverse-Γ (L'_s, L'_m, R'_r, T_r = L'_m/R'_r, k = 3/2 Z_p L'_m), so no L_s = L_r
assumption enters the drive. From the end of the no-load test on (the mechanics and the end), the drive's L'_m
is the one the test measured at the rated flux, R'_r referred at it (`at_flux`; logged as ``L_M_drive``): on a
saturating machine the standstill L'_m is the incremental one, and a current model (4.15) with it lets the flux
fall under torque (`RotatingIdController._rated_model`). The DC load machine commands 0 N m throughout.

**The plan** (`Plan`, a function of the parameters only, so the controller and the fit agree):

1. magnetise at standstill (i_mR at the a-priori rated level i_mR,n: ``i_mR_rated``, which `identify_rotating`
   takes from the plate, `bench.core.nameplate.rated_flux`, else ``psi_rated`` / L_m of the model; L_m
   = sqrt(L'_m (L'_s + L'_m)) under L_s = L_r), ramp to ``omega_test``;
2. **flux scan** (``levels_from = "flux"``, the default): at ``omega_test`` i_mR drops to 0.25 x i_mR,n,
   settles, then rises at ``scan_rate`` x i_mR,n per second (up to 0.9 x the test's current limit) while the
   main flux is estimated on every tick from the measured voltage and current, |ψ_m| = |(u_s - R_s i_s)/(jω_s)
   - L_sσ i_s| (steady state of (3.34), L_sσ = L'_s/2 as in `bench.core.nameplate`), low-passed over `PSI_TAU`;
   from the highest target it falls again at the same rate to the lowest. Each level's i_mR is the mean of the
   currents where the estimate reached its flux target on the way up and left it on the way down: the flux
   lags the current (the rotor's T_r/(1 + K_m) (4.4), the low-pass) alike both ways, so the lag cancels,
   whatever T_r the saturated machine has. So the levels are fluxes, ``flux_lo`` to ``flux_hi`` x ``psi_rated`` (the
   plate's rated flux, `bench.core.nameplate.rated_flux`: `identify_rotating` sets it), reached on any
   magnetising curve within the current limit, and nothing of them depends on the model's L_m (it only
   seeds the scan). ``levels_from = "current"``: no scan, the levels are ``flux_lo`` to ``flux_hi`` x i_mR,n
   itself (a wrong L_m, e.g. a standstill test's incremental one on a saturating motor, misplaces them);
3. **no-load test**: at ``omega_test``, i_mR stepped over ``flux_levels`` levels from ``flux_lo``
   to ``flux_hi``, then back to 1.0 x (the level of step 4). Each level
   settles, then ``level_average`` seconds are analysed. Without load the slip is only the friction's
   (0.1-0.7 rad/s against about 150 rad/s of stator frequency), and the stator sees the inverse-Γ
   circuit (4.2)(4.3) in steady state: Z = R_s + jω_s L'_s + (jω_s L'_m ∥ R'_r ω_s/ω_slip). Its
   magnetising branch Y_m = 1/(Z - R_s - jω_s L'_s) has Im Y_m = -1/(ω_s L'_m) *at any slip*, and an
   error in R_s enters L'_m only in second order, so L'_m follows from the measured voltage and
   current with the standstill R_s, L'_s (`bench.workflows.commission.rotating_fit`);
4. **mechanics**: at the rated flux level, speed holds at ± k/``holds`` x ``omega_test``
   (k = holds..1; there J ω̇ = 0 and m_e is the friction, B ω + T_c sgn ω), joined by speed ramps at
   ``accel`` (there m_e is mostly J ω̇). m_e (4.6) = 3/2 Z_p L'_m Im{i_s i_m*} with the current
   model (4.15) run offline on the logged currents and encoder angle with the L'_m just measured at
   that flux (the drive steers the field with the same L'_m here, so the flux stays at that level);
   friction from the holds, J from the ramps, by least squares on the integrated equation
   of motion (3.37) (`bench.workflows.commission.rotating_fit.mechanics_fit`);
5. ramp to 0, hold, demagnetise.

Why speed control throughout, not torque steps or a coast-down: the trajectory is the plan's whatever
J is (a torque step on an unknown J runs to an unknown speed), so the over-speed margin holds by
construction and the run has a fixed length; the holds measure friction at a known speed with no
inertial torque, both directions, which a coast-down (friction only over a falling speed, B and T_c
hard to separate) does not; and the flux stays on, so m_e is known throughout.

About 13.2 s of rig time with the defaults (`Plan.duration`; 11.2 s without the scan); `bench identify` and
`bench commission` let each flux level settle `SETTLE_T_R` rotor time constants of the model (0.85 s on the thesis
motor: 16.7 s in all).

**J** is everything that turns with the shaft: the motor's rotor, the coupling and the DC load
machine's rotor (the mock plant's J is this total, `bench.params.MotorParams`).

**Safety** (each a `RotatingViolation`: one line, a supervisor trip, the ordinary shutdown):
refused at construction (`BadInput`): ``omega_test`` above 0.7 x the rig's over-speed limit
omega_max, a flux level (``levels_from = "current"``) or a ramp torque that needs more than the test's current
limit, ``flux_hi`` below `FLUX_REACH` x the rated flux (``levels_from = "flux"``). On every
tick: the encoder speed above 0.8 x omega_max; |i_s| above 1.25 x the test's current limit + 0.3 A;
the voltage the plan needs above 0.8 of the inverter's linear range (checked at the first tick with
the measured DC link) or the current loop at its voltage limit for more than `SAT_TIME`; the shaft
not following the speed reference (`TRACK_TIME`; a blocked or loaded shaft). The supervisor's own
trips stay armed.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench.core import load_profiles as lp, nameplate
from bench.workflows.commission import id_plots, rotating_fit as rf
from bench.workflows.commission.circuit import InverseGamma
from bench.workflows.commission.rotating_plan import (FLUX_REACH, I_MARGIN, MIN_PERIODS, PSI_TAU, SAT_TIME, SCAN_CAP,
                                                      SCAN_START, SCHEMA, SETTLE_T_R, SPEED_PLAN_MAX, SPEED_TRIP,
                                                      STAGES, TRACK_TIME, U_HEADROOM, Plan, RotatingViolation, at_flux,
                                                      model_of, motor_of, rated_i_mR)
from bench.controllers.base import Controller, ControllerContext
from bench.controllers.foc import FocController
from bench.controllers.schema import Param, validate
from bench.errors import BadInput
from bench.hal import Measurement
from bench.core.scenarios import Scenario
from bench.core.config import load as load_rig
from bench.runtime.session import RunOptions, run

if TYPE_CHECKING:
    from bench.core.config import RigConfig

class RotatingIdController(Controller):
    name = "rotating_id"
    summary = "rotating identification: no-load test at several flux levels, speed holds and ramps (J, friction)"
    schema: dict[str, Param] = SCHEMA
    fields = FocController.fields + ("segment", "stage", "omega_ref", "i_mR_ref_plan", "theta_mech", "psi_m_est",
                                     "L_M_drive")  # fmt: skip

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        super().__init__(ctx, **params)
        p = self.p
        f = f"controller.{self.name}"
        _rig_refusals(p, ctx.omega_max, ctx.I_max)
        self.g = model_of(p, ctx.motor)
        model = motor_of(self.g, ctx.motor)
        self.I_test = p["i_max"] or ctx.I_max
        self.plan = Plan.from_params(p, rated_i_mR(p, self.g))
        self.flux_mode = p["levels_from"] == "flux"
        kinds = [x.kind for x in self.plan.segments]
        self._scan_seg = kinds.index("scan") if self.flux_mode else len(kinds)
        self._targets = sorted({x.flux for x in self.plan.segments if x.kind == "level"})
        # the flux lags the rising i_mR reference by the flux loop's T_r/(1 + K_m) (4.4) and the estimate's low-pass
        T_r = self.g.L_M / self.g.R_R
        self._scan_lag = p["scan_rate"] * self.plan.i_mR_n * (PSI_TAU + T_r / (1.0 + FocController.defaults["flux_Km"]))
        self.i_cap = SCAN_CAP * self.I_test
        if self.flux_mode:
            if p["flux_hi"] < FLUX_REACH:
                raise BadInput(f"{f}.flux_hi", f"must be >= {FLUX_REACH:g} (the levels reach at least {FLUX_REACH:g} x "
                               f"the rated flux), got {p['flux_hi']:g}")  # fmt: skip
            i_hi = min(self.plan.flux_peak * self.plan.i_mR_n, self.i_cap)  # a priori (the voltage check below)
            k_t = 1.5 * model.Z_p * p["psi_rated"]  # (4.6), psi_R = L'_m i_mR close to the rated |psi_m| [N m/A]
        else:
            i_hi = self.plan.flux_peak * self.plan.i_mR_n
            if i_hi > 0.9 * self.I_test:
                raise BadInput(f"{f}.flux_hi", f"asks for i_mR = {i_hi:.2f} A, more than 0.9 x the test's current "
                               f"limit {self.I_test:g} A (rated i_mR = {p['psi_rated']:g} Wb / L_m = "
                               f"{self.plan.i_mR_n:.2f} A): lower flux_hi or psi_rated")  # fmt: skip
            k_t = 1.5 * model.Z_p * self.g.L_M * self.plan.i_mR_n  # (4.6) at the rated level [N m/A]
        i_q = ctx.motor.J * p["accel"] / model.Z_p / k_t  # J omega_dot_mech = m_e on the ramps
        if math.hypot(self.plan.i_mR_n, i_q) > 0.9 * self.I_test:
            raise BadInput(f"{f}.accel", f"the ramps need i_sq = {i_q:.2f} A (J = {ctx.motor.J:g} kg m^2 of [motor]) "
                           f"beside i_mR = {self.plan.i_mR_n:.2f} A, more than 0.9 x the test's current limit "
                           f"{self.I_test:g} A: lower accel")  # fmt: skip
        self.omega_trip = SPEED_TRIP * ctx.omega_max
        self.i_limit = I_MARGIN[0] * self.I_test + I_MARGIN[1]
        self.track_tol = max(p["track_tol"] * p["omega_test"], 20.0)
        # the voltage the plan needs at its fastest, strongest point: omega_s L_s i_mR + R_s i (steady state (4.10));
        # with the scan: omega_s |psi_s| at the highest flux target, psi_s = psi_m + L_s_sigma i (i a priori; the
        # current loop's voltage limit trips the test all the same, SAT_TIME)
        psi_hi = (p["flux_hi"] * p["psi_rated"] + 0.5 * self.g.L_sigma * i_hi if self.flux_mode
                  else (self.g.L_sigma + self.g.L_M) * i_hi)  # fmt: skip
        self.u_need = self.plan.omega_peak * psi_hi + self.g.R_s * math.hypot(i_hi, i_q)
        self._rated_level = max(j for j, x in enumerate(self.plan.segments) if x.kind == "level")  # (the 1.0 one)
        self.g_drive = self.g
        self.foc = self._drive(self.g)
        # what the voltage channel and the sampling make of the impedance at the no-load test's speed (the fit's
        # corrections, `rotating_fit.level_fit`), on the model: computed here, not in the loop (`_rated_model`)
        w, filt = p["omega_test"], (p["u_filter_fc"], p["u_filter_zeta"])
        self._y_per_z = rf.filter_response(w, *filt) * rf.sampled_ratio(self.g, w, w, ctx.T_s, *filt)
        self.reset()

    def _drive(self, g: InverseGamma) -> FocController:
        """The FOC on the model ``g`` (module docstring: the drive)."""
        ctx, bw = self.ctx, self.p["speed_bw"]
        return FocController(replace(ctx, motor=motor_of(g, ctx.motor), I_max=self.I_test),
                             speed_Kp=bw * ctx.motor.J / ctx.motor.Z_p, speed_Ti=4.0 / bw)  # fmt: skip

    def reset(self) -> None:
        if self.g_drive != self.g:
            self.foc = self._drive(self.g)
        self.foc.reset()
        self.g_drive = self.g  # the drive's model: the standstill one until the no-load test has L'_m at rated flux
        self._ui = [0j, 0j]  # ... its window's sums: u_s and i_s in the field frame, omega_mR, ticks (`_rated_model`)
        self._ws = 0.0
        self._n = 0
        self.seg = -1
        self.stage = 0
        self.w_ref = self.i_ref = 0.0
        self.count_prev: int | None = None
        self.counts = 0  # encoder counts since the start, unwrapped
        self.theta = 0.0
        self._sat = self._off = 0  # ticks at the voltage limit / off the speed reference, in a row
        self._first = True
        self.psi_hat = 0.0  # main-flux estimate [Wb] (levels_from = flux)
        self._scan_i = 0.0  # the scan's current reference [A]
        self._falling = False  # the scan's second half
        self._scan_top = 0.0  # the highest current of the scan [A]
        self._up: dict[float, float] = {}  # flux target (x psi_rated) -> the scan's i_mR where the estimate reached it
        self._down: dict[float, float] = {}  # ... and where it fell below it again on the way down

    def _safety(self, m: Measurement) -> None:
        mod = self.ctx.enc_modulus
        if self.count_prev is not None:
            self.counts += (m.enc_count - self.count_prev + mod // 2) % mod - mod // 2
        self.count_prev = m.enc_count
        self.theta = self.counts * 2.0 * math.pi / self.ctx.counts_per_rev
        if self._first:
            self._first = False
            u_lim = m.u_dc * self.foc.p["u_margin"] / math.sqrt(3.0)
            if self.u_need > U_HEADROOM * u_lim:
                raise RotatingViolation(f"the plan needs about {self.u_need:.0f} V, more than {U_HEADROOM:g} x the "
                                        f"inverter's {u_lim:.0f} V at u_dc = {m.u_dc:.0f} V: lower omega_test or "
                                        "flux_hi")  # fmt: skip
        w = self.foc.encoder.omega_r  # filtered encoder speed of the last tick
        if abs(w) > self.omega_trip:
            raise RotatingViolation(f"speed {w:+.0f} rad/s above {SPEED_TRIP:g} x omega_max = {self.omega_trip:g} "
                                    "rad/s")  # fmt: skip
        i = abs(m.i_s)
        if i > self.i_limit:
            raise RotatingViolation(f"|i_s| = {i:.2f} A above the test's limit {self.i_limit:.2f} A")
        T = self.ctx.T_s
        self._off = self._off + 1 if abs(self.w_ref - w) > self.track_tol else 0
        if self._off * T > TRACK_TIME:
            raise RotatingViolation(f"the shaft does not follow the speed reference ({w:+.0f} rad/s for "
                                    f"{self.w_ref:+.0f} rad/s over {TRACK_TIME:g} s): is it free?")  # fmt: skip
        self._sat = self._sat + 1 if self.foc.current.saturated else 0
        if self._sat * T > SAT_TIME:
            raise RotatingViolation(f"voltage headroom exceeded: the current loop at its voltage limit for "
                                    f"{SAT_TIME * 1e3:g} ms")  # fmt: skip

    @property
    def omega_u(self) -> float:
        """The wrapped FOC's field frequency (bench.hal.Command.omega_u: the drive's stall ride-through)."""
        return self.foc.omega_u

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        self._safety(meas)
        self.seg, self.w_ref, self.i_ref = self.plan.at(meas.t)
        self.stage = 0 if self.seg < 0 else STAGES[self.plan.segments[self.seg].kind]
        if self.flux_mode:
            self.i_ref = self._flux_level(meas)
        if self.seg == self._rated_level and meas.t >= self.plan.segments[self.seg].a0:
            i_m = self.foc.i_m_hat  # (the last tick's: the same rotation for both, the ratio is what counts)
            rot = i_m.conjugate() / max(abs(i_m), 1e-9)
            self._ui[0] += meas.u_s * rot
            self._ui[1] += meas.i_s * rot
            self._ws += self.foc.omega_mR
            self._n += 1
        elif self._n and self.g_drive is self.g:
            self._rated_model()
        return self.foc.step(meas, self.w_ref, self.i_ref)

    def _rated_model(self) -> None:
        """After the no-load test the drive steers the field with the L'_m the test measured at the rated flux (the
        last level's window), not the standstill model's: the current model (4.15) orients the field with
        T_r = L'_m/R'_r and the speed loop's torque is (4.6) with L'_m. A saturating machine's standstill L'_m is
        the incremental one, far below the secant one at rated flux; with it the orientation is detuned as soon as
        torque current flows, the main flux falls on every ramp, away from the flux where the fit's linear current
        model has its L'_m, and J from (3.37) comes out low (docs/results/fleet-commission.md). Steering with the
        measured L'_m keeps the flux at that level, where the fit's torque model holds. The estimate: the fit's
        branch inductance (`rotating_fit.branch_L`) of the window's mean impedance, voltage over current in the
        field frame (the inverter's 6k ± 1 harmonics average out there), the voltage channel's filter and the
        sampling taken out as the fit does (`_y_per_z`). The new FOC takes over the running one's state
        (`FocController.take_over_from`: bumpless)."""
        w = self._ws / self._n
        Z = self._ui[0] / self._ui[1] / self._y_per_z
        L_M = rf.branch_L(Z, w, self.g.R_s, self.g.L_sigma) if abs(w) > 1.0 else math.nan
        if not 0.0 < L_M < math.inf:
            raise RotatingViolation(f"the no-load test at the rated flux gives L'_m = {L_M:.4g} H at {w:.0f} rad/s "
                                    "(no magnetising branch): the voltage or current measurement?")  # fmt: skip
        self.g_drive = at_flux(self.g, L_M)
        foc = self._drive(self.g_drive)
        foc.take_over_from(self.foc)
        self.foc = foc

    def _flux_level(self, m: Measurement) -> float:
        """levels_from = flux: the main-flux estimate (module docstring, step 2) and the i_mR reference of the scan,
        of the levels (the scan's current where it reached their flux) and of everything after (the 1.0 level's)."""
        w = self.foc.omega_mR
        if abs(w) > 1.0:  # (at standstill the voltage says nothing of the flux)
            i = m.i_s
            psi = abs((m.u_s - self.g.R_s * i) / complex(0.0, w) - 0.5 * self.g.L_sigma * i)
            self.psi_hat += (psi - self.psi_hat) * min(1.0, self.ctx.T_s / PSI_TAU)
        if self.seg < self._scan_seg:
            return self.i_ref if self.seg >= 0 else 0.0  # the a-priori level (after the end: 0)
        s, i_n = self.plan.segments[self.seg], self.plan.i_mR_n
        lo = SCAN_START * i_n
        if s.kind == "scan":
            step, psi_n = self.p["scan_rate"] * i_n * self.ctx.T_s, self.p["psi_rated"]
            if self._scan_i == 0.0:  # the scan's first tick
                self._scan_i = lo
            elif m.t < s.a0:  # settling at the low level
                pass
            elif not self._falling:  # rising: where the estimate reaches each target
                for x in self._targets:
                    if x not in self._up and self.psi_hat >= x * psi_n:
                        self._up[x] = self._scan_i
                self._scan_top = self._scan_i
                if len(self._up) == len(self._targets) or self._scan_i >= self.i_cap:
                    self._falling = True
                else:
                    self._scan_i = min(self._scan_i + step, self.i_cap)
            elif len(self._down) < len(self._up):  # falling at the same rate: where it leaves each again
                for x in self._up:
                    if x not in self._down and self.psi_hat <= x * psi_n:
                        self._down[x] = self._scan_i
                if len(self._down) < len(self._up):
                    self._scan_i = max(self._scan_i - step, lo)
            return self._scan_i
        level = s.flux if s.kind == "level" else 1.0
        if level in self._down:  # the estimate lags the current alike both ways: the mean has no lag
            i = 0.5 * (self._up[level] + self._down[level])
        elif level in self._up:  # (the scan ended first: the lag from the model's T_r taken off)
            i = max(self._up[level] - self._scan_lag, lo)
        else:  # not reached within the current limit: the most the scan gave
            i = self._scan_top
        return i * (self.i_ref / (s.flux * i_n)) if s.kind == "end" else i  # (end: demagnetising)

    def internals(self) -> tuple[float, ...]:
        return self.foc.internals() + (float(self.seg), float(self.stage), self.w_ref, self.i_ref, self.theta,
                                       self.psi_hat, self.g_drive.L_M)  # fmt: skip


def _rig_refusals(p: dict[str, Any], omega_max: float | None, I_max: float) -> None:
    """The refusals of checked parameters ``p`` that need the rig's limits only, not the drive's model."""
    f = f"controller.{RotatingIdController.name}"
    if omega_max is None:
        raise BadInput(f, "the rotating test needs the rig's over-speed limit ([limits] omega_max)")
    if p["flux_lo"] >= p["flux_hi"]:
        raise BadInput(f"{f}.flux_lo", f"must be below flux_hi = {p['flux_hi']:g}, got {p['flux_lo']:g}")
    w_lim = SPEED_PLAN_MAX * omega_max
    if p["omega_test"] > w_lim:
        raise BadInput(f"{f}.omega_test", f"must be <= {w_lim:g} rad/s ({SPEED_PLAN_MAX:g} x the rig's "
                       f"omega_max = {omega_max:g}; the test trips at {SPEED_TRIP:g} x), got "
                       f"{p['omega_test']:g}")  # fmt: skip
    periods = p["level_average"] * p["omega_test"] / (2.0 * math.pi)  # no load: omega_s = omega_test
    if periods < MIN_PERIODS:
        raise BadInput(f"{f}.level_average", f"holds {periods:.1f} electrical periods at omega_test = "
                       f"{p['omega_test']:g} rad/s; at least {MIN_PERIODS} are analysed: must be >= "
                       f"{MIN_PERIODS * 2 * math.pi / p['omega_test']:.3g} s, got "
                       f"{p['level_average']:g}")  # fmt: skip
    if (p["i_max"] or I_max) > I_max:
        raise BadInput(f"{f}.i_max", f"must be <= the rig's I_max = {I_max:g} A, got {p['i_max']:g}")


def plate_params(cfg: RigConfig, params: dict[str, Any], g: InverseGamma | None = None) -> dict[str, Any]:
    """``params`` with what the rig's plate sets where they leave it (`bench.core.nameplate`): on another motor's plate
    than the thesis one ``omega_test`` and ``accel`` scaled to the rated speed (capped at `SPEED_PLAN_MAX` x the
    over-speed limit) and, with the drive's model ``g``, ``psi_rated``, the plate's rated main flux from R_s and
    L'_s (`bench.core.nameplate.rated_flux`; the thesis motor's is the default 0.88 Wb); on any plate, with ``g``, the
    flux scan's seed ``i_mR_rated``, the plate's rated i_sd (no L_m in it); with ``g`` on any rig, ``level_settle``
    at least `SETTLE_T_R` rotor time constants of ``g``."""
    k = nameplate.scaled(cfg.motor, cfg.nameplate)
    d = RotatingIdController.defaults
    out: dict[str, Any] = {}
    if k is not None:
        out = {"omega_test": min(d["omega_test"] * k.speed, SPEED_PLAN_MAX * cfg.limits.omega_max),
               "accel": d["accel"] * k.speed}  # fmt: skip
    if g is not None:
        out["level_settle"] = round(min(max(d["level_settle"], SETTLE_T_R * g.L_M / g.R_R), 10.0), 3)  # (its range)
    if g is not None and cfg.nameplate is not None:
        rated = nameplate.rated_flux(cfg.nameplate, g.R_s, g.L_sigma)
        if k is not None:
            out["psi_rated"] = rated.psi_m
        if params.get("levels_from", d["levels_from"]) == "flux":  # the scan's seed: the plate's, not L_m's
            out["i_mR_rated"] = rated.i_sd
    return {**out, **params}


def check_params(params: dict[str, Any], cfg: RigConfig, after_standstill: bool = True) -> dict[str, Any]:
    """The rotating test's parameters (``-r``), as far as they can be checked before any test runs: their names,
    types and ranges, what needs only the rig ``cfg`` (`_rig_refusals`), and ``after_standstill`` no ``model_*``
    (the standstill result gives them). BadInput naming the field; the refusals that need the drive's model
    (``flux_hi``, ``accel``) come when the test is built (`identify_rotating`)."""
    p = validate(f"controller.{RotatingIdController.name}", RotatingIdController.schema, plate_params(cfg, params))
    if after_standstill:
        for n in STANDSTILL_KEYS:
            if params.get(f"model_{n}") not in (None, 0, 0.0):
                raise BadInput(f"--rotating-param model_{n}", "is set by the standstill test that runs first; "
                               "not a -r parameter of bench identify --rotating or bench commission")  # fmt: skip
    _rig_refusals(p, cfg.limits.omega_max, cfg.limits.I_max)
    return p


# --- the session ------------------------------------------------------------------------------------------
def scenario(plan: Plan) -> Scenario:
    """The session's scenario: the plan's speed and i_mR references (for the log), no load."""
    return Scenario("rotating", "rotating identification (bench identify --rotating): no-load test, speed holds "
                    "and ramps, no load", plan.duration, lambda t: plan.at(t)[1], lp.constant(0.0),
                    lambda t: plan.at(t)[2])  # fmt: skip


STANDSTILL_KEYS = ("R_s", "L_sigma", "R_R", "L_M")  # inverse_gamma of a standstill result -> model_*


def standstill_ci(standstill: dict[str, Any]) -> dict[str, float]:
    """The standstill result's uncertainty the rotating fit passes on (`rotating_fit.analyse_log`'s ``model_ci``):
    the 95 % half-widths of its inverse-Γ values, and ``R_r_rel`` the relative one of R_r of the T form (the
    mechanics' current model refers it)."""
    ci: dict[str, float] = {}
    for n, x in standstill["inverse_gamma"].items():
        lo, hi = x.get("ci95", [x["value"]] * 2)
        ci[n] = (hi - lo) / 2.0
    r_r = (standstill.get("thesis_L_s_eq_L_r") or {}).get("R_r")
    if isinstance(r_r, dict) and "ci95" in r_r:
        ci["R_r_rel"] = (r_r["ci95"][1] - r_r["ci95"][0]) / 2.0 / abs(r_r["value"])
    return ci


def identify_rotating(rig: str, standstill: dict[str, Any] | None = None, *, params: dict[str, Any] | None = None,
                      seed: int = 0, out_dir: Path = Path("runs"), progress: bool = False, realtime: bool | None = None,
                      allow_soft_realtime: bool = False) -> dict[str, Any]:  # fmt: skip
    """Run the rotating test on ``rig`` as one session and fit it (module docstring; the fit:
    `bench.workflows.commission.rotating_fit`). ``standstill``: `bench.workflows.commission.identify.identify`'s result,
    whose inverse-Γ R_s, L'_s, R'_r, L'_m are the drive's model and the fit's R_s, L'_s (None: the rig's [motor]).
    Returns the identification (JSON-able), or on a trip {"tripped", "run", "exit_code"}."""
    import json


    params = dict(params or {})
    ci: dict[str, float] = {}
    if standstill is not None:
        g = standstill.get("inverse_gamma")
        if not isinstance(g, dict) or any(n not in g for n in STANDSTILL_KEYS):
            why = f"; it tripped: {standstill['tripped']}" if "tripped" in standstill else ""
            raise BadInput("standstill", "needs the inverse_gamma block (R_s, L_sigma, R_R, L_M) of a standstill "
                           f"identification{why}")  # fmt: skip
        for n in STANDSTILL_KEYS:
            given = params.get(f"model_{n}")
            if given not in (None, 0, 0.0) and given != g[n]["value"]:
                raise BadInput(f"--param model_{n}", "is given twice (also by the standstill result); give one")
            params[f"model_{n}"] = float(g[n]["value"])
        ci = standstill_ci(standstill)
    cfg = load_rig(rig)
    params = plate_params(cfg, params, model_of({**RotatingIdController.defaults, **params}, cfg.motor))
    # the plugin built once here for its plan (the scenario) and its refusals (BadInput), before anything
    # runs; the encoder geometry does not enter the plan
    ctx = ControllerContext(T_s=cfg.T_s, motor=cfg.motor, I_max=cfg.limits.I_max, counts_per_rev=4096,
                            enc_modulus=1 << 16, omega_max=cfg.limits.omega_max)  # fmt: skip
    plan = RotatingIdController(ctx, **params).plan
    summary, code = run(RunOptions(rig=rig, controller="rotating_id", scenario=scenario(plan), seed=seed,
                                   params=params, out_dir=out_dir, progress=progress, realtime=realtime,
                                   allow_soft_realtime=allow_soft_realtime,
                                   label="bench identify --rotating"))  # fmt: skip
    if code != 0:
        return {"tripped": summary["trip_cause"], "run": summary, "exit_code": code}
    log = Path(summary["log"])
    out = rf.analyse_log(log, model_ci=ci, keep_series=True)
    folder = log.parent
    out.update({"seed": seed, "run_plot": summary["plot"], "rig_time_s": summary["duration"]})
    if standstill is None and not any(params.get(f"model_{n}") for n in STANDSTILL_KEYS):
        out["warnings"].append("no standstill result: the model is the rig's [motor]; L_m needs its R_s and L'_s, "
                               "J and friction scale with its R'_r (the torque of the current model)")  # fmt: skip
    out["plots"] = [str(id_plots.plot_magnetising(out, folder / "rot_magnetising.png")),
                    str(id_plots.plot_mechanics(out, folder / "rot_mechanics.png"))]  # fmt: skip
    del out["_series"]
    (folder / "identify_rotating.json").write_text(json.dumps(out, indent=2))
    out["json"] = str(folder / "identify_rotating.json")
    return out


def motor_from(standstill: dict[str, Any], rotating: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The [motor] values of a standstill + rotating identification (thesis form, L_s = L_r, 3.6):
    L_m the secant value at the rated flux (`L_m_rated`, rotating), L_s = L_r = L_m + l with the T form's leakage
    l of the standstill model, which does not saturate (`rotating_fit.leakage`, as the rotating fit holds it);
    R_s and R_r as at standstill (resistances do not saturate); J, B_visc, m_coulomb from the rotating test. Each
    {"value", "ci95"}; L_s's interval from l's and L_m's."""
    L_m = rotating["L_m_rated"]
    th = standstill["thesis_L_s_eq_L_r"]
    g = InverseGamma(*(standstill["inverse_gamma"][n]["value"] for n in STANDSTILL_KEYS))
    leak, ci_leak = rf.leakage(g, standstill_ci(standstill))
    lm = L_m["value"]
    L_s = lm + leak
    ci = math.hypot((L_m["ci95"][1] - L_m["ci95"][0]) / 2.0, ci_leak)
    L_s_val = {"value": L_s, "ci95": [L_s - ci, L_s + ci]}
    mech = rotating["mechanics"]
    out = {"L_s": L_s_val, "L_r": dict(L_s_val), "L_m": {"value": lm, "ci95": list(L_m["ci95"])},
           "R_s": th["R_s"], "R_r": th["R_r"]}  # fmt: skip
    out.update({n: {"value": mech[n]["value"], "ci95": list(mech[n]["ci95"])} for n in ("J", "B_visc", "m_coulomb")})
    return out
