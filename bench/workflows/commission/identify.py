"""`bench identify`: the standstill test as a session, then the fits, the report and the plots.

Follows `bench.workflows.tuning`: `identify` runs the `standstill_id` plugin (`bench.workflows.commission.standstill`)
through `bench.runtime.session.run` - the ordinary supervisor, log and shutdown path, on any rig - then
`analyse` reads the log:

1. **DC test** - per level the mean α current and voltage over the level's window; R_s from
   `fits.dc_line` (slope, an intercept per polarity). The inverter's voltage error per level: the
   reference minus the measured voltage where voltages are measured (direct), and the reference
   minus R_s i (what remains without a voltage measurement). With reference voltages the fit has
   the knee's tail as well and leaves out the levels inside the knee (`TAIL_REL`), unless
   ``dc_fit_from`` picks the levels. The levels give the per-phase table ``inverter_error``
   (`bench.core.inverter_error.from_levels`) that ``--write`` puts into the rig file.
2. **multisine** - lock-in phasors (`fits.lockin`) of the α current and voltage over whole common
   periods, Z = U/I per line. With reference voltages the voltage is the reference shifted by the
   inverter delay plus the DC test's error curve at the sampled current (the drive's own
   compensation, made from the identification); with measured voltages the filter is in the model.
3. **fit** - R_s fixed at the DC value, L'_s, R'_r, L'_m by `fits.impedance` on the sampled-data
   model (`bench.workflows.commission.circuit`); a fit with R_s free as a cross-check. The result in both
   forms: inverse-Γ (unique) and the thesis' T parameters under L_s = L_r (3.6, (3.57)), with 95 %
   intervals: R_s's from the DC fit, the others' `fits.ImpedanceFit.half_width` - the residual's, or
   the lines' noise (period to period) plus their model error (the non-excited harmonics, the lack of
   fit, the multisine's swing on a flux-dependent L'_m: `fits.line_errors`, `fits.swing_bias`) if
   larger, with R_s's error passed on; the T parameters' by their gradient.
4. **refusals** - `refusals`: non-positive values, a leakage ratio outside `LEAKAGE_BAND`, a fit
   residual above `MAX_RESIDUAL`, an interval wider than `rigfile.MAX_REL_CI`, and the warming
   check (the statistic of `bench.workflows.commission.signals` at both ends) moved by more than
   `MAX_WARMING`: ``refused`` lists them, and nothing is written. After ``--rotating`` the [motor] values
   (J, the rated-flux L_m, L_s = L_r from it, R_s, R_r) are held to the interval rule of ``--write``
   (`rigfile.wide_intervals`) as soon as the rotating test has them: a refusal there, not at the write.
5. **saturation** - `saturation_check`: the same fit on the multisine at the second bias ``sat_bias``
   (`bench.workflows.commission.signals`); L_m, its interval and the flux per bias (``saturation`` in the JSON).
   Each L_m is the incremental one at its bias, and its interval is meant to hold that (the swing's
   bias included); on a bias-dependent machine the intervals of L_m, L'_m and L_s are not held to
   `rigfile.MAX_REL_CI` (`refusals`: they are not written from a standstill test).
   Where L_m differs between the biases by more than the intervals and `SAT_TOL`, one warning line
   says so, and ``--write`` writes nothing (`saturated_write_refusal`, exit 2) unless ``--rotating``
   gave the rated-flux L_m.

`from_log` is `bench identify --from-log`: the same analysis of a recorded run, offline.
Writes ``identify.json``, ``ident_dc.png`` and ``ident_impedance.png`` next to the run's log.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.core import load_profiles as lp
from bench.core import nameplate
from bench.workflows.commission import fits
from bench.workflows.commission.circuit import InverseGamma, thesis_params
from bench.workflows.commission.id_plots import plot_dc, plot_impedance
from bench.workflows.commission.signals import Plan
from bench.errors import BadInput, clip
from bench.core.scenarios import Scenario
from bench.core.shutdown import raise_if_signalled
from bench.workflows.commission.standstill import StandstillIdController
from bench.controllers.schema import validate
from bench.workflows.commission.rotating import RotatingIdController, identify_rotating, motor_from, check_params
from bench.core.outputs import check_output
from bench.params import MotorParams
from bench.core.inverter_error import from_levels
from bench.runtime.session import RunOptions, run
from bench.core.rigfile_write import Snapshot, check_writable
from bench.core.config import resolve, load as load_rig
from bench.workflows.commission.rigfile import wide_intervals, write_motor, wide_interval
from bench.daq import LogReader
from bench.daq.reader import internals_topic

VOLTAGES = ("measured", "reference")
# parameters bench identify sets by default with reference voltages (a parameter given wins): the
# multisine on a 3 A bias keeps phases b and c at 1-2 A, >= 5 knee widths above zero current, where
# the inverter's error curve is nearly flat and its tail model (`fits.dc_line`) holds; 6 DC levels per
# polarity leave 4-5 above the knee, so the slope, two intercepts and the tail keep 4+ degrees of freedom
REFERENCE_DEFAULTS = {"ac_bias": 3.0, "dc_levels": 6, "sat_bias": 1.5}
# on a rig with another motor's plate the defaults (the thesis motor's) are scaled to it (`bench.core.nameplate.scaled`,
# `plate_defaults`): the DC test current and the slew with the rated current, the multisine's biases and swing with
# the rated magnetising current, the settling times with the rotor time constant of [motor]
CURRENT_PARAMS = ("dc_current", "slew")
BIAS_PARAMS = ("ac_bias", "ac_amplitude", "sat_bias")
SETTLE_PARAMS = ("dc_settle", "ac_settle", "sat_settle", "check_settle")
TAIL_REL = 0.05  # reference voltages, automatic levels: a level whose knee tail exceeds 5 % of the plateau is left out
# reference voltages: the knee tail's second term (`fits.dc_line`) is fitted where the levels leave at least this many
# degrees of freedom with it (over 100 fleet motors R_s's interval then held the truth in 92-96 % of the runs, 36-48 %
# with the first term alone: docs/results/identify-intervals.md)
SECOND_TAIL_DOF = 3

# refusals after the fit (the result is printed, nothing is written; exit 1): see docs/commissioning.md
MAX_WARMING = 0.01  # |R_s(end) - R_s(start)| / R_s: the windings warmed during the test
LEAKAGE_BAND = (0.01, 0.5)  # L'_s / L'_m (σ = L'_s / (L'_s + L'_m) from 1 % to 33 %)
MAX_RESIDUAL = 0.03  # rms relative complex error of the impedance fit
SAT_TOL = 0.05  # the saturation check: L_m differing by more than this between biases (and their intervals) is flagged
# made of the incremental L'_m: on a bias-dependent machine not written from a standstill test (`refusals`)
SATURATED = (("inverse-Gamma", "L_M"), ("L_s = L_r", "L_m"), ("L_s = L_r", "L_s"))


#: the unit of every identified quantity (thesis form, inverse-Gamma, the rotating test's mechanics)
UNITS = {"R_s": "Ohm", "R_r": "Ohm", "R_R": "Ohm", "L_s": "H", "L_r": "H", "L_m": "H", "L_M": "H", "L_sigma": "H",
         "J": "kg m^2", "B_visc": "N m s/rad", "m_coulomb": "N m"}  # fmt: skip


def summary_table(res: dict[str, Any]) -> str:
    """What `bench identify` prints on a terminal: the identified [motor] (what ``--write`` writes), each value
    with its 95 % interval, the interval's half width relative to the value and the unit; then the
    warnings, the refusals, where the JSON and the plots are, and what was written."""
    motor = res.get("motor") or res.get("thesis_L_s_eq_L_r") or {}
    rows = [("", "value", "95 % interval", "+-", "unit")]
    for n, v in motor.items():
        x, (lo, hi) = v["value"], v["ci95"]
        rel = (hi - lo) / 2.0 / abs(x) if x else math.nan
        rows.append((n, f"{x:.5g}", f"[{lo:.5g}, {hi:.5g}]", f"{rel:.1%}", UNITS.get(n, "")))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    form = "thesis form, L_s = L_r" + (", L_m at the rated flux (rotating test)" if "rotating" in res else "")
    lines = [f"identified motor ({form}; voltages {res.get('voltages', '?')}):"]
    lines += [("  " + "  ".join(c.ljust(w) if i in (0, 4) else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))).rstrip()
              for r in rows]  # fmt: skip
    lines += [f"warning: {w}" for w in res.get("warnings") or ()]
    lines += [f"REFUSED: {r}" for r in res.get("refused") or ()]
    if res.get("json"):
        lines.append(f"all numbers (JSON): {res['json']}")
    if res.get("plots"):
        lines.append("plots: " + ", ".join(str(q) for q in res["plots"]))
    if res.get("written"):
        lines.append(f"[motor] written into {res['written'].get('rig_file')} (old file: {res['written'].get('backup')})")
    elif "written" in res:
        lines.append("nothing written")
    return "\n".join(lines)


def scenario(plan: Plan) -> Scenario:
    """The session's scenario: the shaft is to stay at rest, the DC load commands no torque."""
    return Scenario("standstill", "standstill identification (bench identify): speed 0, no load",
                    plan.duration, lambda t: 0.0, lp.constant(0.0), 0.0)  # fmt: skip


def identify(rig: str = "mock", *, voltages: str = "measured", params: dict[str, Any] | None = None, seed: int = 0,
             out_dir: Path = Path("runs"), progress: bool = False, realtime: bool | None = None,
             allow_soft_realtime: bool = False, write: bool = False, log_buffer: float = 10.0, rotating: bool = False,
             rotating_params: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """Run the standstill test on ``rig`` and return the identification (module docstring); ``write``: put
    the result into the rig file's [motor] (`bench.workflows.commission.rigfile`, after a backup) unless it is refused
    (``refused``); ``log_buffer``: seconds of ticks the log ring holds (`bench.runtime.session.RunOptions`).
    ``rotating`` (a free shaft): then the rotating test (`bench.workflows.commission.rotating.identify_rotating`, its
    own session) on the standstill model, under ``rotating``; ``motor`` is what ``write`` writes: the standstill's
    thesis form, or with the rotating test L_m at the rated flux, L_s = L_r from it, J and the friction
    (`rotating.motor_from`). A signal ends the command with 128 + the signal and the rig file as it was, unless
    it comes after the commit point of the write (`bench.core.rigfile_write`)."""
    params, plan = check_inputs(rig, voltages, params, rotating, rotating_params)
    if write:
        rig_path = resolve(rig)
        check_writable(rig_path, "--write")
        snap = Snapshot.read(rig_path)  # what --write may replace: refused later if the file changes meanwhile
    summary, code = run(RunOptions(rig=rig, controller="standstill_id", scenario=scenario(plan), seed=seed,
                                   params=params, out_dir=out_dir, progress=progress, realtime=realtime,
                                   allow_soft_realtime=allow_soft_realtime, label="bench identify",
                                   log_buffer=log_buffer))  # fmt: skip
    if code != 0:
        return {"tripped": summary["trip_cause"], "run": summary, "exit_code": code}
    raise_if_signalled()  # a signal during the session's shutdown: the run stands, the command ends here
    log = Path(summary["log"])
    out = analyse_log(log)
    folder = log.parent
    out.update({"seed": seed, "run_plot": summary["plot"]})
    out["plots"] = [str(plot_dc(out, folder / "ident_dc.png")),
                    str(plot_impedance(out, folder / "ident_impedance.png"))]
    out["motor"] = out["thesis_L_s_eq_L_r"]
    if rotating:  # L_m is the rotating test's: the standstill L'_m's width does not refuse (`refusals`)
        out["refused"] = refusals(out["inverse_gamma"], out["thesis_L_s_eq_L_r"], out["ac"]["residual_rms_rel"],
                                  out["warming"], out["saturation"], rotating=True)  # fmt: skip
    if rotating and not out["refused"]:
        (folder / "identify.json").write_text(json.dumps(out, indent=2))  # the standstill's, whatever follows
        rot = identify_rotating(rig, out, params=rotating_params, seed=seed, out_dir=out_dir, progress=progress,
                                realtime=realtime, allow_soft_realtime=allow_soft_realtime)  # fmt: skip
        if "tripped" in rot:
            return {**rot, "standstill": out}
        raise_if_signalled()
        out["rotating"] = rot
        out["motor"] = motor_from(out, rot)
        # what --write would refuse (J, L_m at the rated flux, ...), refused here: before anything builds on it
        out["refused"] = wide_intervals(out["motor"])
        out["warnings"].extend(f"rotating test: {w}" for w in rot.get("warnings") or ())
        out["plots"] += rot.get("plots") or []
        sat = out.get("saturation")
        if sat and sat["bias_dependent"]:  # the rated-flux L_m came from the rotating test: say that instead
            out["warnings"] = [saturation_message(sat, rotating=True) if w == sat["message"] else w
                               for w in out["warnings"]]  # fmt: skip
            sat["message"] = saturation_message(sat, rotating=True)
    if write and out["refused"]:
        out["written"] = None
    elif write:
        why = saturated_write_refusal(out)
        if why:  # exit 2, nothing written; the identification stays in the run folder
            out["written"] = None
            (folder / "identify.json").write_text(json.dumps(out, indent=2))
            raise BadInput("--write", f"{why} (the result: {folder / 'identify.json'})")

        try:
            out["written"] = write_motor(rig_path, out["motor"], inverter_error=out.get("inverter_error"), read=snap)
        except BadInput as exc:  # the fit stands; only the write is refused
            out["written"] = None
            out["warnings"].append(str(exc))
    (folder / "identify.json").write_text(json.dumps(out, indent=2))
    out["json"] = str(folder / "identify.json")
    return out


def saturated_write_refusal(res: dict[str, Any]) -> str | None:
    """Why ``--write`` must not write this identification (one line), or None: its L_m came from the standstill
    test alone while the saturation check found it bias-dependent. Nothing is written then, not even the other
    parameters: L_s = L_r = L'_s + L'_m and R_r = R'_r (L_s/L_m)² are made from the same incremental L'_m, so a
    [motor] with those new and L_m old would be no machine at all. With ``--rotating`` L_m is the rotating
    test's, at the rated flux, and it is written."""
    sat = res.get("saturation")
    if not sat or not sat["bias_dependent"] or "rotating" in res:
        return None
    pts = ", ".join(f"{x['L_m']['value']:.3g} H at {x['bias_A']:g} A" for x in sat["points"])
    return (f"not written: the incremental L_m depends on the flux ({pts}); a standstill test cannot give the "
            "rated-flux L_m: identify with --rotating (a free shaft)")


def saturation_message(sat: dict[str, Any], rotating: bool = False) -> str:
    """The one line the saturation check says when L_m depends on the bias (the test's own bias first)."""
    pts = sorted(sat["points"], key=lambda x: x["bias_A"] != sat["test_bias_A"])
    said = ", ".join(f"{x['L_m']['value']:.3g} H at {x['bias_A']:g} A" for x in pts)
    tail = ("the L_m identified is the rotating test's, at the rated flux" if rotating else
            "a standstill test cannot give the rated-flux L_m \u2014 identify with --rotating")
    return f"saturation: incremental L_m {said}: L_m depends on the flux; {tail}"


def check_inputs(rig: str, voltages: str, params: dict[str, Any] | None, rotating: bool,
                 rotating_params: dict[str, Any] | None) -> tuple[dict[str, Any], Plan]:  # fmt: skip
    """Everything `identify` can refuse before any test runs (BadInput naming the field; `bench identify` and
    `bench commission` call it before they make a folder): the voltages, the rig file, the standstill test's
    ``-p`` parameters (only standstill_id's: names, types, ranges, no subnormal), and with ``rotating`` the rotating
    test's ``-r`` parameters (`rotating.check_params`). Returns the parameters as the session takes them (the
    reference voltages' defaults added) and the standstill test's plan."""
    if voltages not in VOLTAGES:
        raise BadInput("--voltages", f"must be one of {', '.join(VOLTAGES)}, got {voltages!r}")
    check_rotating(rotating, voltages, rotating_params)
    cfg = load_rig(rig)
    params = dict(params or {})
    _which_test(params, rotating_params or {})
    if params.get("voltages", voltages) != voltages:
        raise BadInput("--param voltages", f"is {params['voltages']!r} while --voltages is {voltages!r}; "
                       "give --voltages only")  # fmt: skip
    params["voltages"] = voltages
    params = {**plate_defaults(cfg.motor, cfg.nameplate, voltages), **params}
    p = validate(f"controller.{StandstillIdController.name}", StandstillIdController.schema, params)
    if rotating:
        check_params(dict(rotating_params or {}), cfg)
    return params, Plan.from_params(p)


def plate_defaults(motor: MotorParams, plate: nameplate.Nameplate | None, voltages: str) -> dict[str, Any]:
    """The standstill test's defaults that differ from `StandstillIdController`'s for a rig with ``motor`` and
    ``plate``: `REFERENCE_DEFAULTS` with reference voltages, and on another motor than the thesis one those scaled
    to it (`CURRENT_PARAMS`, `BIAS_PARAMS`, `SETTLE_PARAMS`; `bench.core.nameplate.scaled`), to 3 digits."""
    defaults: dict[str, Any] = dict(REFERENCE_DEFAULTS) if voltages == "reference" else {}
    k = nameplate.scaled(motor, plate)
    if k is None:
        return defaults
    base = {**StandstillIdController.defaults, **defaults}
    for names, factor in ((CURRENT_PARAMS, k.current), (BIAS_PARAMS, k.magnetising), (SETTLE_PARAMS, k.settle)):
        defaults.update({n: float(f"{base[n] * factor:.3g}") for n in names})
    return defaults


def _which_test(params: dict[str, Any], rotating_params: dict[str, Any]) -> None:
    """A ``-p`` that is only the rotating test's parameter, or a ``-r`` only the standstill test's: BadInput saying
    which option takes it."""

    ss, rot = StandstillIdController.schema, RotatingIdController.schema
    for name in params:
        if name not in ss and name in rot:
            raise BadInput(f"--param {name}", f"is a parameter of the rotating test (rotating_id), not of the "
                           f"standstill test: use -r {name}={clip(params[name])}")  # fmt: skip
    for name in rotating_params:
        if name not in rot and name in ss:
            raise BadInput(f"--rotating-param {name}", f"is a parameter of the standstill test (standstill_id), not "
                           f"of the rotating test: use -p {name}={clip(rotating_params[name])}")  # fmt: skip


def check_rotating(rotating: bool, voltages: str, rotating_params: dict[str, Any] | None = None) -> None:
    """The rotating test reads the fundamental of the measured voltage: refused with reference voltages; its
    parameters (``-r``) only with it."""
    if rotating_params and not rotating:
        raise BadInput("--rotating-param", f"-r needs --rotating (got {', '.join(map(str, rotating_params))[:100]})")
    if rotating and voltages != "measured":
        raise BadInput("--rotating", "needs measured voltages (the no-load test reads the fundamental of the measured "
                       "voltage); give --voltages measured")  # fmt: skip


def from_log(log: Path, out_dir: Path, *, voltages: str | None = None, dc_fit_from: float | None = None) -> dict[str, Any]:
    """`bench identify --from-log`: re-estimate from a recorded standstill run (offline: real-rig data,
    replays) - `analyse_log`, then ``identify.json`` and the plots in a new folder under ``out_dir``."""
    import time


    log = Path(log)
    if not log.is_file():
        raise BadInput("--from-log", f"no such file: {log}")
    try:
        out = analyse_log(log, voltages, dc_fit_from)
    except BadInput:
        raise
    except Exception as exc:  # not an MCAP log, a log of another layout, ...
        raise BadInput("--from-log", f"{log} is not a readable standstill identification log "
                       f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None  # fmt: skip
    stem = Path(out_dir) / f"{time.strftime('%Y%m%d-%H%M%S')}-identify-from-log"
    folder = next(f for n in range(1, 1000) if not (f := stem.with_name(stem.name + (f"-{n}" if n > 1 else ""))).exists())
    check_output("--out", folder / "identify.json", False)  # makes the folder
    out["plots"] = [str(plot_dc(out, folder / "ident_dc.png")), str(plot_impedance(out, folder / "ident_impedance.png"))]
    (folder / "identify.json").write_text(json.dumps(out, indent=2))
    out["json"] = str(folder / "identify.json")
    return out


def analyse_log(log: Path, voltages: str | None = None, dc_fit_from: float | None = None) -> dict[str, Any]:
    """`analyse` a recorded standstill run (its MCAP log); ``voltages`` and ``dc_fit_from`` override the
    run's: both the measured and the reference voltages are in every log, so one run can be fitted both ways."""
    r = LogReader(log)
    meta = r.metadata()
    run_meta, rig_meta = meta["run"], meta["rig"]
    if run_meta.get("controller") != "standstill_id":
        raise BadInput("log", f"{log} is a run of {run_meta.get('controller')!r}, not of standstill_id")

    params = dict(run_meta["controller_params"])
    params.setdefault("sat_bias", 0.0)  # recorded before the saturation check: none
    params.setdefault("sat_settle", 1.0)
    params.setdefault("ac_grid", "all")  # recorded before the odd multisine: every harmonic
    missing = sorted(set(StandstillIdController.defaults) - set(params))
    if missing:
        raise BadInput("log", f"{log} was recorded by an older standstill test (without {', '.join(missing)}); "
                       "run the test again")  # fmt: skip
    if voltages is not None:
        if voltages not in VOLTAGES:
            raise BadInput("--voltages", f"must be one of {', '.join(VOLTAGES)}, got {voltages!r}")
        params["voltages"] = voltages
    if dc_fit_from is not None:
        params["dc_fit_from"] = float(dc_fit_from)
    meas, ctrl = r.read_ticks("/rig", internals_topic(r.topics()) or "/ident")
    T_s = 1.0 / float(run_meta["rate_hz"])
    end = Plan.from_params(params).segments[-1].t1
    tripped = meas["tripped"].astype(bool)
    if meas["t"].size == 0 or meas["t"][-1] < end - T_s or tripped[meas["t"] < end].any():
        when = f"tripped at t = {meas['t'][tripped][0]:.3f} s" if tripped.any() else \
            f"ends at t = {meas['t'][-1] if meas['t'].size else 0.0:.3f} s"
        raise BadInput("log", f"{log} {when}, before the test's end at {end:.3f} s: nothing to fit")
    out = analyse(meas, ctrl, params, T_s, MotorParams(**rig_meta["motor"]))
    out.update({"rig": rig_meta["rig"]["name"], "log": str(log)})
    return out


def _val(v: float, ci: float) -> dict[str, Any]:
    return {"value": v, "ci95": [v - ci, v + ci]}


@dataclass(frozen=True)
class _Record:
    """A standstill run's columns on the stator α axis (3.17): tick numbers (exact windows), the current, the
    measured voltage and the reference voltage."""

    k: np.ndarray
    T_s: float
    i_a: np.ndarray
    u_m: np.ndarray
    u_r: np.ndarray

    @classmethod
    def of(cls, meas: dict[str, np.ndarray], T_s: float) -> "_Record":
        alpha = {x: (2.0 * meas[f"{x}_a"] - meas[f"{x}_b"] - meas[f"{x}_c"]) / 3.0 for x in ("i", "u")}
        return cls(np.rint(meas["t"] / T_s).astype(np.int64), T_s, alpha["i"], alpha["u"], meas["u_s_ref_re"])

    def window(self, a: float, b: float) -> np.ndarray:
        return (self.k >= int(round(a / self.T_s))) & (self.k < int(round(b / self.T_s)))


@dataclass(frozen=True)
class _DcStage:
    """The DC staircase's result: the levels (for the report and the rig file's inverter table), the line fitted to
    those ``used``, the inverter's error per level from the slope, the smallest level fitted, and whether the knee's
    tail was fitted (reference voltages)."""

    levels: list[dict[str, Any]]
    dc: fits.DcLine
    i_l: np.ndarray
    e_slope: np.ndarray
    i_fit_min: float
    tail: bool


def _dc_stage(rec: _Record, plan: Plan, params: dict[str, Any]) -> _DcStage:
    """1. The DC staircase: the per-level means and the line (`fits.dc_line`); for reference voltages the levels
    inside the knee are left out, lowest first, and the tail's second term is fitted where the levels leave room."""
    voltages = params["voltages"]
    levels = []
    for s in plan.dc:
        w = rec.window(s.a0, s.t1)
        levels.append({"i_ref": s.level, "in_slope_fit": bool(abs(s.level) >= params.get("dc_fit_from", 0.0) - 1e-9),
                       "i": float(rec.i_a[w].mean()), "u_measured": float(rec.u_m[w].mean()),
                       "u_reference": float(rec.u_r[w].mean()), "samples": int(w.sum())})  # fmt: skip
    i_l = np.array([lv["i"] for lv in levels])
    u_l = np.array([lv[f"u_{voltages}"] for lv in levels])
    dc_fit_from = params.get("dc_fit_from", 0.0)
    tail = voltages == "reference"  # the knee bends the reference voltages only
    used = np.abs(np.array([s.level for s in plan.dc])) >= dc_fit_from - 1e-9
    dc = fits.dc_line(i_l[used], u_l[used], tail=int(tail))
    if tail and dc_fit_from <= 0:  # automatic: leave out the levels inside the knee, lowest first
        while True:
            low = np.abs(i_l[used]).min()
            bend = abs(dc.tail) / low**2
            nxt = used & (np.abs(i_l) > low + 1e-9)
            if not (bend > TAIL_REL * np.nanmean(np.abs([dc.c_pos, dc.c_neg])) and abs(dc.tail) > 2 * dc.tail_sd
                    and nxt.sum() >= 5):  # fmt: skip
                break
            used = nxt
            dc = fits.dc_line(i_l[used], u_l[used], tail=1)
    if tail and dc.dof - 1 >= SECOND_TAIL_DOF:  # the tail's second term where the levels leave room for it
        dc = fits.dc_line(i_l[used], u_l[used], tail=2)
    for lv, u_ in zip(levels, used):
        lv["in_slope_fit"] = bool(u_)
    u_ref_l = np.array([lv["u_reference"] for lv in levels])
    e_slope = u_ref_l - dc.R_s * i_l  # the error curve without a voltage measurement
    for lv, es in zip(levels, e_slope):
        lv["e_inv_from_slope"] = float(es)
        if voltages == "measured":
            lv["e_inv_measured"] = lv["u_reference"] - lv["u_measured"]
    return _DcStage(levels, dc, i_l, e_slope, float(np.abs(i_l[used]).min()), tail)


def _warming(rec: _Record, plan: Plan, voltages: str, dc: fits.DcLine) -> dict[str, Any]:
    """The warming check: the same statistic at both ends, inverter bias and all."""
    chk = {}
    for kind, name in (("chk0", "start"), ("chk1", "end")):
        segs = plan.checks(kind)
        ws = [rec.window(s_.a0, s_.t1) for s_ in segs]
        if len(segs) == 2 and all(w_.any() for w_ in ws):
            u = rec.u_m if voltages == "measured" else rec.u_r
            (ip, up), (in_, un) = [(rec.i_a[w_].mean(), u[w_].mean()) for w_ in ws]
            chk[name] = float((up - un) / (ip - in_))
    return {"statistic_start_ohm": chk.get("start"), "statistic_end_ohm": chk.get("end"),
            "dR_s_rel": (chk["end"] - chk["start"]) / dc.R_s if len(chk) == 2 else None, "limit_rel": MAX_WARMING}


def _lockin_z(rec: _Record, seg: Any, plan: Plan, params: dict[str, Any], st: _DcStage,
              warnings: list[str] | None, shape: str = "pchip"
              ) -> tuple[np.ndarray, np.ndarray, float, float, fits.Periods, fits.Curve | None]:  # fmt: skip
    """2. Z = U/I per line over ``seg``'s analysis window (lock-in over whole common periods), the current phasors,
    the lock-in residuals, the window's periods (`fits.periods`: the lines' noise and model error in the intervals)
    and, for reference voltages with the error curve's tail fitted, that curve as the fit's input (`fits.Curve`).
    ``shape``: how the reference voltages' error curve is interpolated between the DC levels below those fitted
    (`_error_curve`); ``warnings`` hears where the current runs below them (None: not told)."""
    k, T_s, i_a, dc, i_fit_min = rec.k, rec.T_s, rec.i_a, st.dc, st.i_fit_min
    freqs = plan.multisine.freqs
    w = rec.window(seg.a0, seg.t1)
    t = k[w] * T_s
    i = i_a[w]
    I, i_res = fits.lockin(t, i, freqs)
    curve = None
    if params["voltages"] == "measured":
        v = rec.u_m[w]
    else:  # the voltage held over [t_k, t_k+1): the reference of tick k - d, plus the error at i(t_k)
        d = int(params["delay_samples"])
        idx = np.flatnonzero(w)
        src = np.searchsorted(k, k[idx] - d)  # rows of tick k - d (a real-time run may have skipped ticks)
        ok = (src < k.size) & (k[np.minimum(src, k.size - 1)] == k[idx] - d)
        idx, src = idx[ok], src[ok]
        e_curve = _error_curve(i_a[idx], st.i_l, st.e_slope, shape)
        if st.tail:  # the fitted model where it was fitted (`fits.DcLine.error`; the levels' interpolation below)
            ii = i_a[idx]
            inside = np.abs(ii) >= i_fit_min
            e_model = dc.error(ii)
            e_curve = np.where(inside, e_model, e_curve)
        lo = i_fit_min if st.tail else np.abs(st.i_l).min()
        if warnings is not None and np.abs(i_a[idx]).min() < lo:
            what = "multisine's" if seg.kind == "ac" else f"saturation check's multisine ({seg.level:g} A bias)"
            warnings.append(f"the {what} current falls to {np.abs(i_a[idx]).min():.2f} A, below the smallest DC "
                            f"level fitted {lo:.2f} A: the inverter error there is interpolated (raise "
                            f"{'ac_bias' if seg.kind == 'ac' else 'sat_bias'})")  # fmt: skip
        v = rec.u_r[src] - e_curve
        t = k[idx] * T_s
        i = i_a[idx]
        I, i_res = fits.lockin(t, i, freqs)
        if st.tail:  # v = u_r - e(i): ∂Z/∂(tail term) = -lock-in of its regressor where the model was used, / I
            X = np.where((np.abs(i) >= i_fit_min)[:, None], dc.tail_regressors(i), 0.0)
            curve = fits.Curve(np.column_stack([-fits.lockin(t, x, freqs)[0] / I for x in X.T]).reshape(I.size, -1),
                               dc.cov)  # fmt: skip
    U, u_res = fits.lockin(t, v, freqs)
    ms = plan.multisine
    periods = fits.periods(t, i, v, ms.f0, ms.harmonics, seg.a0, int(params["ac_periods"]), T_s)
    return U / I, I, i_res, u_res, periods, curve


def analyse(meas: dict[str, np.ndarray], ctrl: dict[str, np.ndarray], params: dict[str, Any], T_s: float,
            nominal: Any) -> dict[str, Any]:  # fmt: skip
    """The identification from a standstill run's /rig and /ctrl columns (module docstring)."""
    plan = Plan.from_params(params)
    voltages = params["voltages"]
    cols = _Record.of(meas, T_s)
    warnings: list[str] = []
    st = _dc_stage(cols, plan, params)
    levels, dc, dc_fit_from = st.levels, st.dc, params.get("dc_fit_from", 0.0)
    warming = _warming(cols, plan, voltages, dc)

    d = int(params["delay_samples"])
    freqs = plan.multisine.freqs
    filt: tuple[float, float] | None = (params["u_filter_fc"], params["u_filter_zeta"]) \
        if voltages == "measured" else None

    def lockin_z(seg: Any, shape: str = "pchip", warn: bool = True
                 ) -> tuple[np.ndarray, np.ndarray, float, float, fits.Periods, fits.Curve | None]:  # fmt: skip
        return _lockin_z(cols, seg, plan, params, st, warnings if warn else None, shape)

    ac = plan.ac
    Z, I, i_res, u_res, rec, curve = lockin_z(ac)
    wv = 2.0 * math.pi * freqs
    start = InverseGamma.of(nominal.L_s, nominal.L_r, nominal.L_m, dc.R_s, nominal.R_r)
    rs_sd = dc.R_s_ci / _t(dc.dof)
    fit = fits.impedance(wv, Z, T_s, filt, start, fixed={"R_s": dc.R_s}, fixed_sd=rs_sd, curve=curve, record=rec)
    # R_s free: does the AC agree with the DC? (reference voltages: the DC's error curve is still in its voltages)
    check = fits.impedance(wv, Z, T_s, filt, fit.params, curve=curve, record=rec)

    # 3. the saturation check: the same fit on the second bias, L_m per bias level; the incremental L'_m's change
    # between the biases puts the multisine's swing into every interval (`fits.swing_bias`)
    saturation = None
    if plan.sat is not None:
        fit, check, saturation = _saturation(lockin_z, plan, fit, check, rec, dc, rs_sd, wv, T_s, filt, voltages)
        if saturation["bias_dependent"]:
            warnings.append(saturation["message"])

    # 4. results in both forms, with intervals
    inv_g, thesis = _forms(fit, dc)
    nom_g = InverseGamma.of(nominal.L_s, nominal.L_r, nominal.L_m, nominal.R_s, nominal.R_r)

    inv_table = from_levels(levels, "e_inv_measured" if voltages == "measured" else "e_inv_from_slope").as_dict()
    refused = refusals(inv_g, thesis, fit.residual_rms, warming, saturation)
    return {
        "voltages": voltages,
        "refused": refused,
        "warnings": warnings,
        "inverse_gamma": inv_g,
        "thesis_L_s_eq_L_r": thesis,
        "inverter_error": inv_table,
        "dc": {"R_s": _val(dc.R_s, dc.R_s_ci), "intercept_pos_V": dc.c_pos, "intercept_neg_V": dc.c_neg,
               "knee_tail_VA2": dc.tail if st.tail else None, "knee_tail_VA4": dc.tail4 if st.tail else None,
               "fit_from_A": st.i_fit_min,
               "residual_rms_V": dc.residual_rms, "dof": dc.dof, "levels": levels},  # fmt: skip
        "warming": warming,
        "saturation": saturation,
        "ac": _ac_report(fit, check, freqs, Z, I, i_res, u_res),
        "conditions": {
            "T_s": T_s, "duration_s": plan.duration, "axis": "stator alpha (phase a), i_beta = 0",
            "dc_levels_A": [s.level for s in plan.dc], "dc_fit_from_A": dc_fit_from,
            "dc_settle_s": params["dc_settle"],
            "dc_average_s": params["dc_average"], "ac_bias_A": ac.level, "ac_peak_A": plan.multisine.peak,
            "ac_line_amplitude_A": plan.multisine.amplitude, "ac_freqs_Hz": [float(f) for f in freqs],
            "ac_periods": params["ac_periods"], "delay_samples": d,
            "sat_bias_A": plan.sat.level if plan.sat is not None else None,
            "sat_peak_A": plan.sat_multisine.peak if plan.sat_multisine is not None else None,
            "voltage_filter": {"f_c": params["u_filter_fc"], "zeta": params["u_filter_zeta"]} if filt else None,
            "shaft_counts_max": int(np.max(np.abs(ctrl["shaft_counts"]))),
        },
        "nominal": {"inverse_gamma": nom_g.as_dict(), "thesis": {n: getattr(nominal, n) for n in
                                                                   ("L_s", "L_r", "L_m", "R_s", "R_r")}},  # fmt: skip
    }


def _saturation(lockin_z: Callable[..., Any], plan: Plan, fit: fits.ImpedanceFit, check: fits.ImpedanceFit,
                rec: fits.Periods, dc: fits.DcLine, rs_sd: float, wv: np.ndarray, T_s: float,
                filt: tuple[float, float] | None, voltages: str
                ) -> tuple[fits.ImpedanceFit, fits.ImpedanceFit, dict[str, Any]]:  # fmt: skip
    """The impedance fit again on the second bias (`Plan.sat`), the multisine's swing (the slope of the incremental
    L'_m between the biases, and its curvature's scale) put into the intervals of both fits and of the R_s-free
    check (`fits.swing_bias`, `fits.with_swing`); returns the fit and the check so widened, and the saturation
    check (`saturation_check`)."""
    ac = plan.ac
    Z2, I2, _, _, rec2, curve2 = lockin_z(plan.sat)
    fit2 = fits.impedance(wv, Z2, T_s, filt, fit.params, fixed={"R_s": dc.R_s}, fixed_sd=rs_sd, curve=curve2,
                          record=rec2)  # fmt: skip
    spacing = ac.level - plan.sat.level
    slope = (fit.params.L_M - fit2.params.L_M) / spacing
    # two points give no curvature; its scale is taken as the slope changing by its own size over the spacing
    # (the cube's part of the swing, which an odd multisine reads as L'_m: docs/results/identify-intervals.md)
    curv = abs(slope / spacing)
    fitted = ((fit, rec), (fit2, rec2), (check, rec))
    bias = [[fits.swing_bias(f, r, slope, wv, T_s, filt), fits.swing_bias(f, r, 0.0, wv, T_s, filt, curv)]
            for f, r in fitted]  # fmt: skip
    if voltages == "reference":  # the second bias's current runs below the levels fitted, where the error curve
        # is interpolated between the levels (`_error_curve`): the step to a straight line goes into its intervals
        Z2c = lockin_z(plan.sat, "linear", warn=False)[0]
        alt = fits.impedance(wv, Z2c, T_s, filt, fit2.params, fixed={"R_s": dc.R_s}, fixed_sd=rs_sd, record=rec2)
        bias[1].append(np.array([getattr(alt.params, n) - getattr(fit2.params, n) for n in fit2.free]))
    fit, fit2, check = (fits.with_swing(f, np.array(b)) for (f, _), b in zip(fitted, bias))
    saturation = saturation_check([(ac.level, fit, _forms(fit, dc)), (plan.sat.level, fit2, _forms(fit2, dc))])
    return fit, check, saturation


def _ac_report(fit: fits.ImpedanceFit, check: fits.ImpedanceFit, freqs: np.ndarray, Z: np.ndarray, I: np.ndarray,
               i_res: float, u_res: float) -> dict[str, Any]:  # fmt: skip
    """The AC test's part of the result: the fit's residual, the lock-in's, the R_s-free check, each line's
    measured and fitted impedance with its noise and model error, and the lack-of-fit test."""
    le = fit.errors
    return {"residual_rms_rel": fit.residual_rms, "dof": fit.dof,
            "lockin_residual_rms": {"i_A": i_res, "u_V": u_res},
            "R_s_free_check": {n: _val(getattr(check.params, n), check.ci95[n]) for n in check.free}
            | {"residual_rms_rel": check.residual_rms},
            "lines": [{"f_Hz": float(f), "Z_re": float(z.real), "Z_im": float(z.imag), "Z_fit_re": float(zf.real),
                       "Z_fit_im": float(zf.imag), "I_A": float(abs(ii)),
                       "noise_rel": math.sqrt(le.noise_var[j]) if le and le.noise_var is not None else None,
                       "model_error_rel": float(le.model[j]) if le else None}
                      for j, (f, z, zf, ii) in enumerate(zip(freqs, Z, fit.Z_fit, I))],
            "lack_of_fit": {"statistic": le.lof_statistic, "limit": le.lof_limit,
                            "found": bool(le.lof_statistic > le.lof_limit)} if le else None}  # fmt: skip


def _forms(fit: fits.ImpedanceFit, dc: fits.DcLine) -> tuple[dict[str, Any], dict[str, Any]]:
    """An impedance fit (R_s fixed at the DC test's) in both forms with 95 % intervals: inverse-Γ, and the thesis'
    T parameters under L_s = L_r; R_s's interval from the DC fit, the others' `fits.ImpedanceFit.half_width`
    (R_s's error passed on; the thesis form's by the gradient of `thesis_params`)."""
    p = fit.params
    th_names = ("L_s", "L_m", "R_r")
    th = thesis_params(p)
    x = np.array([getattr(p, n) for n in fit.free])

    def of(y: np.ndarray) -> np.ndarray:
        q = InverseGamma(**{**p.as_dict(), **dict(zip(fit.free, y))})
        return np.array([thesis_params(q)[n] for n in th_names])

    G = fits.gradient(of, x)
    inv_g = {"R_s": _val(p.R_s, dc.R_s_ci)} | {n: _val(getattr(p, n), fit.ci95[n]) for n in fit.free}
    thesis = {n: _val(th[n], fit.half_width(g)) for n, g in zip(th_names, G)}
    thesis["L_r"] = thesis["L_s"]
    thesis["R_s"] = inv_g["R_s"]
    return inv_g, thesis


def saturation_check(levels: list[tuple[float, fits.ImpedanceFit, tuple[dict[str, Any], dict[str, Any]]]]
                     ) -> dict[str, Any]:  # fmt: skip
    """L_m per DC bias of the multisine, and whether it depends on the bias (``saturation`` in the JSON).

    At standstill the rotor carries no current at DC, so the bias i sets the main flux and the multisine
    measures the incremental inductance dψ/di at it. The flux is its integral from 0 over the measured points
    (trapezoids, L_m taken constant below the lowest bias): L_m i on a linear machine. ``levels``: (bias [A],
    the impedance fit, its `_forms`), the test's own bias first. Bias-dependent when the largest and smallest
    L_m differ by more than their 95 % intervals together (root sum of squares) *and* by more than
    `SAT_TOL` of their mean: a dependence below what ``--write`` accepts as an interval (`rigfile.MAX_REL_CI`)
    is no reason to refuse."""
    pts = sorted(({"bias_A": float(b), "L_m": th["L_m"], "L_M": ig["L_M"], "L_sigma": ig["L_sigma"],
                   "residual_rms_rel": f.residual_rms} for b, f, (ig, th) in levels), key=lambda x: x["bias_A"])  # fmt: skip
    psi, i0, l0 = 0.0, 0.0, pts[0]["L_m"]["value"]
    for x in pts:
        lm = x["L_m"]["value"]
        psi += 0.5 * (l0 + lm) * (x["bias_A"] - i0)
        x["flux_Wb"] = psi
        i0, l0 = x["bias_A"], lm
    half = [(x["L_m"]["ci95"][1] - x["L_m"]["ci95"][0]) / 2.0 for x in pts]
    vals = [x["L_m"]["value"] for x in pts]
    hi, lo = int(np.argmax(vals)), int(np.argmin(vals))
    diff = vals[hi] - vals[lo]
    allowed = math.hypot(half[hi], half[lo])
    rel = diff / (0.5 * (vals[hi] + vals[lo]))
    dep = bool(diff > allowed and rel > SAT_TOL)
    out = {"points": pts, "test_bias_A": float(levels[0][0]), "bias_dependent": dep, "difference_rel": rel,
           "allowed_rel": max(allowed / (0.5 * (vals[hi] + vals[lo])), SAT_TOL), "tolerance_rel": SAT_TOL}  # fmt: skip
    out["message"] = saturation_message(out) if dep else None
    return out


def refusals(inv_g: dict[str, Any], thesis: dict[str, Any], residual: float, warming: dict[str, Any],
             saturation: dict[str, Any] | None = None, rotating: bool = False) -> list[str]:  # fmt: skip
    """Why the identification must not be used (one line each; empty: plausible). Thresholds: module constants.
    Where the saturation check found L_m bias-dependent, or a rotating test follows (``rotating``), the intervals of
    what is made of the incremental L'_m (`SATURATED`) are not held to `rigfile.MAX_REL_CI`: a standstill test does
    not give them for ``--write`` (`saturated_write_refusal`; with ``--rotating`` L_m is the rotating test's, and
    its interval is judged after it), and on a bias-dependent machine their intervals carry the multisine's
    large-signal error (docs/commissioning.md)."""
    out = []
    v = {n: x["value"] for n, x in inv_g.items()}
    for n in ("R_s", "R_R", "L_M", "L_sigma"):
        if not v[n] > 0:
            out.append(f"{n} = {v[n]:.4g} is not positive")
    if v["L_M"] > 0 and not LEAKAGE_BAND[0] <= v["L_sigma"] / v["L_M"] <= LEAKAGE_BAND[1]:
        out.append(f"leakage/magnetising ratio L'_s/L'_m = {v['L_sigma'] / v['L_M']:.3g} is outside "
                   f"[{LEAKAGE_BAND[0]:g}, {LEAKAGE_BAND[1]:g}]")  # fmt: skip
    if not residual <= MAX_RESIDUAL:
        out.append(f"the impedance fit's relative residual {residual:.2%} exceeds {MAX_RESIDUAL:.0%}: the circuit "
                   "does not describe the data")  # fmt: skip
    skip = SATURATED if rotating or (saturation and saturation.get("bias_dependent")) else ()
    for form, vals in (("inverse-Gamma", inv_g), ("L_s = L_r", thesis)):
        for n, x in vals.items():
            if form == "L_s = L_r" and n in ("R_s", "L_r"):  # the same numbers as inverse-Gamma R_s and L_s
                continue
            if (form, n) in skip:
                continue
            wide = wide_interval(f"{n} ({form})", x)
            if wide:
                out.append(wide)
    d = warming.get("dR_s_rel")
    if d is None:
        out.append("no warming check (the test's start or end is missing)")
    elif not abs(d) <= warming["limit_rel"]:
        out.append(f"R_s changed by {d:+.2%} between the start and the end of the test (limit "
                   f"{warming['limit_rel']:.0%}): the motor is warming; let it cool and repeat")  # fmt: skip
    return out


def _error_curve(i: np.ndarray, i_l: np.ndarray, e_l: np.ndarray, shape: str = "pchip") -> np.ndarray:
    """The inverter error at currents ``i`` from the DC levels (i_l, e_l): interpolated on the branch of
    i's sign (the error jumps at zero current), held constant beyond the outermost levels; ``shape`` "pchip"
    (shape-preserving cubic: it follows a knee's bend between the levels, where a straight line cuts it and put
    the second bias's L_m 3-5 % low over 100 fleet motors, now 0.5-0.8 %) or "linear"."""
    from scipy.interpolate import PchipInterpolator

    out = np.empty_like(i)
    for sgn in (1.0, -1.0):
        sel, br = sgn * i >= 0, sgn * i_l > 0
        if not br.any():
            br = np.ones_like(br)
        order = np.argsort(i_l[br])
        x, y = i_l[br][order], e_l[br][order]
        if shape == "pchip" and x.size >= 3:
            out[sel] = PchipInterpolator(x, y, extrapolate=False)(np.clip(i[sel], x[0], x[-1]))
        else:
            out[sel] = np.interp(i[sel], x, y)
    return out


def _t(dof: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, dof)) if dof > 0 else math.inf




