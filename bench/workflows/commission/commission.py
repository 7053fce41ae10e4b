"""`bench commission`: from a motor with nameplate data only to a verified closed loop (thesis 3.6, 5.6, 6.2).

One command, in stages, each recorded in ``commission.json`` and the report:

0. **the rig** - it must state the motor's plate (``[nameplate]``, `bench.core.nameplate`, checked against ``[limits]``
   and any ``[motor]`` when the file is read): the rotating test's flux levels, the test currents and the check's
   i_mR, speeds and loads come from it (on the thesis motor's plate: the thesis values, as always). The check's
   set-points outside the rig's margins are refused before any test runs
   (`bench.workflows.commission.check.check_setpoints`).
1. **identify** - the standstill test of `bench.workflows.commission.identify` (its own run folder, log, plots), then
   wherever the shaft may turn (`shaft_may_turn`; ``rotating`` True or False decides instead) the rotating tests
   (`bench.workflows.commission.rotating`: L_m at the rated flux, J, friction). Without them the result is *provisional*
   (``provisional`` says why; the verdict and the report say so). A trip or a refusal (`identify.refusals`:
   implausible values, wide intervals - with the rotating test also J's and the rated-flux L_m's, as soon as it
   has them -, a warming motor) stops here.
2. **candidate rig file** - a copy of the rig file with the identified ``[motor]`` (the thesis form,
   L_s = L_r, 3.6) in the report folder (`rigfile.motor_text`). Everything after runs on the copy; the
   rig file itself changes only on a "go" (last stage), after a backup. An identified motor the plate
   refuses (`bench.core.nameplate.check`) is a no-go.
3. **flux observer** - the LPV observer of 5.6.2 for the identified motor, scheduled up to the rig's
   over-speed limit (``limits.omega_max``), at the rig's loop rate, verified (`bench.workflows.synth.flux_observer`).
4. **current controller** - the quasi-LPV current controller of 6.2.2 at ``current_rate`` (600 Hz as in
   the thesis), verified (`bench.workflows.synth.current_controller`). Both artifacts carry their certificate
   (γ, the independent lower bound, the gap); a design that fails says which limit it hit, in one line.
5. **closed loop** - the FOC with both designs (`observer=lpv`, `current_controller=lpv`) on the candidate
   rig through `bench.workflows.commission.check.check_scenario`: Fig. 5.7's low-speed experiment with the load stepping
   every 1/3 s, then a ramp to the rated speed, a hold, and a hold with the load, at the rated point's i_mR, its speeds
   and loads scaled to the motor (`bench.core.nameplate.scaled`). The go criteria
   (`bench.workflows.commission.check.check_metrics`) are what a real rig can measure: the speed settled after every
   load step and at rated speed, no trip, and the model against the measurements (`bench.workflows.commission.judge`:
   the voltage-model and current-model fluxes agreeing at speed, in magnitude and angle, and the model's torque step
   against the DC load's), each limit made from the measurements' known errors. With ``judge="truth"`` (the mock) also
   the flux angle and magnitude against the plant's truth. ``skip_identify``: stage 1 is skipped and the rig file's
   ``[motor]`` as it is is the model designed for and checked (nothing is written).
   Every stage's warnings are collected (``warnings``): in the report, and on stderr (`bench commission`).
6. **go / no-go** - ``report.md`` with the tables and PNGs; on "go" the identified ``[motor]`` is
   written into the rig file (`rigfile.write_motor`, backup first) unless ``dry_run``: into the file as the
   command read it at its start (refused if it changed since; `bench.core.rigfile_write.replace_file`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.workflows import synth
from bench.errors import BadInput, DesignFailed
from bench.core.shutdown import signal_cause, signal_exit_code, signalled
from bench.core.rigfile_write import Snapshot, check_writable
from bench.runtime.session import scenario_scaling
from bench.workflows.commission.check import (check_judge, check_metrics, check_scenario, check_setpoints, plot_check,
                                              rated_speed, run_check)  # fmt: skip
from bench.workflows.commission.judge import Bench, model_intervals
from bench.workflows.commission.identify import check_inputs, identify, UNITS
from bench.workflows.commission.rigfile import motor_text, write_motor
from bench.core.config import RigConfig, is_real_rig, load as load_rig, resolve

CURRENT_RATE = 600.0  # [Hz] the quasi-LPV current controller's rate (6.2.2, as the thesis ran it)
#: the current controller's γ bisection for a commissioned model: the full re-balancing from the lower bound
#: (`synthesis.models.current_controller.design_current_controller`). The diagonal one ends where its own
#: iteration ends, and on two fleet motors a 1e-6 change of R_r moved that design's responses by 74 % and 129 %
#: (the full one: 6 % and 1.7 %; not continuous everywhere: 59 % at 1e-4 on a third). On the 20-motor fleet it
#: gives a better flux angle on every saturating motor (docs/results/fleet-commission.md). At 600 Hz the two
#: behave alike on the thesis rig (docs/results/synthesis.md); the shipped artifacts stay diagonal.
CURRENT_RESCALE = "full"
#: its LMI solution centred in its own balanced coordinates (`design_current_controller(centring="balanced")`),
#: minimising tr Y + ||P~|| (`objective="dual"`): a design that follows its model continuously and, but for a
#: fall-back to the max-margin solution, its BLAS kernel's rounding little (SkylakeX against Haswell: within 6.3 % on 19
#: of the fleet's 20 true models, 63 % on m000's, where Clarabel fails the centring). Centred at the scaling the
#: bisection ended in ("scaled", minimising tr X + tr Y; the shipped artifacts), the design follows the path of the
#: bisection's re-balancing, which follows the kernel's rounding: 24-197 % apart on 9 of the 20, and the check's
#: flux angle on one identified model 0.17-0.64 deg by kernel. Balanced with the trace objective, the check tripped
#: on over-current at start on 4 of 5 fleet motors (docs/results/fleet-commission.md)
CURRENT_CENTRING = "balanced"
CURRENT_OBJECTIVE = "dual"


Say = Callable[[str], None]


def shaft_may_turn(cfg: Any) -> bool:
    """The rig file's ``[rig] free_shaft``, else: the mock and emulated rigs yes, a real rig no."""
    return (not is_real_rig(cfg)) if cfg.free_shaft is None else cfg.free_shaft


def _rotating(cfg: Any, rotating: bool | None, voltages: str) -> tuple[bool, str | None]:
    """(run the rotating test?, why the result is provisional or None): ``rotating`` None: wherever the shaft may
    turn and the voltages are measured; False: the standstill test only (``--standstill-only``)."""
    if rotating is None:
        if not shaft_may_turn(cfg):
            return False, ("the rig file does not say the shaft may turn ([rig] free_shaft), so only the standstill "
                           "test ran")  # fmt: skip
        if voltages != "measured":
            return False, ("with reference voltages only the standstill test runs (the rotating one reads the "
                           "measured voltage)")  # fmt: skip
        return True, None
    if rotating and cfg.free_shaft is False:
        raise BadInput("--rotating", f"the rig file says the shaft may not turn ([rig] free_shaft = false in "
                       f"{cfg.path})")  # fmt: skip
    return rotating, None if rotating else "--standstill-only: the standstill test only"


class _Stop(Exception):
    """A stage ended the commissioning: the exit code and the verdict."""

    def __init__(self, code: int, verdict: str) -> None:
        super().__init__(verdict)
        self.code, self.verdict = code, verdict


class _Report:
    """The report as the stages fill it (`stage`), written once the commissioning ends (`finish`)."""

    def __init__(self, rig_path: Path, out: Path, *, dry_run: bool, judge: str, skip_identify: bool,
                 provisional: str | None) -> None:  # fmt: skip
        self.out, self.provisional = out, provisional
        self.rep: dict[str, Any] = {
            "rig": str(rig_path), "out": str(out), "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "stages": {}, "go": False, "dry_run": dry_run, "judge": judge, "skip_identify": skip_identify,
            "provisional": provisional, "warnings": [],
        }  # fmt: skip
        self.t_all = time.perf_counter()

    def stage(self, name: str, t0: float, **kw: Any) -> dict[str, Any]:
        self.rep["stages"][name] = {"wall_time_s": time.perf_counter() - t0, **kw}
        return self.rep["stages"][name]

    def warn(self, prefix: str, warnings: Any) -> None:
        self.rep["warnings"] += [f"{prefix}: {w}" for w in warnings or ()]

    def finish(self, code: int, verdict: str) -> tuple[dict[str, Any], int]:
        rep, out = self.rep, self.out
        if self.provisional and verdict.startswith("GO"):
            verdict = verdict.replace("GO", "GO (provisional: standstill test only)", 1)
        rep["verdict"] = verdict
        rep["wall_time_s"] = time.perf_counter() - self.t_all
        rep["report"] = str(write_report(rep, out))
        (out / "commission.json").write_text(json.dumps(rep, indent=2, default=str))
        rep["json"] = str(out / "commission.json")
        return rep, code


def commission(rig: str, out: Path, *, voltages: str = "measured", ident_params: dict[str, Any] | None = None,
               rotating: bool | None = None, rotating_params: dict[str, Any] | None = None, rated: float | None = None,
               current_rate: float = CURRENT_RATE, seed: int = 0, dry_run: bool = False, realtime: bool | None = None,
               allow_soft_realtime: bool = False, progress: bool = False, say: Say | None = None, judge: str = "rig",
               skip_identify: bool = False) -> tuple[dict[str, Any], int]:  # fmt: skip
    """Run the stages of the module docstring; returns (the report as a dict, the exit code: 0 go, 1 no-go,
    the session's code for a trip or a signal). ``judge``: "rig" (what a real rig measures decides, the truth
    withheld) or "truth" (the mock's truth judged as well; refused on real devices). ``skip_identify``: no
    identification, the rig file's ``[motor]`` as it is is designed for and judged, and nothing is written.
    ``rotating``: None runs the rotating test wherever the shaft may turn (`shaft_may_turn`), False never (a
    provisional result), True always. Bad input raises `BadInput` before OUT is made."""
    say = say or (lambda s: None)
    rig_path = resolve(rig)
    snap = Snapshot.read(rig_path)  # the rig file as this run read it: the candidate's base, and what a GO replaces
    cfg0 = load_rig(str(rig_path))
    rotating, provisional = _check_before_anything(rig_path, snap, cfg0, judge=judge, skip_identify=skip_identify,
                                                   dry_run=dry_run, voltages=voltages, ident_params=ident_params,
                                                   rotating=rotating, rotating_params=rotating_params, rated=rated,
                                                   current_rate=current_rate)  # fmt: skip
    _make_out(out)
    r = _Report(rig_path, out, dry_run=dry_run, judge=judge, skip_identify=skip_identify, provisional=provisional)
    try:
        # 1. identify; 2. the candidate rig file: the identified [motor], everything else as it is
        cand = out / "rig.toml"
        if skip_identify:  # the rig file as it is: its [motor] is the model designed for and judged
            say("identification skipped: the rig file's [motor] as it is")
            r.stage("identify", time.perf_counter(), result="skipped", model=cfg0.motor.as_dict())
            cand.write_text(snap.text, encoding="utf-8")
            ident, thesis, inv_table = None, {}, None
        else:
            say("identification: standstill" + (", then rotating (free shaft)" if rotating else ""))
            t0 = time.perf_counter()
            ident = identify(str(rig_path), voltages=voltages, params=ident_params, seed=seed, out_dir=out / "identify",
                             progress=progress, realtime=realtime, allow_soft_realtime=allow_soft_realtime,
                             rotating=rotating, rotating_params=rotating_params)  # fmt: skip
            thesis, inv_table = _identified(r, t0, ident, rotating, snap, rig_path, cand)
        r.rep["candidate_rig"] = str(cand)
        cfg = load_rig(str(cand))
        # 3. + 4. the designs, each verified, with its certificate
        arts = _designs(r, cfg, cand, current_rate, out, say)
        # 5. the closed-loop check
        _check(r, rig_path, cand, cfg, arts, ident, voltages=voltages, rated=rated, seed=seed, realtime=realtime,
               allow_soft_realtime=allow_soft_realtime, progress=progress, judge=judge, say=say)  # fmt: skip
    except _Stop as stop:
        return r.finish(stop.code, stop.verdict)
    # 6. go
    r.rep["go"] = True
    if skip_identify:
        return r.finish(0, "GO (the rig file's [motor] as it is; nothing written)")
    if not dry_run:
        try:
            r.rep["written"] = write_motor(rig_path, thesis, inverter_error=inv_table, read=snap)
        except BadInput as exc:  # changed since this run read it, held by another writer, not writable
            r.rep["written"] = None
            return r.finish(1, f"GO, but the rig file was not written: {exc}")
    return r.finish(0, "GO" + (" (dry run: the rig file is unchanged)" if dry_run else ""))


def _check_before_anything(rig_path: Path, snap: Snapshot, cfg0: RigConfig, *, judge: str, skip_identify: bool,
                           dry_run: bool, voltages: str, ident_params: dict[str, Any] | None, rotating: bool | None,
                           rotating_params: dict[str, Any] | None, rated: float | None, current_rate: float
                           ) -> tuple[bool, str | None]:  # fmt: skip
    """Every check of the input before anything runs (`BadInput`); returns whether the rotating test runs and why
    the result would be provisional (None: it would not)."""
    check_judge(cfg0, judge)
    if cfg0.nameplate is None:
        raise BadInput("nameplate", f"{rig_path} has no [nameplate]: bench commission takes its tests, the rated flux "
                       "and the check from the motor's plate; add P_rated, U_rated, I_rated, f_rated, n_rated "
                       "(docs/commissioning.md, Nameplate)")  # fmt: skip
    if skip_identify:
        check_skip_identify(snap.text, ident_params, rotating, rotating_params)
        rotating, provisional = False, None  # (no test runs: the model is the rig file's)
    else:
        rotating, provisional = _rotating(cfg0, rotating, voltages)
        if not dry_run:
            check_writable(rig_path, "--rig")  # (--dry-run: only check; --skip-identify writes nothing)
    if current_rate > cfg0.rate_hz or abs(cfg0.rate_hz / current_rate - round(cfg0.rate_hz / current_rate)) > 1e-9:
        raise BadInput("--current-rate", f"must divide the rig's loop rate {cfg0.rate_hz:g} Hz, got {current_rate:g}")
    check_setpoints(cfg0, rated)  # a bad --rated-speed, a check outside the rig's margins: before anything runs
    check_inputs(str(rig_path), voltages, ident_params, rotating, rotating_params)  # -p, -r: before OUT is made
    return rotating, provisional


def _identified(r: _Report, t0: float, ident: dict[str, Any], rotating: bool, snap: Snapshot, rig_path: Path,
                cand: Path) -> tuple[dict[str, Any], Any]:  # fmt: skip
    """The identification's stage in the report and the candidate rig file (the identified ``[motor]`` in the rig
    file as it was read); returns the identified motor and the inverter's error table. `_Stop` where the
    identification tripped or was refused, or its motor does not fit the rig file (``t0``: when it started)."""
    if "tripped" in ident:
        r.stage("identify", t0, result="tripped", trip_cause=ident["tripped"], run=ident["run"].get("summary"))
        r.rep["run"] = ident["run"]
        raise _Stop(ident["exit_code"], f"NO-GO: the identification stopped: {ident['tripped']}")
    thesis = ident["motor"]  # standstill, or with --rotating L_m at the rated flux, J and the friction
    refused = list(ident.get("refused") or [])  # implausible values, wide intervals, a warming motor
    r.warn("identify", ident.get("warnings"))
    r.stage("identify", t0, result="refused" if refused else "ok", json=ident.get("json"), plots=ident.get("plots"),
            motor=thesis, warnings=ident.get("warnings"), refused=refused,
            rig_time_s=ident["conditions"]["duration_s"] + (ident["rotating"]["rig_time_s"] if rotating else 0.0))  # fmt: skip
    if refused:
        raise _Stop(1, f"NO-GO: the identification is refused: {refused[0]}")
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    inv_table = ident.get("inverter_error")  # the inverter's error per phase, from the DC levels
    try:  # (parsed back: the identified [motor] against the plate, bench.core.nameplate.check)
        cand.write_text(motor_text(snap.text, thesis, stamp, str(rig_path), inv_table), encoding="utf-8")
    except BadInput as exc:
        raise _Stop(1, f"NO-GO: the identified motor does not fit the rig file: {exc}") from None
    return thesis, inv_table


def _designs(r: _Report, cfg: RigConfig, cand: Path, current_rate: float, out: Path, say: Say) -> Path:
    """The flux observer (5.6.2) and the current controller (6.2.2) for the candidate, each verified, with its
    certificate; returns their folder. `_Stop` if one fails."""
    arts = out / "artifacts"
    arts.mkdir()

    def observer(p: Say) -> dict[str, Any]:
        return synth.flux_observer(cfg.limits.omega_max, cfg.rate_hz, arts / "flux_observer", rig=str(cand),
                                   progress=p)  # fmt: skip

    def current(p: Say) -> dict[str, Any]:
        return synth.current_controller(current_rate, arts / "current_controller", rig=str(cand), progress=p,
                                        rescale=CURRENT_RESCALE, centring=CURRENT_CENTRING,
                                        objective=CURRENT_OBJECTIVE)  # fmt: skip

    for name, make in (("flux observer", observer), ("current controller", current)):
        say(f"{name}: synthesis and verification")
        t0 = time.perf_counter()
        try:
            info = make(lambda s, n=name: say(f"{n}: {s}"))
        except DesignFailed as exc:
            r.stage(name, t0, result="failed", error=str(exc))
            raise _Stop(1, f"NO-GO: design failed: {exc}") from None
        r.stage(name, t0, result="verified", artifact=str(Path(info["npz"]).with_suffix("")), **_certificate(info))
        r.warn(name, info.get("warnings"))
    return arts


def _check(r: _Report, rig_path: Path, cand: Path, cfg: RigConfig, arts: Path, ident: dict[str, Any] | None, *,
           voltages: str, rated: float | None, seed: int, realtime: bool | None, allow_soft_realtime: bool,
           progress: bool, judge: str, say: Say) -> None:  # fmt: skip
    """The closed-loop check (Fig. 5.7's experiment at the rated speed) with the candidate's designs, judged
    (`check_metrics`); `_Stop` on a NO-GO or a signal."""
    w_rated = rated_speed(cfg, rated)
    scaling = scenario_scaling(cfg)
    say(f"closed-loop check (Fig. 5.7's experiment, ramp to {w_rated:.0f} rad/s)")
    t0 = time.perf_counter()
    # the observer's voltage: the one the identification used (the LPV observer leans on it at low speed, 5.6.3)
    params = {"observer": "lpv", "lpv_artifact": str(arts / "flux_observer"), "voltage_source": voltages,
              "current_controller": "lpv", "lpv_current_artifact": str(arts / "current_controller")}  # fmt: skip
    scn = check_scenario(w_rated, scaling)
    summary, code, cols = run_check(str(cand), params, scn, r.out / "closed-loop", seed, realtime,
                                       allow_soft_realtime, progress)  # fmt: skip
    r.warn("closed-loop check", summary.get("warnings"))
    m = check_metrics(cols, w_rated, summary.get("trip_time") if summary.get("trip_cause") else None, judge=judge,
                      model=cfg.motor, bench=Bench.of(cfg), rel_ci=model_intervals(ident),
                      voltages=voltages == "measured", scaling=scaling)  # fmt: skip
    m["i_mR_ref"] = scn.i_mR_ref
    m["plot"] = str(plot_check(cols, m, r.out / "closed_loop.png"))
    st = r.stage("closed loop", t0, result="go" if m["go"] else "no-go", log=summary.get("log"), params=params,
                 trip_cause=summary.get("trip_cause"), exit_code=code, **m)  # fmt: skip
    r.rep["run_command"] = ("bench run --rig " + str(rig_path) + " --controller foc " +
                            " ".join(f"-p {k}={v}" for k, v in params.items()))  # fmt: skip
    if code < 128 and signalled() is not None:  # a signal during the session's shutdown: the command ends
        code = signal_exit_code(signalled())
        summary = {**summary, "trip_cause": f"{signal_cause(code - 128)} during the check's shutdown"}
    if code >= 128:  # a signal: the session's own shutdown ran; the rig file stays as it was
        r.rep["run"] = summary
        raise _Stop(code, f"NO-GO: interrupted: {summary.get('trip_cause')}")
    if not m["go"]:
        failed = [f"{k} ({_said(c)})" for k, c in st["criteria"].items() if not c["pass"]]
        raise _Stop(1, f"NO-GO: the closed-loop check failed: {', '.join(failed)}")


def _make_out(out: Path) -> None:
    """The report folder, new or empty, made (BadInput naming --out if it cannot be)."""
    try:
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise BadInput("--out", f"{out} exists and is not an empty folder; give a new folder")
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput("--out", f"cannot make the folder {out}: {exc.strerror or exc}") from None


def check_skip_identify(text: str, ident_params: dict[str, Any] | None, rotating: bool,
                        rotating_params: dict[str, Any] | None) -> None:  # fmt: skip
    """``--skip-identify`` takes the rig file's ``[motor]`` as it is: refused with the identification's own options
    and on a rig file without a ``[motor]`` table (nothing to check)."""
    import tomllib

    given = [o for o, v in (("--rotating", rotating), ("-p", ident_params), ("-r", rotating_params)) if v]
    if given:
        raise BadInput("--skip-identify", f"runs no identification, so {' and '.join(given)} cannot apply; drop "
                       f"{'it' if len(given) == 1 else 'them'} or identify")  # fmt: skip
    if not isinstance(tomllib.loads(text).get("motor"), dict):
        raise BadInput("--skip-identify", "the rig file has no [motor] table to check; write the motor's model "
                       "into [motor] or identify it (leave out --skip-identify)")  # fmt: skip


def _said(c: dict[str, Any]) -> str:
    """A criterion's value against its limit, short (the verdict line)."""
    if isinstance(c["value"], str):
        return c["value"]
    unit = c.get("unit", "")
    return f"{c['value']:.3g} {unit} against {c['limit']:.3g} {unit}" + (f", {c['why']}" if c.get("why") else "")


def _certificate(info: dict[str, Any]) -> dict[str, Any]:
    keys = ("gamma", "gamma_a", "gamma_lower_bound", "gap", "backoff", "verified", "wall_time")
    return {k: info[k] for k in keys if k in info}


def _limit_lines(det: dict[str, Any] | None) -> list[str]:
    """The report's account of the limits of the criteria without a truth: each window's error budget
    (`bench.workflows.commission.judge`: every known error at its bound, the changes summed, plus the scatter)."""
    if not det:
        return []
    lines = ["### How the limits are made", "", "Each limit is the sum of what every known error, at its bound, "
             "changes in the value, plus the value's own 95 % scatter (docs/commissioning.md). Accuracy assumed: "
             + ", ".join(f"{k} {v:g}" for k, v in det["accuracy"].items()) + "; the model's 95 % intervals: "
             + (", ".join(f"{k} ±{100.0 * v:.2g} %" for k, v in det["model_intervals_rel"].items())
                if any(det["model_intervals_rel"].values()) else "none (a [motor] as it is)") + ".", "",
             "| criterion | window | value | limit | largest parts of the limit |", "|---|---|---|---|---|"]  # fmt: skip

    def parts(b: dict[str, float], unit: str) -> str:
        top = sorted(b.items(), key=lambda kv: -kv[1])[:3]
        return "; ".join(f"{k}: {v:.2g} {unit}" for k, v in top)

    for f in det.get("flux") or []:
        if "budget" not in f:
            lines.append(f"| flux | {f['window']} | - | - | {f.get('why', '')} |")
            continue
        lines.append(f"| flux magnitude | {f['window']} | {f['magnitude_pct']:+.3g} % | {f['magnitude_limit_pct']:.3g} % "
                     f"| {parts(f['budget']['magnitude'], '%')} |")  # fmt: skip
        if f["load_N_m"] != 0.0:
            lines.append(f"| flux angle | {f['window']} | {f['angle_deg']:+.3g}° | {f['angle_limit_deg']:.3g}° "
                         f"| {parts(f['budget']['angle'], 'deg')} |")  # fmt: skip
    for q in det.get("torque") or []:
        if "budget" not in q:
            lines.append(f"| torque step | {q['windows']} | - | - | {q.get('why', '')} |")
            continue
        lines.append(f"| torque step | {q['windows']} ({q['model_step_N_m']:.3g} N m for {q['load_step_N_m']:.3g}) "
                     f"| {q['deviation_pct']:+.3g} % | {q['limit_pct']:.3g} % | {parts(q['budget'], '%')} |")  # fmt: skip
    return lines + [""]


def write_report(rep: dict[str, Any], out: Path) -> Path:
    """``report.md``: the verdict, the identified motor, the designs with their certificates, the check."""
    st = rep["stages"]
    lines = [f"# Commissioning report: {rep['verdict']}", "", f"Rig file: `{rep['rig']}`; started {rep['started']}; "
             f"{rep.get('wall_time_s', 0.0):.0f} s in all.", ""]  # fmt: skip
    if rep.get("provisional"):
        lines += [f"**Provisional**: {rep['provisional']}. L_m is the standstill test's incremental inductance at its "
                  "bias, not the rated-flux value a rotating test measures, and J and the friction are the rig file's; "
                  "on a saturating motor the designs and the check rest on the wrong L_m.", ""]  # fmt: skip
    if rep.get("warnings"):
        lines += ["## Warnings", ""] + [f"* {w}" for w in rep["warnings"]] + [""]
    idn = st.get("identify", {})
    if idn.get("result") == "skipped":
        lines += ["## Model checked: the rig file's [motor] as it is (not identified, nothing written)", "",
                  "| | value | unit |", "|---|---|---|"]  # fmt: skip
        lines += [f"| {n} | {v:.5g} | {UNITS.get(n, '')} |" for n, v in idn["model"].items()] + [""]
    if "motor" in idn:
        lines += ["## Identified motor (thesis 3.6, L_s = L_r)", "", "| | value | 95 % interval | unit |",
                  "|---|---|---|---|"]  # fmt: skip
        for n, v in idn["motor"].items():
            lo, hi = v["ci95"]
            lines.append(f"| {n} | {v['value']:.5g} | [{lo:.5g}, {hi:.5g}] | {UNITS.get(n, '')} |")
        lines += ["", f"Rig time {idn.get('rig_time_s', math.nan):.1f} s. Fit plots: "
                  + ", ".join(f"![]({Path(p).relative_to(out) if Path(p).is_relative_to(out) else p})"
                              for p in idn.get("plots") or []), ""]  # fmt: skip
    for name in ("flux observer", "current controller"):
        if name in st:
            s = st[name]
            if s["result"] == "failed":
                lines += [f"## {name}: design failed", "", s["error"], ""]
                continue
            lines += [f"## {name}: verified", "", f"γ = {s.get('gamma', math.nan):.4g}, independent lower bound "
                      f"{s.get('gamma_lower_bound', math.nan):.4g}, gap {s.get('gap', math.nan):.3f}; artifact "
                      f"`{s['artifact']}`; {s['wall_time_s']:.1f} s.", ""]  # fmt: skip
    if "closed loop" in st:
        s = st["closed loop"]
        judged_by = ("what a real rig measures (`--judge rig`: the mock's truth withheld)" if s.get("judge") == "rig"
                     else "what a real rig measures and the mock's truth (`--judge truth`)")  # fmt: skip
        lines += ["## Closed-loop check", "", f"Judged by {judged_by}.", "",
                  "| criterion | value | limit | where | |", "|---|---|---|---|---|"]  # fmt: skip
        for k, c in s["criteria"].items():
            v = c["value"] if isinstance(c["value"], str) else f"{c['value']:.3g} {c.get('unit', '')}"
            lim = c["limit"] if isinstance(c["limit"], str) else f"{c['limit']:.3g} {c.get('unit', '')}"
            where = c.get("window", "") + (f" ({c['why']})" if c.get("why") else "")
            lines.append(f"| {k} | {v} | {lim} | {where} | {'pass' if c['pass'] else '**FAIL**'} |")
        tr = s.get("truth")
        if tr and not tr.get("judged"):
            lines += ["", f"The mock's truth, not judged: flux angle p95 {tr['flux_angle_p95_deg']:.3g}°, flux "
                      f"magnitude p95 {100.0 * tr['flux_mag_p95_rel']:.3g} %."]  # fmt: skip
        lines += ["", "![](closed_loop.png)", ""] + _limit_lines(s.get("rig"))
    if rep.get("run_command"):
        lines += ["To run the commissioned controllers:", "", "```", rep["run_command"], "```", ""]
    if rep.get("written"):
        lines += [f"`[motor]` written into `{rep['written']['rig_file']}`; the old file is `{rep['written']['backup']}`.", ""]
    elif "closed loop" in st:
        lines += ["The rig file was not changed.", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path

