"""Coverage of `bench identify`'s 95 % intervals: how often each reported interval holds the hidden truth.

Per motor of `bench.workflows.commission.fleet` (random 0.37-11 kW motors, half saturating, random inverter errors) one
standstill identification (`bench.workflows.commission.identify.identify`, measured voltages unless ``--voltages
reference``, the test's parameters scaled to the motor from its plate, `FleetMotor.standstill_params`;
lockstep, the compiled plant), then each
reported interval against the truth it claims to bracket (`truth_of`):

* ``inverse_gamma``: R_s, L_sigma (L'_s), R_R (R'_r), L_M (L'_m) at the test's bias;
* ``thesis`` (L_s = L_r): L_s (= L_r), L_m, R_r;
* ``sat_point``: L_m, L_M and L_sigma the saturation check reports at its second bias;
* ``R_s_free``: the cross-check fit with R_s free: R_s, L_sigma, R_R, L_M;
* ``rotating`` (``--rotating``: the rotating test after the standstill one, as `bench identify --rotating` runs
  it): L_m_rated, the secant L_m at the flux it is reported at (``psi_rated_Wb``: the plate's rated flux), J,
  B_visc and m_coulomb against the true machine's.

**The truth on a saturating motor** is what the standstill test claims to measure: the parameters at the DC
bias of the multisine, with L_m the *incremental* inductance dψ/di_mu of the true curve at the main flux that
bias sets (at standstill the rotor carries no DC current: i_mu = the bias), as the saturation warning says
("incremental L_m ... at 2 A"); R_s, R_r and the leakages are the machine's (`FleetMotor.truth_at`).

Per quantity: the share of runs whose interval holds the truth (with its 95 % Wilson interval: 100 runs
measure a coverage to about +-5 %), split linear / saturating (mild, strong), and the error in units of the
interval's standard error, z = (estimate - truth) / (half width / t): its mean is the bias and its rms the
spread the interval does not see (both 0 and 1 for an honest interval).

Run ``python3 -m bench.workflows.commission.coverage --motors 100 --out DIR`` (JSON on stdout, progress with an ETA on
stderr). Each run's log stays in DIR/runs/<motor>/ with ``--keep-logs``; ``--from-logs DIR`` fits them again
with the present code and scores them (same data, another analysis: coverage before and after a change).
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from bench.workflows.commission.fleet import FleetMotor, add_fleet_options, draw_fleet, fleet_options_refused
from bench.workflows.commission.identify import _t, identify, analyse_log
from bench.core.progress import Steps
from bench.core.shutdown import COMMAND_SIGNALS, Interrupted, SignalGuard, signal_exit_code
from bench.workflows.commission import rotating_fit
from bench.workflows.commission.rotating import standstill_ci

TARGET = 0.90  # the lowest acceptable coverage of a 95 % interval
ROTATING = ("L_m_rated", "J", "B_visc", "m_coulomb")  # the rotating test's intervals (``--rotating``)
KINDS = {"linear": ("linear",), "saturating": ("mild", "strong"), "mild": ("mild",), "strong": ("strong",),
         "all": ("linear", "mild", "strong")}  # fmt: skip


def intervals(res: dict[str, Any]) -> dict[str, tuple[float, float, float]]:
    """Every interval an identification reports: {"group.name": (value, low, high)} (module docstring)."""
    out: dict[str, tuple[float, float, float]] = {}

    def put(group: str, table: dict[str, Any], names: tuple[str, ...]) -> None:
        for n in names:
            if n in table:
                v = table[n]
                out[f"{group}.{n}"] = (float(v["value"]), float(v["ci95"][0]), float(v["ci95"][1]))

    put("inverse_gamma", res["inverse_gamma"], ("R_s", "L_sigma", "R_R", "L_M"))
    put("thesis", res["thesis_L_s_eq_L_r"], ("L_s", "L_m", "R_r"))
    sat = res.get("saturation")
    if sat:
        second = next(x for x in sat["points"] if x["bias_A"] != sat["test_bias_A"])
        put("sat_point", second, ("L_m", "L_M", "L_sigma"))
    put("R_s_free", res["ac"]["R_s_free_check"], ("R_s", "L_sigma", "R_R", "L_M"))
    rot = res.get("rotating")
    if rot:
        put("rotating", {"L_m_rated": rot["L_m_rated"], **rot["mechanics"]}, ROTATING)
    return out


def truth_of(motor: FleetMotor, res: dict[str, Any]) -> dict[str, float]:
    """The true value each interval of `intervals` claims to bracket (module docstring)."""
    c = res["conditions"]
    at = motor.truth_at(c["ac_bias_A"])
    out = {f"inverse_gamma.{n}": at["inverse_gamma"][n] for n in ("R_s", "L_sigma", "R_R", "L_M")}
    out |= {f"thesis.{n}": at["thesis"][n] for n in ("L_s", "L_m", "R_r")}
    out |= {f"R_s_free.{n}": at["inverse_gamma"][n] for n in ("R_s", "L_sigma", "R_R", "L_M")}
    if c.get("sat_bias_A"):
        sb = motor.truth_at(c["sat_bias_A"])
        out |= {"sat_point.L_m": sb["thesis"]["L_m"], "sat_point.L_M": sb["inverse_gamma"]["L_M"],
                "sat_point.L_sigma": sb["inverse_gamma"]["L_sigma"]}  # fmt: skip
    rot = res.get("rotating")
    if rot:
        sat, t = motor.sat_curve(), motor.true
        psi = rot["L_m_rated"]["psi_rated_Wb"]
        out["rotating.L_m_rated"] = t.L_m if sat is None else sat.L_m_of(psi)
        out |= {f"rotating.{n}": getattr(t, n) for n in ROTATING[1:]}
    return out


def score(motor: FleetMotor, res: dict[str, Any]) -> dict[str, Any]:
    """One identification against the truth: per interval the value, the interval, the truth, inside or not,
    the relative error and half width, and z (the error over the interval's standard error)."""
    truth = truth_of(motor, res)
    rows = {}
    for key, (v, lo, hi) in intervals(res).items():
        x = truth[key]
        half = 0.5 * (hi - lo)
        t95 = 1.959964 if key.startswith("rotating.") else \
            _t(res["dc"]["dof"] if key == "inverse_gamma.R_s" else res["ac"]["dof"])  # (rotating: normal)
        rows[key] = {"value": v, "ci95": [lo, hi], "truth": x, "inside": bool(lo <= x <= hi),
                     "error_rel": v / x - 1.0, "half_rel": half / abs(x),
                     "z": (v - x) / (half / t95) if half > 0 else math.copysign(math.inf, v - x)}  # fmt: skip
    return {"motor": motor.label, "kind": motor.kind, "P_rated": motor.nameplate.P_rated, "intervals": rows,
            "refused": res.get("refused") or [], "warnings": res.get("warnings") or [],
            "residual_rms_rel": res["ac"]["residual_rms_rel"],
            "bias_dependent": bool((res.get("saturation") or {}).get("bias_dependent"))}  # fmt: skip


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial share k/n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1.0 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Coverage per quantity and motor class (`KINDS`), with the Wilson interval, mean and rms of z and the
    median relative half width."""
    import numpy as np

    keys = sorted({k for r in rows for k in r["intervals"]})
    out: dict[str, Any] = {}
    for cls, kinds in KINDS.items():
        sel = [r for r in rows if r["kind"] in kinds]
        per: dict[str, Any] = {}
        for key in keys:
            xs = [r["intervals"][key] for r in sel if key in r["intervals"]]
            if not xs:
                continue
            k = sum(x["inside"] for x in xs)
            z = np.array([x["z"] for x in xs], dtype=float)
            z = z[np.isfinite(z)]
            per[key] = {"n": len(xs), "covered": k, "coverage": k / len(xs), "wilson95": wilson(k, len(xs)),
                        "z_mean": float(z.mean()) if z.size else math.nan,
                        "z_rms": float(np.sqrt(np.mean(z**2))) if z.size else math.nan,
                        "half_rel_median": float(np.median([x["half_rel"] for x in xs])),
                        "abs_error_rel_median": float(np.median([abs(x["error_rel"]) for x in xs])),
                        "pass": k / len(xs) >= TARGET}  # fmt: skip
        out[cls] = {"motors": len(sel), "quantities": per}
    return out


def run(n_motors: int, *, seed: int = 0, noise_seed: int = 0, out: Path, keep_logs: bool = False,
        engine: str = "auto", voltages: str = "measured", rotating: bool = False) -> dict[str, Any]:  # fmt: skip
    """The study (module docstring): motors 0..n-1 of fleet ``seed``, noise seed ``noise_seed`` + k for motor k,
    ``voltages`` as `bench identify --voltages`, ``rotating``: the rotating test after it. A motor whose row is
    already in ``out``/rows.jsonl is not run again (an interrupted study goes on)."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    motors = draw_fleet(n_motors, seed)
    rows_path = out / "rows.jsonl"
    done = {}
    if rows_path.exists():
        for line in rows_path.read_text().splitlines():
            r = json.loads(line)
            done[r["motor"]] = r
    t0 = time.perf_counter()
    rigs = out / "rigs"
    rigs.mkdir(exist_ok=True)
    with Steps(n_motors, "identifications", tty=None) as step:
        for k, m in enumerate(motors):
            if m.label in done:
                step(k + 1)
                continue
            import tomlkit

            rig = rigs / f"{m.label}.toml"
            rig.write_text(tomlkit.dumps(m.rig_doc(engine)), encoding="utf-8")
            folder = out / "runs" / m.label
            if folder.exists():
                shutil.rmtree(folder)
            t1 = time.perf_counter()
            res = identify(str(rig), voltages=voltages, params=m.standstill_params(voltages), seed=noise_seed + k,
                           out_dir=folder, rotating=rotating)  # fmt: skip
            wall = time.perf_counter() - t1
            if "tripped" in res:
                if res["exit_code"] > 128:
                    raise Interrupted(res["exit_code"] - 128)
                row: dict[str, Any] = {"motor": m.label, "kind": m.kind, "tripped": res["tripped"]}
            else:
                row = score(m, res)
                row["log"] = res["log"]
                row["log_rotating"] = (res.get("rotating") or {}).get("log")
                if not keep_logs:
                    for key in ("log", "log_rotating"):
                        if row[key]:
                            Path(row[key]).unlink()
                        row[key] = None
            row |= {"seed": noise_seed + k, "wall_s": wall}
            with rows_path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            done[m.label] = row
            step(k + 1)
    rows = [done[m.label] for m in motors]
    return result(rows, {"motors": n_motors, "fleet_seed": seed, "noise_seed": noise_seed, "engine": engine,
                         "voltages": voltages, "rotating": rotating, "wall_s": time.perf_counter() - t0})  # fmt: skip


def from_logs(out: Path, n_motors: int, seed: int = 0) -> dict[str, Any]:
    """Score the kept logs in ``out`` again, fitted by the present code (`analyse_log`)."""

    out = Path(out)
    old = {}
    for line in (out / "rows.jsonl").read_text().splitlines():
        r = json.loads(line)
        old[r["motor"]] = r
    motors = draw_fleet(n_motors, seed)
    rows = []
    with Steps(n_motors, "fits", tty=None) as step:
        for k, m in enumerate(motors):
            r = old.get(m.label)
            if r is None or not r.get("log"):
                raise FileNotFoundError(f"no kept log of {m.label} in {out} (run the study with --keep-logs)")
            res = analyse_log(Path(r["log"]))  # the run's own voltages and plan
            if r.get("log_rotating"):
                res["rotating"] = rotating_fit.analyse_log(Path(r["log_rotating"]), model_ci=standstill_ci(res))
            rows.append(score(m, res) | {"seed": r["seed"], "log": r["log"], "log_rotating": r.get("log_rotating")})
            step(k + 1)
    return result(rows, {"motors": n_motors, "fleet_seed": seed, "from_logs": str(out),
                         "rotating": any(r.get("log_rotating") for r in rows)})  # fmt: skip


def result(rows: list[dict[str, Any]], config: dict[str, Any]) -> dict[str, Any]:
    ok = [r for r in rows if "intervals" in r]
    return {"study": "coverage of bench identify's 95 % intervals (standstill"
                     + (", then rotating" if config.get("rotating") else "") + ") on fleet motors",
            "config": config, "tripped": [r["motor"] for r in rows if "tripped" in r],
            "refused": [r["motor"] for r in ok if r["refused"]], "summary": summarise(ok), "rows": rows}  # fmt: skip


def table(res: dict[str, Any], classes: tuple[str, ...] = ("linear", "mild", "strong", "all")) -> str:
    """The coverage per quantity and class as a markdown table (bold: below `TARGET`)."""
    s = res["summary"]
    keys = list(s["all"]["quantities"])
    head = "| interval | " + " | ".join(f"{c} ({s[c]['motors']})" for c in classes) + " |"
    lines = [head, "|---" * (1 + len(classes)) + "|"]
    for key in keys:
        cells = []
        for c in classes:
            q = s[c]["quantities"].get(key)
            if q is None:
                cells.append("")
                continue
            txt = f"{100 * q['coverage']:.0f} %"
            cells.append(txt if q["pass"] else f"**{txt}**")
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python3 -m bench.workflows.commission.coverage",

                                 description=__doc__.splitlines()[0])
    add_fleet_options(ap, "fleet motors", 100)
    ap.add_argument("--noise-seed", type=int, default=0, help="run seed of motor 0; motor k gets this + k")
    ap.add_argument("--out", type=Path, help="folder for the rigs, the runs and rows.jsonl")
    ap.add_argument("--voltages", choices=("measured", "reference"), default="measured",
                    help="as bench identify --voltages (default measured)")
    ap.add_argument("--rotating", action="store_true", help="the rotating test after the standstill one (its "
                    "intervals too: L_m at the rated flux, J, friction)")
    ap.add_argument("--keep-logs", action="store_true", help="keep each run's MCAP log (for --from-logs)")
    ap.add_argument("--from-logs", type=Path, help="score the kept logs of a study in this folder, fitted again")
    ap.add_argument("--markdown", action="store_true", help="print the coverage table (markdown) on stderr too")
    a = ap.parse_args(argv)
    if fleet_options_refused(a, 10000):
        return 2
    if a.from_logs is None and a.out is None:
        print("bench: error: --out is required (or --from-logs DIR)", file=sys.stderr)
        return 2

    try:
        with SignalGuard(COMMAND_SIGNALS):
            if a.from_logs is not None:
                res = from_logs(a.from_logs, a.motors, a.seed)
            else:
                res = run(a.motors, seed=a.seed, noise_seed=a.noise_seed, out=a.out, keep_logs=a.keep_logs,
                          voltages=a.voltages, rotating=a.rotating)  # fmt: skip
    except Interrupted as exc:  # the motors done so far stay in rows.jsonl: the same command goes on from there
        print(f"bench: {exc}", file=sys.stderr)
        return signal_exit_code(exc.signum)
    dest = (a.from_logs or a.out) / ("coverage-refit.json" if a.from_logs else "coverage.json")
    dest.write_text(json.dumps(res, indent=1))
    if a.markdown:
        print(table(res), file=sys.stderr)
    print(json.dumps({k: v for k, v in res.items() if k != "rows"} | {"json": str(dest)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
