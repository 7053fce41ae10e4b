"""The designs over a grid of set-ups and random motors: does every one construct, verify, and how close is it?

The construction (App. B, `synthesis.construct`) must not depend on the BLAS kernel, the release of numpy or
the motor a lab happens to have. This module designs

* the flux observer (5.6.2) for ω_r,max ∈ `FLUX_OMEGAS` × reading {full, thesis} × rate {600, 3000} Hz,
* the current controller (6.2.2) at `CURRENT_RATES`,
* both for random motors: each of R_s, R_r, L_m and the leakage inductance drawn independently within ±40 %
  of (3.57) (L_s = L_r = L_m + L_σ, the thesis' assumption of 3.6),

and reports for each: constructed, verified (the independent checks of `synthesis.verify` on the grid and off
it), γ_a / lower bound (`gap`), γ / γ_a (`backoff`: the rung of the ladder that verified) and the inertia
numbers of the construction. ``python -m synthesis.design_grid [flux|current|motors|all]`` prints JSON lines on
stdout, one per design, with progress on stderr; tests/test_design_grid.py runs a subset by default and the
whole grid as a slow test.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np

from synthesis.environment import environment
from synthesis.models.motor import MotorData
from synthesis.construct import ConstructionError
from synthesis.models.flux_observer import design_flux_observer
from synthesis.verify import VerificationError, verify
from synthesis.models.current_controller import CurrentSpec, design_current_controller

__all__ = ["FLUX_OMEGAS", "FLUX_RATES", "CURRENT_RATES", "random_motors", "flux_case", "current_case", "cases"]

#: ω_r,max [rad/s] of the flux-observer grid (the thesis' 200, the rigs' 400)
FLUX_OMEGAS: tuple[float, ...] = (10.0, 25.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 400.0)
FLUX_RATES: tuple[float, ...] = (600.0, 3000.0)
CURRENT_RATES: tuple[float, ...] = (600.0, 1000.0, 3000.0)
#: the motor parameters' spread of the random motors (each within ±SPREAD of (3.57), independently)
SPREAD: float = 0.4


def random_motors(n: int, seed: int = 0, spread: float = SPREAD) -> list[MotorData]:
    """n motors with R_s, R_r, L_m, L_σ each uniform in (1 ± spread) × (3.57); L_s = L_r = L_m + L_σ (3.6)."""
    base = MotorData()
    l_sigma = base.L_s - base.L_m
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        f = 1.0 + spread * rng.uniform(-1.0, 1.0, 4)
        L_m, L_l = base.L_m * f[2], l_sigma * f[3]
        out.append(MotorData(L_s=L_m + L_l, L_r=L_m + L_l, L_m=L_m, R_s=base.R_s * f[0], R_r=base.R_r * f[1]))
    return out


def _off_grid(n: int) -> list[np.ndarray]:
    """Points between those of `ParameterSet.interval(1).grid(n)` (the verification's grid): the midpoints."""
    g = np.linspace(-1.0, 1.0, n)
    return [np.array([[v]]) for v in 0.5 * (g[1:] + g[:-1])]


def _record(kind: str, setup: dict, t0: float, **kw: Any) -> dict:
    return {"design": kind, **setup, **kw, "wall_time": time.perf_counter() - t0}


def flux_case(omega_r_max: float, variant: str = "full", rate_hz: float = 3000.0, motor: MotorData = MotorData()
              ) -> dict:  # fmt: skip
    """One flux-observer design (5.6.2) with its verification on and off the grid; never raises."""

    setup = dict(omega_r_max=omega_r_max, variant=variant, rate_hz=rate_hz, motor=motor.as_dict())
    t0 = time.perf_counter()
    try:
        d = design_flux_observer(omega_r_max, Ts=1.0 / rate_hz, variant=variant, motor=motor)
    except (ConstructionError, VerificationError, np.linalg.LinAlgError) as e:
        return _record("flux_observer", setup, t0, constructed=isinstance(e, VerificationError), verified=False,
                       error=str(e))  # fmt: skip
    off = verify(d.plant, d.controller, d.gamma, _off_grid(41), raise_on_fail=False, lmi_points=None)
    lb = d.lower_bound.value if d.lower_bound else math.nan
    return _record("flux_observer", setup, t0, constructed=True, verified=bool(d.verification.passed),
                   verified_off_grid=bool(off.passed), gap=d.gamma_a / lb, backoff=d.gamma / d.gamma_a,
                   gamma=d.gamma, gamma_a=d.gamma_a, gamma_lower_bound=lb,
                   max_frozen_hinf_over_gamma=max(d.verification.max_frozen_hinf, off.max_frozen_hinf) / d.gamma,
                   inertia=d.controller.info.get("inertia"))  # fmt: skip


def current_case(rate_hz: float = 600.0, motor: MotorData = MotorData()) -> dict:
    """One current-controller design (6.2.2, the shipped settings) verified on and off its δ grid; never raises."""

    setup = dict(rate_hz=rate_hz, motor=motor.as_dict())
    t0 = time.perf_counter()
    try:
        d = design_current_controller(CurrentSpec(rate_hz=rate_hz, motor=motor))
    except (ConstructionError, VerificationError, np.linalg.LinAlgError) as e:
        return _record("current_controller", setup, t0, constructed=False, verified=False, error=str(e))
    rng = np.random.default_rng(1)  # off the verification's 9 x 9 grid: random points of the normalised δ box
    off_pts = [np.diag(rng.uniform(-1.0, 1.0, 2)) for _ in range(24)]
    off = verify(d.plant, d.controller, d.gamma, off_pts, raise_on_fail=False, lmi_points=None)
    lb = d.lower_bound.value if d.lower_bound else math.nan
    return _record("current_controller", setup, t0, constructed=True, verified=bool(d.verification.passed),
                   verified_off_grid=bool(off.passed), gap=d.gamma_a / lb, backoff=d.gamma / d.gamma_a,
                   gamma=d.gamma, gamma_a=d.gamma_a, gamma_lower_bound=lb, n_c=d.controller.K.n_c,
                   max_frozen_hinf_over_gamma=max(d.verification.max_frozen_hinf, off.max_frozen_hinf) / d.gamma,
                   inertia=d.controller.info.get("inertia"))  # fmt: skip


def cases(which: str, n_motors: int = 20, seed: int = 0) -> Iterator[tuple[str, Any, tuple]]:
    """(label, function, arguments) of every design in the grid ``which`` (flux, current, motors, all)."""
    if which in ("flux", "all"):
        for rate in FLUX_RATES:
            for variant in ("full", "partial"):
                for w in FLUX_OMEGAS:
                    yield f"flux {variant} {w:g} rad/s {rate:g} Hz", flux_case, (w, variant, rate)
    if which in ("current", "all"):
        for rate in CURRENT_RATES:
            yield f"current {rate:g} Hz", current_case, (rate,)
    if which in ("motors", "all"):
        for k, m in enumerate(random_motors(n_motors, seed)):
            yield f"motor {k}: flux 400 rad/s", flux_case, (400.0, "full", 3000.0, m)
            yield f"motor {k}: current 600 Hz", current_case, (600.0, m)


def markdown_table(records: list[dict]) -> str:
    """The records of `main`'s JSON lines as a Markdown table (docs/results/synthesis.md)."""
    rows = ["| design | set-up | motor | constructed / verified / off grid | γ_a / bound | γ / γ_a | max frozen H∞ / γ |",
            "|---|---|---|---|---|---|---|"]  # fmt: skip
    base = MotorData().as_dict()
    for r in records:
        if "design" not in r:
            continue
        setup = (f"{r['omega_r_max']:g} rad/s, {'thesis' if r['variant'] == 'partial' else 'full'}, {r['rate_hz']:g} Hz"
                 if r["design"] == "flux_observer" else f"{r['rate_hz']:g} Hz")  # fmt: skip
        m = r["motor"]
        motor = "(3.57)" if m == base else ", ".join(f"{k} {m[k] / base[k]:.2f}" for k in ("R_s", "R_r", "L_m"))
        if m != base:
            motor += f", L_σ {(m['L_s'] - m['L_m']) / (base['L_s'] - base['L_m']):.2f}"
        ok = " / ".join("yes" if r.get(k) else "**no**" for k in ("constructed", "verified", "verified_off_grid"))
        num = (f"{r['gap']:.4f} | {r['backoff']:.3g} | {r['max_frozen_hinf_over_gamma']:.3f}" if r["verified"]
               else f"{r.get('error', '')[:100]} | | ")  # fmt: skip
        rows.append(f"| {r['design'].replace('_', ' ')} | {setup} | {motor} | {ok} | {num} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m synthesis.design_grid", description=__doc__.splitlines()[0])
    ap.add_argument("which", nargs="?", default="all", choices=["flux", "current", "motors", "all"])
    ap.add_argument("--motors", type=int, default=20, help="random motors (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random motors")
    ap.add_argument("--table", metavar="JSONL", help="print the Markdown table of a file of this command's output")
    a = ap.parse_args(argv)
    if a.table:
        with open(a.table) as f:
            print(markdown_table([json.loads(line) for line in f if line.strip()]))
        return 0
    todo = list(cases(a.which, a.motors, a.seed))
    print(json.dumps({"environment": environment()}), flush=True)
    t0 = time.perf_counter()
    for k, (label, fn, args) in enumerate(todo):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # optimal_inaccurate solves are re-checked; the verdict is the record
            rec = fn(*args)
        print(json.dumps(rec, default=float), flush=True)
        done = time.perf_counter() - t0
        eta = done / (k + 1) * (len(todo) - k - 1)
        verdict = "ok" if rec["verified"] else "FAILED"
        print(f"[{k + 1}/{len(todo)}] {label}: {verdict} ({rec['wall_time']:.0f} s; ETA {eta / 60:.1f} min)",
              file=sys.stderr, flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
