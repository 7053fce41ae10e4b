"""How far a design moves when its motor model moves a little: the LPV flux observer (5.6.2) or the quasi-LPV
current controller (6.2.2).

Commissioned vs true (`bench.workflows.commission.versus_true`) compares the observer designed for the identified model
with the one designed for the truth. That comparison means something only where the design is a continuous function of
the model. This module measures it: the observer is designed for the rig's ``[motor]`` and again with one parameter
moved by each relative step, and the frozen observers' responses (î_m/ī_s and î_m/ū_s, `observer_response`) are
compared over speeds and frequencies (`change`). With ``--report``
(a `bench commission` report of the same motor) each moved design also runs the commissioning check on the plant
(`versus_true.against_true`, its "true" design being the moved one) and its flux-angle p95 is reported.

    python3 -m bench.workflows.commission.design_spread --rig R [--design current-controller] [--param R_r] [--rel 1e-4
    1e-3]
                                              [--rescale full|diagonal] [--centring balanced|scaled]
                                              [--objective trace|dual] [--report commission.json]
                                              [--kernels SkylakeX Haswell ...]

The current controller (``--design current-controller``, at the rate `bench commission` designs it for) is
compared by its frozen responses at the corners and the centre of its δ box (ω_cc and i_sq/î_mR) at 1, 10 and
100 Hz (`current_responses`; not at 0 Hz, where its integrators' gain is unbounded), and each row also says where
its γ bisection ended (the state scaling T of `synthesis.lmi.bisect_gamma`), at which fraction of the maximal
margin its LMI solution was centred, and the controller's order.

JSON on stdout, a line per design on stderr. Results: docs/results/fleet-commission.md.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bench.workflows.commission.commission import CURRENT_CENTRING, CURRENT_OBJECTIVE, CURRENT_RATE, CURRENT_RESCALE
from bench.workflows.synth import motor_data
from synthesis.artifacts import MOTOR_KEYS, _jsonable
from synthesis.environment import blas_info
from synthesis.models.motor import MotorData
from synthesis.models.flux_observer import observer_response, design_flux_observer
from bench.core.config import load as load_rig
from synthesis.models.current_controller import CurrentSpec, design_current_controller
from bench.workflows.commission.versus_true import against_true

#: the frozen observers are compared at these speeds (relative to the design's ω_r,max), each at 0 Hz, at the
#: speed's own electrical frequency (where the flux turns in steady state, stator coordinates) and at 10 Hz
SPEEDS_REL = (0.05, 0.3, 1.0)


def responses(design: Any) -> np.ndarray:
    """The frozen observer's (î_m/ī_s, î_m/ū_s) at `SPEEDS_REL`, each at 0, ω_r and 2π·10 rad/s: shape
    (3, 3, 2)."""
    out = []
    for s in SPEEDS_REL:
        w_r = s * design.omega_r_max
        out.append(np.stack(observer_response(design, w_r, np.array([0.0, w_r, 2.0 * math.pi * 10.0])), axis=-1))
    return np.array(out)


DESIGNS = ("flux-observer", "current-controller")


def current_responses(design: Any) -> np.ndarray:
    """The frozen current controller's response at δ in {-1, 0, 1}² (normalised) at 1, 10 and 100 Hz: shape
    (27, outputs x inputs), each point's entries on the last axis as `change` takes them."""
    out = []
    for a in (-1.0, 0.0, 1.0):
        for b in (-1.0, 0.0, 1.0):
            S = design.controller.frozen(np.diag([a, b]))
            out += [S.evaluate(np.exp(2j * math.pi * f / design.spec.rate_hz)) for f in (1.0, 10.0, 100.0)]
    return np.array(out).reshape(len(out), -1)


def change(H: np.ndarray, ref: np.ndarray) -> float:
    """The largest change of `responses` ``H`` against ``ref``, at each speed and frequency relative to the larger
    of ``ref``'s two responses there (the observer's gain falls 100-fold from standstill to its top speed)."""
    return float(np.max(np.abs(H - ref).max(axis=-1) / np.abs(ref).max(axis=-1)))


def spread(rig: str, param: str, rels: list[float], report: Path | None = None, work: Path | None = None,
           say: Any = None, design: str = "flux-observer",
           rescale: str = CURRENT_RESCALE, centring: str = CURRENT_CENTRING,
           objective: str = CURRENT_OBJECTIVE, keep_responses: bool = False) -> dict[str, Any]:  # fmt: skip
    """The ``design`` for the rig's ``[motor]`` and for ``param`` × (1 + rel) for each rel (module docstring);
    ``rescale``, ``centring``, ``objective``: the current controller's re-balancing and centring (`bench
    commission`'s by default); ``keep_responses``: each row holds its responses too (``[re, im]`` pairs)."""
    import tempfile

    cfg = load_rig(rig)
    if param not in MOTOR_KEYS:
        raise ValueError(f"--param: one of {', '.join(MOTOR_KEYS)}, not {param!r}")
    if design not in DESIGNS:
        raise ValueError(f"--design: one of {', '.join(DESIGNS)}, not {design!r}")
    base = motor_data(rig)
    rep = json.loads(report.read_text()) if report else None
    out: dict[str, Any] = {"rig": rig, "design": design, "param": param, "designs": []}
    if design == "current-controller":
        out["rescale"], out["centring"], out["objective"] = rescale, centring, objective
    if design == "flux-observer":
        out["speeds_rel"] = SPEEDS_REL
    ref = None
    with tempfile.TemporaryDirectory() as tmp:
        for rel in [0.0, *rels]:
            motor = MotorData(**{k: getattr(base, k) * (1.0 + rel * (k == param)) for k in MOTOR_KEYS})
            if design == "flux-observer":
                d = design_flux_observer(cfg.limits.omega_max, Ts=1.0 / cfg.rate_hz, motor=motor)
                H = responses(d)
            else:
                d = design_current_controller(CurrentSpec(rate_hz=CURRENT_RATE, motor=motor), rescale=rescale,
                                              centring=centring, objective=objective)  # fmt: skip
                H = current_responses(d)
            ref = H if ref is None else ref
            row: dict[str, Any] = {"rel": rel, "gamma": d.gamma, "gamma_a": d.gamma_a,
                                   "response_change_max": change(H, ref)}  # fmt: skip
            if keep_responses:
                row["responses"] = np.stack([H.real, H.imag], axis=-1).tolist()
            if design == "current-controller":  # where the bisection ended: its state scaling, the centring's margin
                row["scaling_T"] = _jsonable(d.bisection.scaling.T)  # complex under the full re-balancing
                row["margin_frac"] = d.order_reduction["margin_frac"]
                row["order"] = d.controller.K.n_c
            if rep is not None:
                truth = cfg.motor.with_(**{param: getattr(cfg.motor, param) * (1.0 + rel)})
                r = against_true(rep, truth, (work or Path(tmp)) / f"rel{rel:g}", centring=centring,
                                 objective=objective)  # fmt: skip
                row["check_flux_angle_p95_deg"] = r["true"]["flux_angle_p95_deg"]
                row["commissioned_flux_angle_p95_deg"] = r["commissioned"]["flux_angle_p95_deg"]
            out["designs"].append(row)
            if say:
                say(f"{param} x (1{rel:+g}): response moved {100 * row['response_change_max']:.3g} %"
                    + (f", check flux-angle p95 {row['check_flux_angle_p95_deg']:.3g} deg" if rep is not None else ""))
    return out


def across_kernels(argv: list[str], kernels: list[str], say: Any = None) -> dict[str, Any]:
    """The same design (this module's command line ``argv``, its model unmoved) in one subprocess per OpenBLAS
    kernel (``OPENBLAS_CORETYPE``, read when the library loads, so not switchable in this process): each
    kernel's design against the first one's (`change`), with the kernel each child really ran (`blas_info`). A
    design whose LMI solution is ill-conditioned follows the rounding of the kernel it ran on: two labs would
    commission the same motor differently (docs/results/fleet-commission.md)."""
    import os
    import subprocess

    rows: list[dict[str, Any]] = []
    ref = None
    for k in kernels:
        cmd = [sys.executable, "-m", __spec__.name, *argv, "--rel", "--responses"]
        p = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OPENBLAS_CORETYPE": k})
        if p.returncode != 0:
            raise ValueError(f"--kernels {k}: the design failed: {p.stderr.strip().splitlines()[-1:]}")
        res = json.loads(p.stdout)
        R = np.array(res["designs"][0].pop("responses"))
        H = R[..., 0] + 1j * R[..., 1]
        ref = H if ref is None else ref
        rows.append({"kernel": k, "blas": res["blas"], "response_change_max": change(H, ref),
                     "in_force": all((b["kernel"] or "").lower() == k.lower() for b in res["blas"]),
                     **{n: res["designs"][0].get(n) for n in ("gamma", "gamma_a", "order", "margin_frac")}})  # fmt: skip
        if say:
            say(f"OPENBLAS_CORETYPE={k} ({', '.join(b['kernel'] or '?' for b in res['blas'])}): response moved "
                f"{100 * rows[-1]['response_change_max']:.3g} % against {kernels[0]}")  # fmt: skip
    return {"argv": argv, "kernels": rows}


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python3 -m bench.workflows.commission.design_spread",

                                 description=__doc__.splitlines()[0])
    ap.add_argument("--rig", required=True, help="rig file whose [motor] the observer is designed for")
    ap.add_argument("--design", default="flux-observer", help="flux-observer (5.6.2) or current-controller (6.2.2)")
    ap.add_argument("--param", default="R_r", help="the [motor] parameter moved (L_s, L_r, L_m, R_s, R_r)")
    ap.add_argument("--rel", type=float, nargs="*", default=[1e-4, 1e-3], help="relative steps of the parameter")
    ap.add_argument("--rescale", default=CURRENT_RESCALE, choices=("full", "diagonal"),
                    help="the current controller's re-balancing (default: as bench commission)")
    ap.add_argument("--centring", default=CURRENT_CENTRING, choices=("balanced", "scaled"),
                    help="where the current controller's LMI solution is centred (default: as bench commission)")
    ap.add_argument("--objective", default=CURRENT_OBJECTIVE, choices=("trace", "dual"),
                    help="what that centring minimises (default: as bench commission)")
    ap.add_argument("--report", type=Path, help="a bench commission report (commission.json) of the same motor: "
                    "also run the check with each moved design (the observer and the current controller, centred "
                    "as --centring and --objective say)")  # fmt: skip
    ap.add_argument("--work", type=Path, help="keep the check runs here (default: a temporary folder)")
    ap.add_argument("--kernels", nargs="+", metavar="CORETYPE", help="the model unmoved, designed once per OpenBLAS "
                    "kernel (e.g. SkylakeX Haswell Sandybridge) in a subprocess each: how far the design follows the "
                    "kernel's rounding")  # fmt: skip
    ap.add_argument("--responses", action="store_true", help=argparse.SUPPRESS)  # each row's responses (--kernels)
    a = ap.parse_args(argv)

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    try:
        if a.kernels:
            keep = ["--rig", a.rig, "--design", a.design, "--rescale", a.rescale, "--centring", a.centring,
                    "--objective", a.objective]  # fmt: skip
            res = across_kernels(keep, a.kernels, say)
        else:
            res = spread(a.rig, a.param, a.rel, a.report, a.work, say=say, design=a.design, rescale=a.rescale,
                         centring=a.centring, objective=a.objective, keep_responses=a.responses)
            res["blas"] = blas_info()
    except (ValueError, OSError) as e:  # a bad rig file, --param, or --report (missing, not JSON)
        print(f"design_spread: {e}", file=sys.stderr)
        return 2
    json.dump(res, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
