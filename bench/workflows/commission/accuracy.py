"""Accuracy of the standstill identification against the mock plant's hidden truth (`bench perf identify`).

The mock plant knows the machine it simulates (``[mock.motor]``) while the rig's ``[motor]`` - the
nominal model the test's current controllers are tuned on - stays the thesis' (3.57). This module
draws hidden machines at random, runs `bench.workflows.commission.identify.identify` on each through the
ordinary session (lockstep), once with the measured and once with the reference voltages, each with
that mode's defaults (what ``bench identify --voltages MODE`` does), and compares the results with
the truth. ``one_run`` (``--one-run``) halves the time: one run with the measured voltages, its log
fitted both ways (`analyse_log`: both voltages are in every log) - the same thing only while the two
modes share their test plan (they do not: the reference voltages have their own defaults).

**The hidden motors.** From ``numpy.random.default_rng(motors_seed)``, per motor, independently and
uniformly within ±`SPREAD` (40 %) of (3.57): R_s, R_r, L_m and the *per-side leakage inductance*
L_ls = L_s − L_m = L_r − L_m (0.011 H in (3.57)); then L_s = L_r = L_m + L_ls. The machines are drawn
with L_s = L_r on purpose: the terminals fix only the four inverse-Γ parameters (R_s, L'_s = σ L_s,
R'_r = (L_m/L_r)² R_r, L'_m = L_m²/L_r, `bench.workflows.commission.circuit`), so the thesis' T parameters
are comparable with a truth only when the truth satisfies the thesis' assumption L_s = L_r (3.6).
The inverse-Γ comparison is valid for any machine. Values are rounded to 4 significant digits (the
rounded values are the truth, written into the rig file). Each is checked with
`MotorParams.validate` and the rig file with `MockConfig.from_dict`.

Per motor the inverter's voltage error (`mock_hw.inverter`) is drawn too: dead time uniform in
0–3 µs (at 560 V and 15 kHz: 0–25 V per phase), on-state drop uniform in 0–2 V, the soft knee of
``rigs/mock-real.toml`` (i_knee = 0.2 A). The sensor model is the mock's default and all of it is
on without asking: current and voltage noise (2 mV rms at the ADC), 12-bit ADCs on ±10 V, the
voltage channel's 2nd-order 1 kHz filter, the inverter's one-sample delay. Main-flux saturation and
the thermal model are off (standstill identification measures the incremental L_m at its bias flux,
not the rated secant one: docs/commissioning.md); one extra row, not in the summary, shows the
thesis motor with the saturation curve of ``rigs/mock-real.toml``.

Row 0 is the thesis motor (3.57) itself, with the inverter of ``rigs/mock-real.toml`` (2 µs,
1.5 V, 0.2 A), then ``n_motors`` random ones; the summary covers all of them.

**Tolerances** (`TOL`, relative): R_s 2 %, R_r 5 %, leakage 5 %, L_m 5 % with the measured voltages,
twice those with the reference voltages (`REFERENCE_FACTOR`); each applies to both forms -
inverse-Γ (R_s, R'_r, L'_s, L'_m) and thesis (R_s, R_r, L_ls, L_m). **Repeatability**: for
``repeat_motors`` of the random motors, ``repeat_seeds`` noise seeds each; the coefficient of
variation std/mean (ddof = 1) at most 1 % for R_s, 2 % for the rest (`CV_MAX`).

**Time**: per run the rig (loop) time of the test, the loop's wall time and the wall time of the
whole `identify` call (session, fit, plots); with ``one_run`` also that of the second fit.

The plant's engine defaults to "auto" (numba when it imports): bit-identical to the Python reference
(`mock_hw.plant`), several times faster per run.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomlkit

from bench.workflows.commission.circuit import InverseGamma
from bench.errors import BadInput
from bench.params import MotorParams
from bench.core.config import RIGS_DIR
from bench.core import nameplate
from mock_hw.plant import MockConfig
from bench.workflows.commission.identify import analyse_log, identify
from bench.core.progress import Steps
from bench.workflows.commission.rotating import identify_rotating
from bench.core.shutdown import Interrupted

SPREAD = 0.4  # each drawn parameter within +-40 % of (3.57)
DEAD_TIME_MAX = 3e-6  # [s]
V_ON_MAX = 2.0  # [V]
THESIS = MotorParams()  # (3.57)

TOL = {"R_s": 0.02, "R_r": 0.05, "leakage": 0.05, "L_m": 0.05}  # measured voltages
REFERENCE_FACTOR = 2.0  # reference voltages: twice those
CV_MAX = {"R_s": 0.01, "R_r": 0.02, "leakage": 0.02, "L_m": 0.02}
VOLTAGES = ("measured", "reference")
# which estimate each toleranced quantity is, per form (names as in identify's JSON; L_ls = L_s - L_m)
FORMS: dict[str, dict[str, str]] = {
    "inverse_gamma": {"R_s": "R_s", "R_r": "R_R", "leakage": "L_sigma", "L_m": "L_M"},
    "thesis": {"R_s": "R_s", "R_r": "R_r", "leakage": "L_ls", "L_m": "L_m"},
}
ENGINES = ("auto", "compiled", "python")
ABBR = {"measured": "meas.", "reference": "ref."}


def mock_real() -> tuple[dict[str, float], dict[str, Any]]:
    """The inverter error ([mock.inverter]) and the saturation curve ([mock.motor]) of rigs/mock-real.toml:
    the thesis rows use both, the drawn motors its knee."""
    import tomllib


    mock = tomllib.loads((RIGS_DIR / "mock-real.toml").read_text(encoding="utf-8"))["mock"]
    inv = {k: float(mock["inverter"][k]) for k in ("dead_time", "v_on", "i_knee")}
    return inv, {k: mock["motor"][k] for k in ("saturation", "psi_rated", "psi_sat", "sat_exp")}


@dataclass(frozen=True)
class HiddenMotor:
    """One test machine: the truth in [mock.motor] and its inverter's voltage error."""

    label: str
    params: MotorParams
    dead_time: float  # [s]
    v_on: float  # [V]
    i_knee: float  # [A]
    saturation: bool = False

    def truth(self) -> dict[str, dict[str, float]]:
        """The true parameters in both forms (inverse-Γ always valid; the thesis form because L_s = L_r)."""
        p = self.params
        g = InverseGamma.of(p.L_s, p.L_r, p.L_m, p.R_s, p.R_r)
        return {"inverse_gamma": g.as_dict(),
                "thesis": {"R_s": p.R_s, "R_r": p.R_r, "L_m": p.L_m, "L_s": p.L_s, "L_ls": p.L_s - p.L_m}}  # fmt: skip

    def inverter(self) -> dict[str, float]:
        return {"dead_time": self.dead_time, "v_on": self.v_on, "i_knee": self.i_knee}

    def rig_text(self, engine: str = "auto") -> str:
        """A mock rig file: [motor] = (3.57) (what the rig believes), [mock.motor] = this machine, and this machine's
        plate (`bench.core.nameplate.plate_of` at the thesis motor's 380 V, 50 Hz, 1420 rpm; (3.57) keeps App. A.1's).
        Another machine's rig leaves [motor] out (its defaults are (3.57) all the same): the plate is checked
        against a [motor] the file states, and (3.57) is not that machine."""

        doc = tomlkit.parse((RIGS_DIR / "mock.toml").read_text(encoding="utf-8"))
        if self.params != THESIS:
            pl = nameplate.THESIS
            doc["nameplate"] = nameplate.plate_of(self.params, pl.U_rated, pl.f_rated, pl.n_rated).as_dict()
            del doc["motor"]  # the rig knows the plate, not yet the machine: (3.57) would not fit it
        doc["rig"]["name"] = f"accuracy-{self.label}"  # type: ignore[index]
        mock = doc["mock"]
        mock["engine"] = engine  # type: ignore[index]
        mock["inverter"] = self.inverter()  # type: ignore[index]
        p = self.params
        motor: dict[str, Any] = {n: getattr(p, n) for n in ("L_s", "L_r", "L_m", "R_s", "R_r")}
        if self.saturation:
            motor.update(mock_real()[1])
        mock["motor"] = motor  # type: ignore[index]
        return tomlkit.dumps(doc)


def _sig(x: float, digits: int = 4) -> float:
    return float(f"{x:.{digits - 1}e}")


def thesis_motor(saturation: bool = False) -> HiddenMotor:
    """(3.57) behind the inverter of rigs/mock-real.toml (optionally with its saturation curve)."""
    return HiddenMotor("thesis-saturated" if saturation else "thesis", THESIS, saturation=saturation,
                       **mock_real()[0])  # fmt: skip


def draw_motors(n: int, seed: int = 0) -> list[HiddenMotor]:
    """``n`` random machines (module docstring), validated."""
    rng = np.random.default_rng(seed)
    knee = mock_real()[0]["i_knee"]
    out = []
    for j in range(1, n + 1):
        f_Rs, f_Rr, f_Lm, f_Lls = rng.uniform(1.0 - SPREAD, 1.0 + SPREAD, 4)
        L_m = _sig(THESIS.L_m * f_Lm)
        L_s = _sig(L_m + _sig((THESIS.L_s - THESIS.L_m) * f_Lls))
        p = THESIS.with_(R_s=_sig(THESIS.R_s * f_Rs), R_r=_sig(THESIS.R_r * f_Rr), L_m=L_m, L_s=L_s, L_r=L_s)
        p.validate()
        m = HiddenMotor(f"m{j:02d}", p, dead_time=_sig(rng.uniform(0.0, DEAD_TIME_MAX)),
                        v_on=_sig(rng.uniform(0.0, V_ON_MAX)), i_knee=knee)  # fmt: skip
        MockConfig.from_dict(tomlkit.parse(m.rig_text()).unwrap()["mock"])  # the plant accepts it
        out.append(m)
    return out


def estimates(res: dict[str, Any]) -> dict[str, dict[str, float]]:
    """An identification's values in both forms (names of `HiddenMotor.truth`)."""
    g = {n: v["value"] for n, v in res["inverse_gamma"].items()}
    th = {n: res["thesis_L_s_eq_L_r"][n]["value"] for n in ("R_s", "R_r", "L_m", "L_s")}
    th["L_ls"] = th["L_s"] - th["L_m"]
    return {"inverse_gamma": g, "thesis": th}


def in_ci95(res: dict[str, Any], truth: dict[str, dict[str, float]]) -> dict[str, bool]:
    """Whether each true inverse-Γ value lies inside the identification's own 95 % interval (do the
    intervals account for the errors, or is there a bias they do not see?)."""
    g = res["inverse_gamma"]
    return {n: bool(g[n]["ci95"][0] <= truth["inverse_gamma"][n] <= g[n]["ci95"][1]) for n in g}


def errors(res: dict[str, Any], truth: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """Relative errors estimate/truth - 1, per form and parameter."""
    est = estimates(res)
    return {form: {n: est[form][n] / truth[form][n] - 1.0 for n in truth[form]} for form in truth}


def tolerance(voltages: str) -> dict[str, float]:
    k = 1.0 if voltages == "measured" else REFERENCE_FACTOR
    return {q: k * t for q, t in TOL.items()}


def verdict(err: dict[str, dict[str, float]], voltages: str) -> dict[str, Any]:
    """Per form and toleranced quantity: the error, the tolerance, pass; "pass" overall."""
    tol = tolerance(voltages)
    out: dict[str, Any] = {}
    ok = True
    for form, names in FORMS.items():
        out[form] = {}
        for q, n in names.items():
            e = err[form][n]
            good = bool(abs(e) <= tol[q])
            ok &= good
            out[form][q] = {"param": n, "error": e, "tol": tol[q], "pass": good}
    out["pass"] = ok
    return out


def _fit_row(r: dict[str, Any], truth: dict[str, dict[str, float]], voltages: str) -> dict[str, Any]:
    err = errors(r, truth)
    out = {"errors": err, "verdict": verdict(err, voltages), "estimates": estimates(r),
           "truth_in_ci95": in_ci95(r, truth), "warnings": r["warnings"],
           "ac_residual_rms_rel": r["ac"]["residual_rms_rel"]}  # fmt: skip
    if r.get("refused"):  # bench identify's own refusal (exit 1, nothing written): the mode failed here
        out["refused"] = r["refused"]
        out["verdict"]["pass"] = False
    return out


def _one(motor: HiddenMotor, seed: int, params: dict[str, Any], folder: Path, engine: str,
         modes: tuple[str, ...], one_run: bool) -> dict[str, Any]:  # fmt: skip
    """Identify ``motor`` (noise seed ``seed``) with each of ``modes``: a run per mode, with that mode's
    defaults (what `bench identify --voltages MODE` does); ``one_run``: one run with the measured
    voltages, its log fitted with each mode (`analyse_log`)."""
    folder.mkdir(parents=True, exist_ok=True)
    rig = folder / f"{motor.label}.toml"
    rig.write_text(motor.rig_text(engine), encoding="utf-8")
    truth = motor.truth()
    row: dict[str, Any] = {"motor": motor.label, "seed": seed}
    for v in ("measured",) if one_run else modes:
        t0 = time.perf_counter()
        res = identify(str(rig), voltages=v, params=params, seed=seed, out_dir=folder / v)
        wall = time.perf_counter() - t0
        if "tripped" in res:
            if res["exit_code"] > 128:  # a signal (Ctrl-C, SIGTERM) ended the run: it ends the benchmark too

                raise Interrupted(res["exit_code"] - 128)
            for w in modes if one_run else (v,):
                row[w] = {"tripped": res["tripped"], "verdict": {"pass": False}}
            continue
        summary = json.loads((Path(res["log"]).parent / "summary.json").read_text())
        timing = {"rig_s": summary["duration"], "loop_wall_s": summary["wall_time"], "identify_wall_s": wall}
        for w in modes if one_run else (v,):
            t0 = time.perf_counter()
            r = res if w == v else analyse_log(Path(res["log"]), w)
            row[w] = _fit_row(r, truth, w) | {"time": timing if w == v else {**timing, "refit_wall_s":
                                                                             time.perf_counter() - t0}}  # fmt: skip
            row[w].update({"shaft_counts_max": res["conditions"]["shaft_counts_max"], "log": res["log"]})
    return row


def _summary(rows: list[dict[str, Any]], modes: tuple[str, ...]) -> dict[str, Any]:
    """Max |error| per voltages, form and quantity over the rows, with the worst motor; pass per tolerance."""
    out: dict[str, Any] = {"motors": len(rows)}
    for v in modes:
        tol = tolerance(v)
        ok_rows = [r for r in rows if "errors" in r[v]]
        sv: dict[str, Any] = {"tripped": [r["motor"] for r in rows if "tripped" in r[v]],
                              "refused": [r["motor"] for r in ok_rows if r[v].get("refused")]}  # fmt: skip
        all_ok = not sv["tripped"] and not sv["refused"]
        for form, names in FORMS.items():
            sv[form] = {}
            for q, n in names.items():
                errs = [(abs(r[v]["errors"][form][n]), r[v]["errors"][form][n], r["motor"]) for r in ok_rows]
                worst = max(errs) if errs else (math.nan, math.nan, None)
                fails = [m for a, _, m in errs if not a <= tol[q]]
                sv[form][q] = {"param": n, "max_abs_error": worst[0], "worst_error": worst[1],
                               "worst_motor": worst[2], "tol": tol[q], "failing_motors": fails,
                               "pass": not fails and not sv["tripped"]}  # fmt: skip
                all_ok &= not fails
        ci = [x for r in ok_rows for x in r[v]["truth_in_ci95"].values()]
        sv["truth_in_ci95_share"] = sum(ci) / len(ci) if ci else math.nan
        sv["pass"] = bool(all_ok)
        out[v] = sv
    return out


def _repeatability(runs: dict[str, list[dict[str, Any]]], modes: tuple[str, ...]) -> dict[str, Any]:
    """Coefficient of variation per motor, voltages, form and quantity over its seeds; max over motors."""
    per: dict[str, Any] = {label: {"seeds": [r["seed"] for r in rows]} for label, rows in runs.items()}
    out: dict[str, Any] = {"per_motor": per}
    for v in modes:
        worst: dict[str, dict[str, float]] = {f: {q: 0.0 for q in FORMS[f]} for f in FORMS}
        tripped = [f"{label} seed {r['seed']}" for label, rows in runs.items() for r in rows if "errors" not in r[v]]
        for label, rows in runs.items():
            ok = [r for r in rows if "errors" in r[v]]
            per[label][v] = {}
            for form, names in FORMS.items():
                per[label][v][form] = {}
                for q, n in names.items():
                    x = np.array([r[v]["estimates"][form][n] for r in ok])
                    e = np.array([r[v]["errors"][form][n] for r in ok])
                    cv = float(np.std(x, ddof=1) / abs(np.mean(x))) if x.size > 1 else math.nan
                    per[label][v][form][q] = {"cv": cv, "mean_error": float(e.mean()) if e.size else math.nan}
                    worst[form][q] = max(worst[form][q], cv) if not math.isnan(cv) else math.nan
        out[v] = {form: {q: {"max_cv": worst[form][q], "limit": CV_MAX[q], "pass": bool(worst[form][q] <= CV_MAX[q])}
                         for q in FORMS[form]} for form in FORMS}  # fmt: skip
        out[v]["tripped"] = tripped
        out[v]["pass"] = not tripped and all(x["pass"] for f in FORMS for x in out[v][f].values())
    return out


def _times(rows: list[dict[str, Any]], modes: tuple[str, ...]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for v in modes:
        out[v] = {}
        for k in ("rig_s", "loop_wall_s", "identify_wall_s", "refit_wall_s"):
            x = [r[v]["time"][k] for r in rows if k in r[v].get("time", {})]
            if x:
                out[v][k] = {"mean": float(np.mean(x)), "max": float(np.max(x))}
    return out


def run(n_motors: int = 20, *, motors_seed: int = 0, seed: int = 0, repeat_motors: int = 3, repeat_seeds: int = 10,
        params: dict[str, Any] | None = None, voltages: tuple[str, ...] = VOLTAGES, one_run: bool = False,
        thesis_row: bool = True, saturation_row: bool = True, engine: str = "auto", out_dir: Path | None = None,
        progress: bool = True) -> dict[str, Any]:  # fmt: skip
    """The benchmark (module docstring). ``voltages``: the modes judged, each by its own run (``one_run``:
    one run with the measured voltages, fitted with each); ``thesis_row``: (3.57) first; ``out_dir``:
    keep the rig files, logs and plots there (else a temporary folder, removed at the end)."""
    if engine not in ENGINES:
        raise BadInput("--engine", f"must be one of {', '.join(ENGINES)}, got {engine!r}")
    modes = tuple(v for v in VOLTAGES if v in voltages)
    if not modes or len(modes) != len(set(voltages)):
        raise BadInput("--voltages", f"must be some of {', '.join(VOLTAGES)}, got {', '.join(map(str, voltages))}")
    params = dict(params or {})
    if "voltages" in params:
        raise BadInput("--param voltages", "is not a parameter here: the modes are chosen with --voltages")
    if not 0 <= repeat_motors <= n_motors:
        raise BadInput("--repeat-motors", f"must be in 0..{n_motors} (--motors), got {repeat_motors}")
    if repeat_motors and repeat_seeds < 2:
        raise BadInput("--repeat-seeds", f"must be at least 2 for a coefficient of variation, got {repeat_seeds}")
    drawn = draw_motors(n_motors, motors_seed)
    motors = ([thesis_motor()] if thesis_row else []) + drawn
    extra_seeds = [seed + k for k in range(1, repeat_seeds)] if repeat_motors else []
    per_motor = 1 if one_run else len(modes)
    total = per_motor * (len(motors) + repeat_motors * len(extra_seeds) + int(saturation_row))
    tmp = None if out_dir is not None else tempfile.TemporaryDirectory(prefix="bench-perf-identify-")
    root = Path(out_dir) if out_dir is not None else Path(tmp.name)  # type: ignore[union-attr]
    t_start = time.perf_counter()
    done = 0
    try:
        with Steps(total, "identify runs", tty=None if progress else False) as step:

            def go(m: HiddenMotor, s: int) -> dict[str, Any]:
                nonlocal done
                r = _one(m, s, params, root / m.label / f"seed{s}", engine, modes, one_run)
                done += per_motor
                step(done)
                return r

            rows = [go(m, seed) for m in motors]
            repeats = {m.label: [first] + [go(m, s) for s in extra_seeds]
                       for m, first in list(zip(drawn, rows[len(motors) - len(drawn):]))[:repeat_motors]}  # fmt: skip
            sat = go(thesis_motor(saturation=True), seed) if saturation_row else None
    finally:
        if tmp is not None:
            tmp.cleanup()
    if tmp is not None:  # the logs are gone
        for r in rows + ([sat] if sat else []):
            for v in modes:
                r[v].pop("log", None)
    summary = _summary(rows, modes)
    rep = _repeatability(repeats, modes) if repeats else None
    return {
        "benchmark": "standstill identification against the mock plant's hidden truth",
        "config": {
            "n_random_motors": n_motors, "thesis_row": thesis_row, "motors_seed": motors_seed, "noise_seed": seed,
            "spread": SPREAD,
            "drawn": "R_s, R_r, L_m, L_ls = L_s - L_m (L_s = L_r), each uniform within +-spread of (3.57)",
            "dead_time_s": [0.0, DEAD_TIME_MAX], "v_on_V": [0.0, V_ON_MAX], "i_knee_A": mock_real()[0]["i_knee"],
            "sensors": "mock defaults: noise 2 mV rms at the ADCs, 12-bit ADCs, 1 kHz voltage filter, "
                       "one-sample inverter delay", "saturation": False, "thermal": False,
            "voltages": list(modes),
            "runs": "one run per motor and seed with the measured voltages, fitted with each" if one_run else
                    "one run per motor, seed and voltages, with that voltages' defaults",
            "identify_params": params, "engine": engine, "repeat_motors": repeat_motors,
            "repeat_seeds": [seed] + extra_seeds if repeat_motors else [],
            "tolerances": {v: tolerance(v) for v in modes}, "cv_max": CV_MAX, "forms": FORMS,
        },  # fmt: skip
        "summary": summary,
        "repeatability": rep,
        "time": _times(rows + [r for rs in repeats.values() for r in rs[1:]], modes),
        "total_wall_s": time.perf_counter() - t_start,
        "motors": [{"label": m.label, "truth": m.truth(), "inverter": m.inverter(), **r} for m, r in zip(motors, rows)],
        "saturation_row": ({"label": "thesis-saturated", "truth": thesis_motor(True).truth(), "curve": mock_real()[1],
                            "inverter": mock_real()[0], **sat} if sat else None),  # fmt: skip
        "pass": {v: summary[v]["pass"] and (rep is None or rep[v]["pass"]) for v in modes},
    }


def _pct(x: float, sign: bool = True) -> str:
    text = f"{100 * x:+.2f}" if sign else f"{100 * x:.2f}"
    return "0.00 %" if float(text) == 0.0 else text.replace("-", "−") + " %"


def _cell(text: str, ok: bool) -> str:
    return text if ok else f"**{text}**"


def markdown(res: dict[str, Any]) -> str:
    """The result as markdown tables (docs/commissioning.md): the worst error per quantity, the worst
    coefficient of variation, the errors per motor (thesis form), the time. Bold: outside the tolerance."""
    modes = res["config"]["voltages"]
    forms = {"inverse_gamma": "inverse-Γ: R_s, R'_r, L'_s, L'_m", "thesis": "L_s = L_r: R_s, R_r, L_ls, L_m"}
    out = ["| voltages | form | R_s | R_r | leakage | L_m | truth inside the 95 % interval |", "|---" * 7 + "|"]
    for v in modes:
        s = res["summary"][v]
        tol = "/".join(f"{100 * t:g}" for t in tolerance(v).values())
        for form, name in forms.items():
            cells = [_cell(f"{_pct(x['max_abs_error'], False)} ({x['worst_motor']})", x["pass"])
                     for x in (s[form][q] for q in TOL)]  # fmt: skip
            share = f"{100 * s['truth_in_ci95_share']:.0f} %"
            out.append(f"| {v} (≤ {tol} %) | {name} | {' | '.join(cells)} | {share} |")
        if s["tripped"] or s["refused"]:
            bad = f"tripped: {', '.join(s['tripped']) or '-'} | refused: {', '.join(s['refused']) or '-'}"
            out.append(f"| {v} | {bad} |")
    rep = res["repeatability"]
    if rep:
        which = f"{', '.join(rep['per_motor'])}, {len(res['config']['repeat_seeds'])} seeds each"
        out += ["", f"| voltages | form | largest CV ({which}): R_s | R_r | leakage | L_m |", "|---" * 6 + "|"]
        for v in modes:
            for form, name in forms.items():
                cells = [_cell(_pct(x["max_cv"], False), x["pass"]) for x in (rep[v][form][q] for q in TOL)]
                out.append(f"| {v} (≤ {'/'.join(f'{100 * c:g}' for c in CV_MAX.values())} %) | {name} | "
                           f"{' | '.join(cells)} |")  # fmt: skip
    head = "| motor | R_s [Ω] | R_r [Ω] | L_m [H] | L_ls [mH] | t_d [µs] | v_on [V] |"
    head += "".join(f" {q} {ABBR[v]} |" for v in modes for q in ("R_s", "R_r", "L_ls", "L_m"))
    out += ["", head, "|---" * (7 + 4 * len(modes)) + "|"]
    sat = res.get("saturation_row")
    for m in res["motors"] + ([sat] if sat else []):
        t, inv = m["truth"]["thesis"], m["inverter"]
        row = (f"| {m['label']} | {t['R_s']:.4g} | {t['R_r']:.4g} | {t['L_m']:.4g} | {1e3 * t['L_ls']:.3g} | "
               f"{1e6 * inv['dead_time']:.3g} | {inv['v_on']:.3g} |")  # fmt: skip
        for v in modes:
            r = m[v]
            if "errors" not in r:
                row += f" {r.get('tripped')} | | | |"
                continue
            e, tol = r["errors"]["thesis"], tolerance(v)
            row += "".join(f" {_cell(_pct(e[n]), m is sat or abs(e[n]) <= tol[q])} |"
                           for q, n in FORMS["thesis"].items())  # fmt: skip
        out.append(row)
    out.append("")
    for v in modes:
        tm = res["time"][v]
        out.append(f"Time, {v} voltages: {tm['rig_s']['max']:.1f} s of rig time per run; wall time per run "
                   f"{tm['identify_wall_s']['mean']:.1f} s mean, {tm['identify_wall_s']['max']:.1f} s max (the loop "
                   f"{tm['loop_wall_s']['mean']:.1f} s of it).")  # fmt: skip
    out.append(f"The whole benchmark: {res['total_wall_s'] / 60:.1f} min wall.")
    return "\n".join(out) + "\n"


#: rotating tests: L_m at the rated flux within 3 %, J within 5 % (friction: reported, a few % of 0.05-0.2 N m)
ROTATING_TOL = {"L_m": 0.03, "J": 0.05}


def run_rotating(n_motors: int = 20, *, motors_seed: int = 0, seed: int = 0, saturation_row: bool = True,
                 progress: bool = True) -> dict[str, Any]:  # fmt: skip
    """The rotating tests (`bench.workflows.commission.rotating`) against the truth: per machine of `draw_motors` (and
    (3.57) with mock-real's saturation curve, whose L_m at the rated flux is 0.341 H), the standstill test
    with the measured voltages, then `identify_rotating` on its result; L_m at the rated flux, J, B_visc and
    m_coulomb against [mock.motor] (J and the friction are the mock's defaults: not drawn)."""

    motors = draw_motors(n_motors, motors_seed) + ([thesis_motor(saturation=True)] if saturation_row else [])
    rows = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-perf-identify-rotating-") as tmp, \
            Steps(len(motors), "rotating identifications", tty=None if progress else False) as step:  # fmt: skip
        for k, m in enumerate(motors):
            folder = Path(tmp) / m.label
            folder.mkdir()
            rig = folder / "rig.toml"
            rig.write_text(m.rig_text(), encoding="utf-8")
            t0 = time.perf_counter()
            ss = identify(str(rig), seed=seed, out_dir=folder)
            rot = identify_rotating(str(rig), ss, seed=seed, out_dir=folder) if "tripped" not in ss else ss
            row: dict[str, Any] = {"motor": m.label, "wall_s": time.perf_counter() - t0}
            if "tripped" in rot:
                row.update(tripped=rot["tripped"], passed=False)
            else:
                p = m.params
                est = {"L_m": rot["L_m_rated"]["value"]} | {n: rot["mechanics"][n]["value"]
                                                             for n in ("J", "B_visc", "m_coulomb")}  # fmt: skip
                err = {n: est[n] / getattr(p, n) - 1.0 for n in est}
                row.update(errors=err, rig_s=rot["rig_time_s"],
                           passed=all(abs(err[n]) <= tol for n, tol in ROTATING_TOL.items()))  # fmt: skip
            rows.append(row)
            step(k + 1)
    ok = [r for r in rows if "errors" in r]
    worst = {n: max((abs(r["errors"][n]) for r in ok), default=math.nan) for n in ("L_m", "J", "B_visc", "m_coulomb")}
    return {"benchmark": "rotating identification against the mock plant's hidden truth", "motors": len(rows),
            "motors_seed": motors_seed, "noise_seed": seed, "tolerances": ROTATING_TOL, "rows": rows,
            "worst_abs_error": worst, "pass": all(r["passed"] for r in rows),
            "rig_s_max": max((r["rig_s"] for r in ok), default=math.nan), "total_wall_s": time.perf_counter() - t_start}
