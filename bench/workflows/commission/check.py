"""The closed-loop check of `bench commission` (stage 5): Fig. 5.7's low-speed experiment with the load stepping, a ramp
to the rated speed, a hold and a loaded hold, at the rated point scaled to the motor (`check_scenario`, its set-points
inside the rig's margins: `check_setpoints`); its run (`run_check`), its go criteria (`check_metrics`: the speed,
no trip, and what a real rig measures, `bench.workflows.commission.judge`; with the truth on the mock its flux errors)
and its figure (`check_figure`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.core import load_profiles as lp, nameplate
from bench.errors import BadInput
from bench.core.scenarios import I_MR_REF, T_MAGNETISE, Scaling, Scenario, check_profile
from bench.core.setpoints import I_MR, LOAD, SPEED, Margins
from bench.runtime.metrics import estimation_errors
from bench.core.plotstyle import save, pyplot
from bench.runtime.session import scenario_scaling, RunOptions, run
from bench.workflows.commission.judge import Window, criteria, Bench, NAMES as RIG_NAMES, draw
from bench.core.config import is_real_rig
from bench.daq import LogReader


#: the closed-loop check: Fig. 5.7's low-speed part (10 rad/s, 0 <-> 3 N m every 1/3 s for 2 s), a 1 s ramp
#: to the rated speed, 1 s hold without load, then 0.8 s with the load (the flux angle and the torque criteria
#: need a load at speed, `bench.workflows.commission.judge`)
LOW_SPEED = 10.0  # [rad/s electrical]
LOAD_STEP = 3.0  # [N m]
LOAD_HALF_PERIOD = 1.0 / 3.0  # [s]
LOW_TIME, RAMP_TIME, HOLD_TIME, LOADED_TIME = 2.0, 1.0, 1.0, 0.8  # [s]
HOLD_JUDGED = 0.3  # [s] judged at the end of the unloaded hold (its mean speed, the fluxes) ...
LOADED_JUDGED = 0.4  # [s] ... and of the loaded one
JUDGES = ("rig", "truth")  # --judge: what a real rig measures; the mock's truth as well
RATED_FRACTION = 0.75  # default rated speed: this fraction of the over-speed limit (capped by the voltage)
VOLTAGE_MARGIN = 0.85  # ... and at most this fraction of the linear-range voltage u_dc_min/sqrt(3) at i_mR


@dataclass(frozen=True)
class Go:
    """The go criteria of the closed-loop check (each one a line of the report)."""

    settled_abs: float = 2.0  # [rad/s] speed error allowed at the end of each load step ...
    settled_rel: float = 0.02  # ... plus this fraction of the reference
    hold_rel: float = 0.02  # speed error at the end of the hold at rated speed, relative
    flux_angle_p95_deg: float = 5.0  # --judge truth: flux angle error against the truth, p95 [deg]
    flux_mag_p95_rel: float = 0.10  # ... and flux magnitude error, p95, relative to the mean true |i_m|
    # the criteria without a truth (bench.workflows.commission.judge) take their limits from the measurements' errors


GO = Go()


def rated_speed(cfg: Any, requested: float | None = None) -> float:
    """The ramp's top speed [rad/s electrical]: ``requested``, else `RATED_FRACTION` of the over-speed
    limit, capped where the no-load stator voltage ω L_s i_mR reaches `VOLTAGE_MARGIN` of the linear range
    at the lowest DC link the rig allows (no field weakening in the FOC); i_mR the check's (`check_scenario`)."""
    k = nameplate.scaled(cfg.motor, cfg.nameplate)
    i_mR = I_MR_REF if k is None else k.i_mR
    v_cap = VOLTAGE_MARGIN * cfg.limits.u_dc_min / math.sqrt(3.0) / (cfg.motor.L_s * i_mR)
    if requested is not None:
        if not 0 < requested <= 0.9 * cfg.limits.omega_max:
            raise BadInput("--rated-speed", f"must be in (0, {0.9 * cfg.limits.omega_max:g}] rad/s (0.9 x the rig's "
                           f"over-speed limit), got {requested:g}")  # fmt: skip
        return float(requested)
    return float(min(RATED_FRACTION * cfg.limits.omega_max, v_cap))


def check_setpoints(cfg: Any, rated: float | None = None) -> None:
    """The closed-loop check's set-points (`check_scenario` at `rated_speed`, scaled to the plate) inside the rig's
    margins, as the check's own session will hold them (`bench.core.scenarios.check_profile`): `BadInput` naming what to
    change, before any test runs. (Its i_mR is the plate's rated one on the rig file's [motor]; the session checks
    it again on the identified motor.)"""
    margins = Margins.of_rig(cfg)
    scn = check_scenario(rated_speed(cfg, rated), scenario_scaling(cfg))
    scales = "the check's loads are Fig. 5.7's scaled to the plate's rated torque"
    check_profile(scn, margins, advice={
        SPEED: ("--rated-speed", f"give at most {margins.bound(SPEED):g} rad/s"),
        LOAD: (margins.torque_field, f"{scales}: a load machine whose torque limit allows them"),
        I_MR: ("limits.I_max", "the check's i_mR is the plate's rated one: a limits.I_max that allows it")})  # fmt: skip


def _fig57(scaling: Scaling | None) -> tuple[float, float]:
    """Fig. 5.7's low speed [rad/s] and load step [N m], scaled to another motor (``scaling``) than the thesis one."""
    return (LOW_SPEED, LOAD_STEP) if scaling is None else (LOW_SPEED * scaling.speed, LOAD_STEP * scaling.torque)


def check_scenario(w_rated: float, scaling: Scaling | None = None) -> Scenario:
    """Fig. 5.7's experiment, then a ramp to ``w_rated``, a hold without load and a hold with the load step; with
    ``scaling`` (another motor than the thesis one, `bench.runtime.session.scenario_scaling`) Fig. 5.7's speed, load and
    i_mR scaled to it."""
    t0 = T_MAGNETISE
    t1, t2 = t0 + LOW_TIME, t0 + LOW_TIME + RAMP_TIME
    t3 = t2 + HOLD_TIME
    low, step = _fig57(scaling)

    def speed(t: float) -> float:
        if t < t0:
            return 0.0
        if t < t1:
            return low
        return low + (w_rated - low) * min((t - t1) / RAMP_TIME, 1.0)

    low_load = lp.gated(lp.square(t0, LOAD_HALF_PERIOD, 0.0, step), t0, t1)
    return Scenario("commission", f"commissioning check: Fig. 5.7 ({low:.3g} rad/s, 0 <-> {step:.3g} N m every "
                    f"1/3 s), ramp to {w_rated:.0f} rad/s, hold, {step:.3g} N m", t3 + LOADED_TIME, speed,
                    lambda t, w: step if t >= t3 else low_load(t, w),
                    I_MR_REF if scaling is None else scaling.i_mR)  # fmt: skip


def check_windows(w_rated: float, scaling: Scaling | None = None) -> list[Window]:
    """The check's steady windows (`bench.workflows.commission.judge.Window`), each with its commanded load: the last
    third of every low-speed load segment (where the speed must have settled), the end of the unloaded hold at
    ``w_rated`` and the end of the loaded one (``scaling``: as `check_scenario`)."""
    scn, t0 = check_scenario(w_rated, scaling), T_MAGNETISE
    low, step = _fig57(scaling)
    t3 = t0 + LOW_TIME + RAMP_TIME + HOLD_TIME
    out = []
    for k in range(int(round(LOW_TIME / LOAD_HALF_PERIOD))):
        a, b = t0 + (k + 2.0 / 3.0) * LOAD_HALF_PERIOD, t0 + (k + 1) * LOAD_HALF_PERIOD
        out.append(Window(f"low speed {k + 1}", a, b, scn.load(0.5 * (a + b), low), False))
    out.append(Window("rated speed, no load", t3 - HOLD_JUDGED, t3, 0.0, True))
    out.append(Window(f"rated speed, {step:.3g} N m", t3 + LOADED_TIME - LOADED_JUDGED, t3 + LOADED_TIME,
                      step, True))  # fmt: skip
    return out


def check_metrics(d: dict[str, np.ndarray], w_rated: float, trip_t: float | None, go: Go = GO, *, judge: str = "rig",
                  model: Any = None, bench: Bench | None = None, rel_ci: dict[str, float] | None = None,
                  voltages: bool = True, scaling: Scaling | None = None) -> dict[str, Any]:  # fmt: skip
    """The closed-loop check's numbers and verdicts from a run's columns (``/rig/...``, ``/ctrl/...``, and
    ``/truth/...`` where the rig has them). ``judge`` "rig" judges what a real rig measures: the speed, the trip,
    and with ``model`` (the `MotorParams` under test) and ``bench`` (`bench.workflows.commission.judge.Bench`) the
    criteria without a truth (`bench.workflows.commission.judge.criteria`; ``rel_ci`` the model's intervals,
    ``voltages`` False where the rig measures none); a truth in the log is reported (``truth``), not judged. "truth"
    judges the flux against the truth as well (missing truth: those criteria fail). ``scaling``: Fig. 5.7's speed and
    load as `check_scenario` scaled them."""
    check_judge(None, judge)
    t, w, ref = d["/rig/t"], d["/ctrl/omega_hat"], d["/rig/omega_r_ref"]  # the encoder speed the FOC uses
    t0 = T_MAGNETISE
    low, step = _fig57(scaling)
    out: dict[str, Any] = {"rated_speed": w_rated, "low_speed": low, "load_step": step, "judge": judge,
                           "criteria": {}}  # fmt: skip
    crit = out["criteria"]
    steps = []
    windows = check_windows(w_rated, scaling)
    for win in (x for x in windows if not x.rated):  # the last third of every load segment: settled?
        sel = (t >= win.a) & (t < win.b)
        e = float(np.mean(w[sel] - ref[sel])) if sel.any() else math.nan
        seg = (t >= win.b - LOAD_HALF_PERIOD) & (t < win.b)
        steps.append({"t": win.b - LOAD_HALF_PERIOD, "load_N_m": win.load, "settled_error": e,
                      "peak_error": float(np.max(np.abs(w[seg] - ref[seg]))) if seg.any() else math.nan})  # fmt: skip
    out["load_steps"] = steps
    lim = go.settled_abs + go.settled_rel * low
    worst = max((abs(s["settled_error"]) for s in steps), default=math.nan)
    crit["speed settled after each load step"] = _crit(worst, lim, "rad/s")
    t3 = t0 + LOW_TIME + RAMP_TIME + HOLD_TIME
    hold = (t >= t3 - HOLD_JUDGED) & (t < t3)
    e_hold = float(np.mean(w[hold] - ref[hold])) / w_rated if hold.any() else math.nan
    out["hold_error_rel"] = e_hold
    crit["speed at rated speed"] = _crit(abs(e_hold) * 100.0, go.hold_rel * 100.0, "%")
    out["trip_time"] = trip_t
    crit["no trip"] = {"value": "tripped" if trip_t is not None else "none", "limit": "none", "pass": trip_t is None}
    if model is not None and bench is not None:
        rig_crit, out["rig"] = criteria(d, windows, model, bench, rel_ci, voltages=voltages)
        crit.update(rig_crit)
    if "/truth/i_m_re" in d:
        e = truth_errors(d, t0 + 0.1, trip_t)
        out["truth"] = {k: e[k] for k in ("flux_angle_p95_deg", "flux_angle_max_deg", "flux_mag_p95_rel", "tracking_rms")}
        out["truth"]["judged"] = judge == "truth"
    if judge == "truth" and "truth" in out:
        tr = out["truth"]
        crit["flux angle vs truth (p95)"] = _crit(tr["flux_angle_p95_deg"], go.flux_angle_p95_deg, "deg")
        crit["flux magnitude vs truth (p95)"] = _crit(tr["flux_mag_p95_rel"] * 100.0, go.flux_mag_p95_rel * 100.0, "%")
    elif judge == "truth":  # asked for, and the log has none (an emulator started elsewhere): cannot pass
        crit["flux vs truth"] = {"value": "no /truth in the log", "limit": "none", "pass": False}
    out["go"] = all(c["pass"] for c in crit.values())
    return out


def truth_errors(d: dict[str, np.ndarray], t_from: float, t_end: float | None = None) -> dict[str, Any]:
    """`bench.runtime.metrics.estimation_errors` of a run's columns over [t_from, t_end) (mock rig: against the
    truth)."""
    def cols(tp: str) -> dict[str, np.ndarray]:
        return {k.removeprefix(tp): v for k, v in d.items() if k.startswith(tp)}

    return estimation_errors(d["/rig/t"], cols("/ctrl/"), cols("/truth/"), d["/rig/omega_r_ref"], t_from, t_end)


def _crit(value: float, limit: float, unit: str) -> dict[str, Any]:
    return {"value": value, "limit": limit, "unit": unit, "pass": bool(value <= limit)}  # NaN fails


def run_check(rig: str, params: dict[str, Any], scn: Scenario, out_dir: Path, seed: int, realtime: bool | None,
                 allow_soft_realtime: bool, progress: bool) -> tuple[dict[str, Any], int, dict[str, np.ndarray]]:  # fmt: skip
    """One ordinary session (supervisor, log, shutdown) and its log's columns."""

    summary, code = run(RunOptions(rig=rig, controller="foc", scenario=scn, seed=seed, params=params,
                                   out_dir=out_dir, progress=progress, realtime=realtime,
                                   allow_soft_realtime=allow_soft_realtime, label="bench commission"))  # fmt: skip
    r = LogReader(Path(summary["log"]))
    topics = [tp for tp in ("/rig", "/ctrl", "/truth") if tp in r.topics()]
    cols = {f"{tp}/{k}": v for tp, c in zip(topics, r.read_ticks(*topics)) for k, v in c.items()}
    return summary, code, cols


def plot_check(d: dict[str, np.ndarray], m: dict[str, Any], png: Path, go: Go = GO) -> Path:
    """``closed_loop.png``: `check_figure` saved."""
    return save(check_figure(d, m, go), png)


#: how the check's figure draws a limit and a judged window
LIMIT_STYLE = {"color": "tab:red", "ls": "--", "lw": 0.9}
WINDOW_STYLE = {"color": "tab:orange", "alpha": 0.15, "lw": 0}


def check_figure(d: dict[str, np.ndarray], m: dict[str, Any], go: Go = GO):  # noqa: ANN201 - a matplotlib Figure
    """Every criterion of the check (`check_metrics`) in the panel of the signal it judges, with its limit and
    its window: the speed (no trip), the low-speed error after each load step, the error at rated speed,
    with ``--judge truth`` the flux angle and magnitude against the truth, and the criteria without a truth
    (`bench.workflows.commission.judge.draw`). A panel whose criterion failed has a red frame and a red "FAIL" title;
    the figure's title names the failed criteria."""
    plt = pyplot()
    crit = m.get("criteria", {})
    t = d["/rig/t"]
    truth = "/truth/i_m_re" in d and "flux angle vs truth (p95)" in crit
    names = ["no trip", "speed settled after each load step", "speed at rated speed"]
    names += ["flux angle vs truth (p95)", "flux magnitude vs truth (p95)"] if truth else []
    rig_names = [n for n in RIG_NAMES if n in crit]
    names += rig_names
    fig, axs = plt.subplots(len(names), 1, figsize=(9, 2.0 * len(names) + 1.0), sharex=True)
    trip = float(m["trip_time"]) if m.get("trip_time") is not None else None
    if trip is not None:
        for a in axs:
            a.axvline(trip, color="tab:red", lw=1.0, ls=":")
    _speed_panels(axs[:3], d, m, go)
    if truth:
        ok = t >= T_MAGNETISE + 0.1  # the window of check_metrics' truth errors
        if trip is not None:
            ok &= t < trip
        _truth_panels(axs[3], axs[4], d, ok, crit, go)
    for ax, name in zip(axs[len(names) - len(rig_names):], rig_names):
        draw(ax, name, d, m, LIMIT_STYLE, WINDOW_STYLE)
    for ax, name in zip(axs, names):
        _judged(ax, crit.get(name), name)
    axs[-1].set_xlabel("t [s]")
    for a in axs:
        a.grid(alpha=0.3)
    failed = [k for k, c in crit.items() if not c["pass"]]
    head = f"closed-loop check: {'GO' if m.get('go') else 'NO-GO'}"
    if failed:
        head += "\nfailed: " + ", ".join(failed)
    fig.suptitle(head, fontsize=10, color="black" if m.get("go") else "tab:red")
    return fig


def _judged(ax: Any, c: dict[str, Any] | None, name: str) -> None:
    """The criterion ``c``'s verdict as the panel's title; a red frame where it failed."""
    if c is None:
        return
    fmt = lambda x: x if isinstance(x, str) else f"{x:.3g} {c.get('unit', '')}".strip()  # noqa: E731
    ok = bool(c["pass"])
    limit = "" if c["limit"] == "none" else f" (limit {fmt(c['limit'])})"
    where = f", {c['window']}" if c.get("window") else ""
    ax.set_title(f"{name}: {fmt(c['value'])}{limit}{where} - {'pass' if ok else 'FAIL'}",
                 fontsize=9, loc="left", color="black" if ok else "tab:red", fontweight="normal" if ok else "bold")
    if not ok:
        for sp in ax.spines.values():
            sp.set_color("tab:red")
            sp.set_linewidth(2.0)


def _speed_panels(axs: Any, d: dict[str, np.ndarray], m: dict[str, Any], go: Go) -> None:
    """The speed (a trip), the low-speed error with each load step's settled window, the error at rated speed."""
    t = d["/rig/t"]
    w, ref = d["/ctrl/omega_hat"], d["/rig/omega_r_ref"]
    t1 = T_MAGNETISE + LOW_TIME
    t_end = t1 + RAMP_TIME + HOLD_TIME
    ax = axs[0]
    ax.plot(t, ref, color="tab:gray", ls=":", label="reference")
    ax.plot(t, w, "k", lw=0.8, label="encoder speed")
    ax.set_ylabel("speed\n[rad/s el.]")
    ax.legend(fontsize=8, loc="upper left")

    ax = axs[1]  # the low-speed part: the speed error, each load segment's settled window and its mean
    low = t < t1 + 0.2
    ax.plot(t[low], w[low] - ref[low], "k", lw=0.7, label="speed error")
    lim = go.settled_abs + go.settled_rel * m.get("low_speed", LOW_SPEED)
    ax.axhline(lim, **LIMIT_STYLE, label=f"limit \u00b1{lim:.3g} rad/s")
    ax.axhline(-lim, **LIMIT_STYLE)
    for k, st in enumerate(m.get("load_steps") or []):
        a_, b_ = st["t"] + 2.0 / 3.0 * LOAD_HALF_PERIOD, st["t"] + LOAD_HALF_PERIOD
        ax.axvspan(a_, b_, **WINDOW_STYLE, label="judged window" if k == 0 else None)
        e = st["settled_error"]
        bad = not abs(e) <= lim
        ax.plot([0.5 * (a_ + b_)], [e if np.isfinite(e) else 0.0], "X" if bad else "o", ms=8 if bad else 5,
                color="tab:red" if bad else "tab:green", label=None)
    ax2 = ax.twinx()
    ax2.plot(t[low], d["/rig/m_l_ref"][low], color="tab:blue", ls="--", lw=0.8)
    ax2.set_ylabel("load [N m]", color="tab:blue")
    ax.set_ylabel("speed error\n[rad/s]")
    ax.legend(fontsize=7, loc="lower right")

    ax = axs[2]  # the ramp and the hold: the error relative to the rated speed
    w_rated = float(m.get("rated_speed") or np.nan)
    high = t >= t1
    ax.plot(t[high], 100.0 * (w[high] - ref[high]) / w_rated, "k", lw=0.7, label="speed error")
    hl = go.hold_rel * 100.0
    ax.axhline(hl, **LIMIT_STYLE, label=f"limit \u00b1{hl:.3g} %")
    ax.axhline(-hl, **LIMIT_STYLE)
    ax.axvspan(t_end - HOLD_JUDGED, t_end, **WINDOW_STYLE, label="judged window (mean)")
    ax.set_ylim(-5.0 * hl, 5.0 * hl)
    ax.set_ylabel("speed error\n[% of rated]")
    ax.legend(fontsize=7, loc="lower left")


def _truth_panels(ax_angle: Any, ax_mag: Any, d: dict[str, np.ndarray], ok: np.ndarray, crit: dict[str, Any],
                  go: Go) -> None:  # fmt: skip
    """With ``--judge truth``: the flux angle and magnitude errors against the mock's truth over ``ok``."""
    t = d["/rig/t"]
    im = d["/truth/i_m_re"] + 1j * d["/truth/i_m_im"]
    im_hat = d["/ctrl/i_m_hat_re"] + 1j * d["/ctrl/i_m_hat_im"]

    def p95_line(ax: Any, name: str) -> None:  # the judged value beside its limit
        c = crit.get(name)
        if c is not None and np.isfinite(c["value"]):
            ax.axhline(c["value"], color="tab:purple", ls="-.", lw=1.3, label=f"p95 of |error|: {c['value']:.3g} {c['unit']}")
            ax.margins(y=0.15)

    ax = ax_angle
    ax.plot(t[ok], np.degrees(np.angle(im_hat[ok] * np.conj(im[ok]))), "k", lw=0.7, label="flux angle error")
    ax.axhline(go.flux_angle_p95_deg, **LIMIT_STYLE, label=f"limit of the p95 of |error|: {go.flux_angle_p95_deg:g} deg")
    ax.axhline(-go.flux_angle_p95_deg, **LIMIT_STYLE)
    p95_line(ax, "flux angle vs truth (p95)")
    ax.set_ylabel("flux angle\nerror [deg]")
    ax.legend(fontsize=7, loc="lower left")
    ax = ax_mag
    mean_im = float(np.mean(np.abs(im[ok]))) if ok.any() else np.nan
    ax.plot(t[ok], 100.0 * (np.abs(im_hat[ok]) - np.abs(im[ok])) / mean_im, "k", lw=0.7, label="flux magnitude error")
    ml = go.flux_mag_p95_rel * 100.0
    ax.axhline(ml, **LIMIT_STYLE, label=f"limit of the p95 of |error|: {ml:g} %")
    ax.axhline(-ml, **LIMIT_STYLE)
    p95_line(ax, "flux magnitude vs truth (p95)")
    ax.set_ylabel("flux magnitude\nerror [% of |i_m|]")
    ax.legend(fontsize=7, loc="lower left")


def check_judge(cfg: Any, judge: str) -> None:
    """``--judge``: one of `JUDGES`; "truth" only on a rig that has one (the mock plant, in-process emulators;
    ``cfg`` None: not checked)."""
    if judge not in JUDGES:
        raise BadInput("--judge", f"must be one of {', '.join(JUDGES)}, got {judge!r}")
    if judge == "truth" and cfg is not None and is_real_rig(cfg):
        raise BadInput("--judge", f"truth needs a rig with a truth (the mock plant or the emulators); rig {cfg.name!r} "
                       "drives real devices: judge with --judge rig")  # fmt: skip
