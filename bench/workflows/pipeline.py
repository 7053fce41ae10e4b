"""`bench pipeline narx-speed`: the thesis' systematic chain in one command (6.4, 7.2).

rig logs -> neural model -> quasi-LPV model -> controller -> back on the rig:

1. **collect** the training and validation sets of 6.4.2 (`bench.workflows.narx.collect_sets`, two seeds);
2. **train** the NARX MLP by Levenberg-Marquardt for each initialisation spread in ``spreads``
   (`bench.workflows.narx.train`: ARX, MLP, validation report, MLP -> LFT), the candidates in parallel as tasks of the
   sweep engine (`bench.workflows.sweep.tasks`, task ``narx_candidate``; each also computes its gamma_a);
3. **select** the model for control: the thesis found that "many different models gave the same
   performance ... but in order to construct a controller yielding a good closed-loop performance it was
   necessary for the sector bounds to be small" (6.4.2). Among the candidates whose validation rms error is
   within `RMS_TOLERANCE` of the best, the one with the smallest LMI bound gamma_a of the Fig. 6.13 set-up
   (`synthesis.lmi.bisect_gamma`) is taken;
4. **synthesise and verify** the LPV speed controller (6.4.3) and the robust one for the e_bar of a 0.5 rad/s
   speed noise (7.2) (`bench.workflows.synth.speed_controller`; verification failures raise);
5. **closed loop**: the new controllers and the relay-tuned Ziegler-Nichols PI on scenario fig6.14
   (`bench.workflows.reproductions.lpv_speed.figure`);
6. **report**: ``report.json`` and ``report.md`` with every number and the stage timings, and the PNGs.

``quick=True`` runs a small version (4000 samples per set, 300 LM evaluations, one spread, one i_mR) for tests.
Everything lands in ``out_dir``.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import time
from pathlib import Path
from typing import Any

from bench.errors import BadInput
from bench.core.progress import Say
from bench.workflows.sweep import table
from bench.workflows.synth import speed_controller
from bench.workflows.sweep.engine import run_sweep
from bench.workflows.sweep.spec import parse
from bench.workflows.narx import collect_sets
from bench.workflows.reproductions import lpv_speed as rep

RMS_TOLERANCE = 0.02  # candidates within 2 % of the best validation rms error are equally good predictors
SPREADS = (1.0, 0.3, 0.1)


def _candidates(folder: Path, logs: tuple[Path, Path], spreads: tuple[float, ...], max_nfev: int,
                workers: int | None, scheduler: str | None, progress: bool) -> list[dict[str, Any]]:  # fmt: skip
    """Train and transform the candidates as ``narx_candidate`` sweep tasks; one dict per spread, in order."""

    spec = parse({"sweep": {"name": "narx-candidates", "task": "narx_candidate",
                            "description": "NARX candidates of the systematic chain (6.4.2)"},
                  "task": {"train_log": str(logs[0]), "val_log": str(logs[1]), "max_nfev": max_nfev},
                  "design": {"axes": {"task.init_spread": [float(x) for x in spreads]}}})  # fmt: skip
    res = run_sweep(spec, folder, workers=None if scheduler else workers, scheduler=scheduler, progress=progress)
    rows = sorted(table.read(Path(res["results"])), key=lambda r: r["index"])
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise RuntimeError(f"training candidate init spread {bad[0]['task.init_spread']:g} failed: {bad[0]['error']}")
    return [{"spread": r["task.init_spread"], "model": r["out.model"], "report": r["out.report"],
             "rms_val": r["out.rms_val"], "rms_train": r["out.rms_train"], "arx_rms_val": r["out.arx_rms_val"],
             "figures": json.loads(r["out.figures"]), "lm_wall_s": r["out.lm_wall_s"], "gamma_a": r["out.gamma_a"],
             "gamma_lti": r["out.gamma_lti"], "widths": [float(w) for w in r["out.widths"].split(",")],
             "task_wall_s": r["case_wall_time"]} for r in rows]  # fmt: skip


def _check_settings(samples: int, seeds: tuple[int, int], spreads: tuple[float, ...]) -> None:
    """The chain's settings that cannot make a model: one `BadInput` naming the one."""
    if not 500 <= samples <= 1_000_000:
        raise BadInput("--samples", f"must be in [500, 1000000], got {samples}")
    if seeds[0] == seeds[1]:
        raise BadInput("--seed", "training and validation sets need different seeds (6.4.2)")
    if not spreads or any(not 0 < s <= 100 for s in spreads):
        raise BadInput("--spreads", f"initialisation spreads in (0, 100] are needed, got {list(spreads)}")


def _select(cands: list[dict[str, Any]]) -> dict[str, Any]:
    """The candidate with the smallest γ_a among those whose validation rms is within `RMS_TOLERANCE` of the best."""
    best_rms = min(c["rms_val"] for c in cands)
    ok = [c for c in cands if c["rms_val"] <= (1 + RMS_TOLERANCE) * best_rms]
    return min(ok, key=lambda c: c["gamma_a"])


def _syntheses(model: Path, out_dir: Path, rig: str, robust: bool, say: Say, report: dict[str, Any],
               times: dict[str, float]) -> dict[str, dict[str, Any]]:  # fmt: skip
    """The LPV speed controller (6.4.3) and, with ``robust``, the robust one (7.2; a failed robust design is
    reported, not fatal), each verified, into ``report``; returns the closed loop's columns (the FOC's
    parameters of each)."""
    t = time.perf_counter()
    nom = speed_controller(model, out_dir / "speed_controller", rig=rig, progress=lambda m: say(f"   {m}"))
    times["synthesis_nominal"] = time.perf_counter() - t
    report["nominal"] = {k: nom["nominal"][k] for k in ("gamma_a", "gamma", "gamma_lti", "n_c", "thesis", "widths",
                                                        "construction", "verification", "timings")}  # fmt: skip
    columns: dict[str, dict[str, Any]] = {"LPV": {"speed_controller": "lpv",
                                                  "lpv_speed_artifact": str(out_dir / "speed_controller")}}
    if robust:
        say("synthesise and verify the robust LPV speed controller (7.2, e_bar for 0.5 rad/s)")
        t = time.perf_counter()
        try:
            rob = speed_controller(model, out_dir / "speed_controller_robust", rig=rig, robust=True,
                                   progress=lambda m: say(f"   {m}"))  # fmt: skip
            report["robust"] = {k: rob["robust_design"][k] for k in (
                "e_bar", "gamma", "gamma_nominal", "gamma_robust", "gamma_a_nominal", "gamma_a_robust", "eps", "r",
                "rt", "certified_e", "steps", "verification")}  # fmt: skip
            columns["robust LPV"] = {"speed_controller": "lpv", "lpv_speed_artifact": str(out_dir / "speed_controller_robust")}
        except BadInput as e:  # no robust design: reported, not fatal
            report["robust"] = {"error": str(e)}
        times["synthesis_robust"] = time.perf_counter() - t
    return columns


def run_pipeline(out_dir: Path, *, samples: int = 22000, seeds: tuple[int, int] = (1, 2), max_nfev: int = 3000,
                 spreads: tuple[float, ...] = SPREADS, rig: str = "mock", quick: bool = False, robust: bool = True,
                 progress: Say | None = None, workers: int | None = 2,
                 scheduler: str | None = None) -> dict[str, Any]:  # fmt: skip
    """Run the chain (module docstring) into ``out_dir``; returns the report (also written as JSON + markdown).

    The candidates train on the sweep engine: a local Dask cluster of ``workers``, or ``scheduler``.
    """

    say_line = progress or (lambda s: None)
    n_stages = 6 if robust else 5
    stage_no = iter(range(1, n_stages + 1))

    def say(msg: str) -> None:  # "k/n" for a new stage, indented lines for its details
        say_line(msg if msg.startswith(" ") else f"{next(stage_no)}/{n_stages} {msg}")

    if quick:
        samples, max_nfev, spreads = min(samples, 4000), min(max_nfev, 300), spreads[-1:]
    _check_settings(samples, seeds, spreads)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    times: dict[str, float] = {}
    report: dict[str, Any] = {"settings": {"samples": samples, "seeds": list(seeds), "max_nfev": max_nfev,
                                           "spreads": list(spreads), "rig": rig, "quick": quick}}  # fmt: skip

    say(f"collect: training (seed {seeds[0]}) and validation (seed {seeds[1]}) sets, {samples} samples each")
    t = time.perf_counter()
    logs, coll = collect_sets(out_dir / "data", samples=samples, seeds=seeds, rig=rig,
                              progress=lambda m: say(f"   {m}"))  # fmt: skip
    times["collect"] = time.perf_counter() - t
    report["collect"] = coll

    say(f"train and transform: {len(spreads)} candidate(s) (init spreads {', '.join(f'{x:g}' for x in spreads)}, "
        f"{max_nfev} LM evaluations) as sweep tasks, then gamma_a of the Fig. 6.13 set-up for each")
    t = time.perf_counter()
    cands = _candidates(out_dir / "candidates", logs, spreads, max_nfev, workers, scheduler, progress is not None)
    for c in cands:
        say(f"   spread {c['spread']:g}: val rms {c['rms_val']:.4f} rad/s, widths "
            f"{', '.join(f'{w:.2g}' for w in c['widths'][:2])}, gamma_a {c['gamma_a']:.4g}")  # fmt: skip
    times["train"] = time.perf_counter() - t
    t = time.perf_counter()
    chosen = _select(cands)
    times["select"] = time.perf_counter() - t
    report["candidates"] = cands
    report["selected"] = {"spread": chosen["spread"], "model": chosen["model"],
                          "rule": f"smallest gamma_a among validation rms <= {1 + RMS_TOLERANCE:g} x best"}  # fmt: skip
    say(f"   selected: init spread {chosen['spread']:g}")

    say("synthesise and verify the LPV speed controller (6.4.3)")
    columns = _syntheses(Path(chosen["model"]), out_dir, rig, robust, say, report, times)

    say("closed loop on the rig: scenario fig6.14, LPV vs relay-tuned Ziegler-Nichols PI")
    t = time.perf_counter()
    zn = rep.zn_pi(1)
    columns["PI (ZN), 3 kHz"] = zn["params"]
    imrs = (2.2,) if quick else rep.I_MR_REFS
    cl = rep.figure(out_dir, "closed-loop", "LPV speed controller(s) and the ZN PI on scenario fig6.14 (dotted: reference)",
                    columns, imrs)  # fmt: skip
    times["closed_loop"] = time.perf_counter() - t
    report["closed_loop"] = {"scenario": cl["scenario"], "relay": zn["relay"],
                             "runs": {c: v["runs"] for c, v in cl["columns"].items()}}  # fmt: skip

    say("report")
    report["figures"] = {"closed-loop": str(out_dir / "closed-loop.png")}
    for name, src in chosen["figures"].items():  # the chosen candidate's NARX figures beside it
        dst = out_dir / f"{'narx-' if name in ('sectors', 'lm') else ''}{name}.png"
        shutil.copyfile(src, dst)
        report["figures"][name] = str(dst)
    times["total"] = time.perf_counter() - t_all
    report["timings_s"] = times
    report["machine"] = {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg": os.getloadavg()}
    (out_dir / "report.json").write_text(json.dumps(report, indent=2, default=float))
    (out_dir / "report.md").write_text(markdown(report))
    return report


def markdown(r: dict[str, Any]) -> str:
    """A short human-readable report of `run_pipeline`'s numbers."""
    s = r["settings"]
    lines = ["# NARX -> quasi-LPV -> LPV speed controller (bench pipeline narx-speed)", "",
             f"{s['samples']} samples per set, seeds {s['seeds']}, {s['max_nfev']} LM evaluations, rig {s['rig']}"
             f"{' (quick)' if s['quick'] else ''}.", "", "## Candidate models (6.4.2) and selection", "",
             "| init spread | MLP rms train / val [rad/s] | ARX rms val | widest sector widths | gamma_a | LTI bound |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for c in r["candidates"]:
        lines.append(f"| {c['spread']:g} | {c['rms_train']:.4f} / {c['rms_val']:.4f} | {c['arx_rms_val']:.4f} | "
                     f"{', '.join(f'{w:.2g}' for w in c['widths'][:2])} | {c['gamma_a']:.4g} | {c['gamma_lti']:.4g} |")  # fmt: skip
    lines += ["", f"Selected: spread {r['selected']['spread']:g} ({r['selected']['rule']}).", "",
              "## LPV speed controller (6.4.3)", ""]  # fmt: skip
    n = r["nominal"]
    lines.append(f"gamma_a = {n['gamma_a']:.4g} (thesis < 0.016), constructed gamma = {n['gamma']:.4g} (thesis 0.018, "
                 f"backoff {n['construction']['backoff']:g}), ignoring the residual gains {n['gamma_lti']:.4g} (thesis "
                 f"0.011); order {n['n_c']}; verification {'passed' if n['verification']['passed'] else 'FAILED'}.")  # fmt: skip
    if "robust" in r:
        rb = r["robust"]
        lines += ["", "## Robust LPV speed controller (7.2)", ""]
        if "error" in rb:
            lines.append(f"No robust design: {rb['error']}")
        else:
            lines.append(f"e_bar = {', '.join(f'{e:.3%}' for e in rb['e_bar'])} (0.5 rad/s, 6.3.3); gamma "
                         f"{rb['gamma_nominal']:.4g} -> {rb['gamma_robust']:.4g} (thesis 0.018 -> 0.034); eps = "
                         f"{', '.join(f'{e:.3g}' for e in rb['eps'])}; r = {', '.join(f'{e:.3g}' for e in rb['r'])}; "
                         f"r~ = {', '.join(f'{e:.3g}' for e in rb['rt'])}; verification "
                         f"{'passed' if rb['verification']['passed'] else 'FAILED'}.")  # fmt: skip
    lines += ["", "## Closed loop (scenario fig6.14, true speed)", "",
              "| controller | i_mR,ref [A] | rms small steps [rad/s] | mean abs steady-state error [rad/s] | "
              "final step settles (10 rad/s) [s] | tripped |", "|---|---|---|---|---|---|"]  # fmt: skip
    for c, runs in r["closed_loop"]["runs"].items():
        for imr, v in runs.items():
            settle = v["big_step_settle_10rad_s_s"]
            settle = "did not settle" if settle is None or settle != settle else f"{settle:.3f}"  # NaN: never within 10 rad/s
            lines.append(f"| {c} | {imr} | {v['rms_small_steps_rad_s']:.2f} | {v['steady_state_abs_mean_rad_s']:.2f} | "
                         f"{settle} | {v['tripped']} |")  # fmt: skip
    lines += ["", "## Wall time [s]", "", "| stage | s |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in r["timings_s"].items()]
    lines += ["", "Figures: " + ", ".join(f"`{Path(v).name}`" for v in r["figures"].values()), ""]
    return "\n".join(lines)
