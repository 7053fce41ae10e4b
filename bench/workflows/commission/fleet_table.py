"""The fleet's commissioning table: `bench commission` on random motors from 0.37 to 11 kW, judged as a real rig.

For each motor of `bench.workflows.commission.fleet` (half of them saturating, each behind its own inverter errors; the
rig file has the plate and the user's guess from it in ``[motor]``), three `bench commission` commands, each a real
subprocess on its own copy of the rig file, judged by what a real rig measures (``--judge rig``, the default: the
mock's truth withheld):

1. **commission** - ``bench commission --rig R --out O`` with every default: the standstill and rotating tests,
   the two designs, the closed-loop check; GO expected, in at most `MAX_WALL` s. On GO, the same designs made
   for the true parameters and both pairs through the same check (`versus_true.against_true`): the flux-angle
   p95 and the speed tracking (RMS) over Fig. 5.7's part against the plant's truth, commissioned / true; within
   `MAX_RATIO` expected.
2. **L_m −30 %** - the rig file's ``[motor]`` the true machine told an L_m 30 % low (the leakage kept:
   L_s = L_r = 0.7 L_m + L_ls), ``bench commission --skip-identify``: NO-GO by the criteria without a truth
   (`bench.workflows.commission.judge.NAMES`) expected.
3. **R_r +30 %** - the same with R_r told 30 % high.

A told rig file the plate's own check refuses when it is read (`bench.core.nameplate.check`: the wrong circuit draws
another current or power factor at the rated point than the plate says; one line, exit 2, before anything runs) is
recorded as refused, and the same command runs once more on the file with the plate's optional ``cos_phi`` left
out, so that the check's criteria judge the model as well (``without_cos_phi``).

Run ``python3 -m bench.workflows.commission.fleet_table --motors 20 --out DIR``: JSON on stdout (``--markdown``: the
table on stderr too), one line per command with an ETA on stderr. Each motor's row goes into DIR/rows.jsonl as it
finishes; the same command goes on from there (done motors are not run again). The reports stay in DIR/<motor>/.
Results: docs/results/fleet-commission.md.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import tomlkit

from bench.workflows.commission.fleet import FleetMotor, add_fleet_options, draw_fleet, fleet_options_refused
from bench.workflows.commission.judge import NAMES
from bench.core.shutdown import Interrupted, COMMAND_SIGNALS, SignalGuard, signal_exit_code
from bench.workflows.commission.versus_true import against_true
from bench.core.progress import VERIFIED, summarised_warnings
from synthesis.environment import blas_info, environment

MAX_WALL = 300.0  # [s] a commissioning's wall time, at most
MAX_RATIO = 1.2  # commissioned / true designs' flux-angle p95 and speed tracking, at most
TOLD = {"L_m": 0.7, "R_r": 1.3}  # the wrong [motor]: L_m -30 % (the leakage kept), R_r +30 %
MOTOR_NAMES = ("L_s", "L_r", "L_m", "R_s", "R_r", "J")
SEED = 0  # bench commission's default --seed: the noise of every run, the true designs' check too


def told_motor(true: Any, wrong: str | None) -> dict[str, float]:
    """``[motor]`` values: the true machine (`bench.params.MotorParams`), with ``wrong`` ("L_m" or "R_r", `TOLD`)
    told wrong, or as it is (None)."""
    m = {n: float(getattr(true, n)) for n in MOTOR_NAMES}
    if wrong == "L_m":
        L_m = TOLD["L_m"] * true.L_m
        m.update(L_m=L_m, L_s=L_m + true.L_s - true.L_m, L_r=L_m + true.L_r - true.L_m)
    elif wrong == "R_r":
        m["R_r"] = TOLD["R_r"] * true.R_r
    elif wrong is not None:
        raise ValueError(f"wrong must be one of {', '.join(TOLD)} or None, got {wrong!r}")
    return m


def rig_text(motor: FleetMotor, wrong: str | None = None, cos_phi: bool = True) -> str:
    """The motor's rig file (`FleetMotor.rig_doc`), with ``wrong``: ``[motor]`` the truth told wrong
    (`told_motor`); ``cos_phi`` False leaves the plate's power factor out."""
    doc = motor.rig_doc()
    if wrong is not None:
        doc["motor"] = {**told_motor(motor.true, wrong), "Z_p": motor.true.Z_p}
    if not cos_phi:
        del doc["nameplate"]["cos_phi"]
    return tomlkit.dumps(doc)


def bench_commission(rig: Path, out: Path, *options: str) -> dict[str, Any]:
    """``python3 -m bench commission --rig RIG --out OUT OPTIONS`` as a subprocess: its exit code, wall time,
    verdict and, where it ran, the no-truth criteria, the truth (reported, not judged) and the identified motor from
    commission.json; the error line where it refused (exit 2). A signal that ended it ends this too
    (`bench.core.shutdown.Interrupted`)."""

    cmd = [sys.executable, "-m", "bench", "commission", "--rig", str(rig), "--out", str(out), *options]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _, err = proc.communicate()
    except Interrupted as exc:  # passed on: the command's own shutdown path ends it
        proc.send_signal(exc.signum)
        proc.communicate()
        raise
    wall = time.perf_counter() - t0
    if proc.returncode > 128:
        raise Interrupted(proc.returncode - 128)
    row: dict[str, Any] = {"command": " ".join(["bench", *cmd[3:]]), "exit_code": proc.returncode,
                           "wall_time_s": wall}  # fmt: skip
    rep_path = out / "commission.json"
    if proc.returncode == 2 or not rep_path.exists():  # refused before anything ran (a report there is not its own)
        lines = err.strip().splitlines()
        return row | {"verdict": "refused", "go": False, "error": lines[-1] if lines else ""}
    rep = json.loads(rep_path.read_text())
    row |= {"verdict": rep["verdict"], "go": bool(rep["go"]), "report": str(out / "report.md"),
            "warnings": rep.get("warnings") or []}  # fmt: skip
    cl = rep["stages"].get("closed loop")
    if cl is not None:
        row["criteria"] = {k: {n: c[n] for n in ("value", "limit", "pass", "why") if n in c}
                           for k, c in cl["criteria"].items()}  # fmt: skip
        row["no_truth_failed"] = [k for k in NAMES if k in cl["criteria"] and not cl["criteria"][k]["pass"]]
        row["truth"] = cl.get("truth")
        row["check"] = {k: cl.get(k) for k in ("rated_speed", "low_speed", "load_step", "i_mR_ref")}
    ident = rep["stages"].get("identify", {}).get("motor")
    if ident:
        row["identified"] = {n: ident[n]["value"] for n in ident}
        row["identified_ci_rel"] = {n: (ident[n]["ci95"][1] - ident[n]["ci95"][0]) / 2.0 / abs(ident[n]["value"])
                                    if ident[n]["value"] else None for n in ident}  # fmt: skip
        # (None where the value is 0: a friction coefficient held at its bound)
    row["_rep"] = rep
    return row


def told_case(motor: FleetMotor, wrong: str, work: Path) -> dict[str, Any]:
    """`bench commission --skip-identify` on the rig file with ``[motor]`` told ``wrong``; if the plate's check
    refuses that file, also on it without the plate's cos_phi (module docstring)."""
    rig = work / f"told-{wrong}.toml"
    rig.write_text(rig_text(motor, wrong), encoding="utf-8")
    row = bench_commission(rig, work / f"told-{wrong}", "--skip-identify")
    row.pop("_rep", None)
    if row["exit_code"] == 2:
        rig2 = work / f"told-{wrong}-no-cos-phi.toml"
        rig2.write_text(rig_text(motor, wrong, cos_phi=False), encoding="utf-8")
        again = bench_commission(rig2, work / f"told-{wrong}-no-cos-phi", "--skip-identify")
        again.pop("_rep", None)
        row["without_cos_phi"] = again
    return row


def one_motor(motor: FleetMotor, work: Path) -> dict[str, Any]:
    """The three commands of the module docstring on one motor, and the designs for the true parameters."""

    work.mkdir(parents=True, exist_ok=True)
    p = motor.nameplate
    row: dict[str, Any] = {"motor": motor.label, "kind": motor.kind, "P_rated": p.P_rated, "I_rated": p.I_rated,
                           "n_rated": p.n_rated, "psi_rated_Wb": motor.psi_rated,
                           "saturation": motor.saturation}  # fmt: skip
    rig = work / "rig.toml"
    rig.write_text(rig_text(motor), encoding="utf-8")
    c = bench_commission(rig, work / "commission")
    rep = c.pop("_rep", None)
    if "identified" in c:
        t = motor.true
        c["identified_error"] = {n: c["identified"][n] / getattr(t, n) - 1.0 for n in MOTOR_NAMES
                                 if n in c["identified"]}  # fmt: skip
    row["commission"] = c
    if rep is not None and "closed loop" in rep["stages"] and "flux observer" in rep["stages"]:
        with summarised_warnings(f"{motor.label}: the true designs", checked=VERIFIED):
            row["versus_true"] = against_true(rep, motor.true, work / "versus-true", SEED)
    row["told"] = {w: told_case(motor, w, work) for w in TOLD}
    row |= expectations(row)
    return row


def expectations(row: dict[str, Any]) -> dict[str, Any]:
    """What the table asks of a motor's row: GO (exit 0: the check passed and the identified [motor] written), the
    check passed, within `MAX_RATIO` of the true designs, `MAX_WALL`, and NO-GO by a no-truth criterion for each told
    model (or refused by the plate, and NO-GO without its cos_phi). None where the commissioning stopped before the
    check (nothing to compare)."""
    c = row["commission"]
    ratio = (row.get("versus_true") or {}).get("ratio")
    told = {}
    for w, t in row["told"].items():
        judged = t.get("without_cos_phi", t)
        told[w] = {"refused_by_plate": t["exit_code"] == 2,
                   "no_go_no_truth": judged["exit_code"] == 1 and bool(judged.get("no_truth_failed"))}  # fmt: skip
    check = (c.get("criteria") or {}).values()
    go = c["exit_code"] == 0 and c["verdict"].startswith("GO") and "provisional" not in c["verdict"]
    return {"expect": {"go": go, "check_passed": all(x["pass"] for x in check) if check else None,
                       "flux_angle_p95_within": ratio["flux_angle_p95_deg"] <= MAX_RATIO if ratio else None,
                       "speed_tracking_within": ratio["speed_tracking_rms"] <= MAX_RATIO if ratio else None,
                       "wall_time_within": c["wall_time_s"] <= MAX_WALL, "told": told}}  # fmt: skip


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Which motors miss each expectation (`expectations`; ``no_check``: those that stopped before the check), the
    worst ratios and the wall times."""

    def failing(key: str) -> list[str]:
        return [r["motor"] for r in rows if r["expect"][key] is False]

    def ratios(k: str) -> list[float]:
        return [r["versus_true"]["ratio"][k] for r in rows if "versus_true" in r]

    walls = sorted(r["commission"]["wall_time_s"] for r in rows)
    out: dict[str, Any] = {"motors": len(rows), "not_go": failing("go"),
                           "no_check": [r["motor"] for r in rows if r["expect"]["check_passed"] is None],
                           "check_failed": failing("check_passed"),
                           "flux_angle_p95_beyond": failing("flux_angle_p95_within"),
                           "speed_tracking_beyond": failing("speed_tracking_within"),
                           "wall_time_beyond": failing("wall_time_within")}  # fmt: skip
    for w in TOLD:
        out[f"told_{w}_not_caught"] = [r["motor"] for r in rows if not r["expect"]["told"][w]["no_go_no_truth"]]
        out[f"told_{w}_refused_by_plate"] = [r["motor"] for r in rows if r["expect"]["told"][w]["refused_by_plate"]]
    out["worst_ratio"] = {k: max(ratios(k), default=math.nan) for k in ("flux_angle_p95_deg", "speed_tracking_rms")}
    out["wall_time_s"] = {"max": walls[-1], "median": walls[len(walls) // 2]} if walls else {}
    out["all_met"] = not any(v for k, v in out.items() if isinstance(v, list) and not k.endswith("refused_by_plate"))
    return out


def _worst(t: dict[str, Any]) -> str:
    """A told case in one cell: its verdict and the criterion without a truth nearest to or furthest beyond its
    limit (value / limit)."""
    judged = t.get("without_cos_phi", t)
    pre = "plate refused; without cos φ: " if "without_cos_phi" in t else ""
    if judged["exit_code"] == 2:
        return f"{pre}refused: {judged.get('error', '')[:80]}"
    verdict = "**NO-GO**" if judged["exit_code"] == 1 else f"**{judged['verdict'].split(' (')[0]}**"
    crit = {k: c for k, c in (judged.get("criteria") or {}).items() if k in NAMES}
    if not crit:
        return f"{pre}{verdict}"
    x, k, c = max((c["value"] / c["limit"], k, c) for k, c in crit.items())
    unsteady = [(k, c) for k, c in crit.items() if c.get("why")]  # failed as not steady (judge.UNSTEADY)
    if unsteady:
        k, c = unsteady[0]
    name = k.split(":")[0].removesuffix(" vs the DC load")
    if unsteady:
        return f"{pre}{verdict}: {name} not steady ({c['value']:.3g} / {c['limit']:.3g})"
    return f"{pre}{verdict}: {name} {c['value']:.3g} / {c['limit']:.3g} ({x:.1f}×)"


def markdown(rows: list[dict[str, Any]]) -> str:
    """The table of docs/results/fleet-commission.md."""
    lines = ["| motor | kW | kind | verdict | wall [s] | L_m err | R_r err | flux angle p95 [°] comm. / true | "
             "speed tracking RMS [rad/s] comm. / true | told L_m −30 % | told R_r +30 % |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        c = r["commission"]
        err = c.get("identified_error", {})
        e = lambda n: f"{100 * err[n]:+.2f} %" if n in err else ""  # noqa: E731
        vt = r.get("versus_true")
        if vt:
            fa = (f"{vt['commissioned']['flux_angle_p95_deg']:.3g} / {vt['true']['flux_angle_p95_deg']:.3g} "
                  f"({vt['ratio']['flux_angle_p95_deg']:.2f})")  # fmt: skip
            st = (f"{vt['commissioned']['speed_tracking_rms']:.3g} / {vt['true']['speed_tracking_rms']:.3g} "
                  f"({vt['ratio']['speed_tracking_rms']:.2f})")  # fmt: skip
        else:
            fa = st = ""
        verdict = c["verdict"] if c["exit_code"] == 0 else f"**{c['verdict'].split(':')[0]}**"
        lines.append(f"| {r['motor']} | {r['P_rated'] / 1e3:g} | {r['kind']} | {verdict} | {c['wall_time_s']:.0f} | "
                     f"{e('L_m')} | {e('R_r')} | {fa} | {st} | {_worst(r['told']['L_m'])} | "
                     f"{_worst(r['told']['R_r'])} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def run(n_motors: int, out: Path, *, seed: int = 0, only: list[str] | None = None,
        say: Any = None) -> dict[str, Any]:  # fmt: skip
    """The table over motors 0..n-1 of fleet ``seed`` (``only``: these labels of them); rows already in
    ``out``/rows.jsonl are kept (module docstring)."""
    say = say or (lambda s: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    motors = draw_fleet(n_motors, seed)
    if only:
        unknown = sorted(set(only) - {m.label for m in motors})
        if unknown:
            raise ValueError(f"--only: {', '.join(unknown)} not among the {n_motors} motors")
        motors = [m for m in motors if m.label in only]
    rows_path = out / "rows.jsonl"
    done: dict[str, dict[str, Any]] = {}
    if rows_path.exists():
        for line in rows_path.read_text().splitlines():
            r = json.loads(line)
            done[r["motor"]] = r
    todo = [m for m in motors if m.label not in done]
    t0 = time.perf_counter()
    for i, m in enumerate(todo):
        eta = (time.perf_counter() - t0) / i * (len(todo) - i) if i else math.nan
        say(f"motor {m.label} ({m.nameplate.P_rated / 1e3:g} kW, {m.kind}): {len(done) + 1}/{len(motors)}"
            + (f", ETA {eta / 60:.0f} min" if i else ""))  # fmt: skip
        if (out / m.label).exists():  # left by an interrupted run (its row is not in rows.jsonl): start it afresh
            shutil.rmtree(out / m.label)
        row = one_motor(m, out / m.label)
        # the commands inherit this process's BLAS kernel; the current controller's design follows it
        # (docs/results/fleet-commission.md), so each row says which it ran under (a resumed run may mix them)
        row["blas"] = blas_info()
        e = row["expect"]
        say(f"  {m.label}: {row['commission']['verdict'][:60]} in {row['commission']['wall_time_s']:.0f} s; "
            f"told L_m caught {e['told']['L_m']['no_go_no_truth']}, R_r caught {e['told']['R_r']['no_go_no_truth']}")
        with rows_path.open("a") as f:
            f.write(json.dumps(row, default=str) + "\n")
        done[m.label] = row
    rows = [done[m.label] | expectations(done[m.label]) for m in motors]
    return {"table": "bench commission on fleet motors, judged as a real rig", "fleet_seed": seed,
            "motors": [m.label for m in motors], "summary": summary(rows), "rows": rows, "environment": environment(),
            "wall_time_s": time.perf_counter() - t0}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python3 -m bench.workflows.commission.fleet_table",

                                 description=__doc__.splitlines()[0])
    add_fleet_options(ap, "fleet motors 0..N-1")
    ap.add_argument("--only", default=None, help="comma-separated motor labels among them (e.g. m000,m003)")
    ap.add_argument("--out", type=Path, required=True, help="folder for the rig files, the reports and rows.jsonl")
    ap.add_argument("--markdown", action="store_true", help="print the table (markdown) on stderr too")
    a = ap.parse_args(argv)
    if fleet_options_refused(a, 1000):
        return 2
    only = [s.strip() for s in a.only.split(",") if s.strip()] if a.only else None

    def say(s: str) -> None:
        print(s, file=sys.stderr, flush=True)

    try:
        with SignalGuard(COMMAND_SIGNALS):
            res = run(a.motors, a.out, seed=a.seed, only=only, say=say)
    except ValueError as exc:
        print(f"bench: error: {exc}", file=sys.stderr)
        return 2
    except Interrupted as exc:  # the motors done so far stay in rows.jsonl: the same command goes on from there
        print(f"bench: {exc}", file=sys.stderr)
        return signal_exit_code(exc.signum)
    dest = a.out / "fleet-table.json"
    dest.write_text(json.dumps(res, indent=1, default=str))
    if a.markdown:
        print(markdown(res["rows"]), file=sys.stderr)
    print(json.dumps({k: v for k, v in res.items() if k != "rows"} | {"json": str(dest)}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
