"""Synthesis benchmark: ``python -m bench.perf.synthesis`` prints JSON with wall times (this machine, 1 process).

- ``gamma_bisection``: γ_a of the flux observer (5.6.2, ω_r,max = 200 and the shipped 400, σ_i = σ_u = 1e-4,
  3 kHz) by bisection on Thm 5.15 with the full re-balancing of issue 12 (`flux_gamma_a`; target ≤ 10 s), next
  to the independent lower bound (`gamma_lower_bound`, `gap`);
- ``construction``: the solution at 1.1 γ_a and the controller construction (5.27)-(5.36), App. B;
- ``verification``: the independent checks of `synthesis.verify` on a 41-point ω_r grid.

``python -m bench.perf.synthesis current [repeats]``: the quasi-LPV current controller of 6.2.2 (causal
discretisation, 600 Hz and 3 kHz; and the as-written full D_bl ⋆ M at 600 Hz): wall time of the
whole design (bisection, construction with order reduction, verification on a 9 x 9 δ grid).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import warnings

import cvxpy as cp
import numpy as np

from synthesis.construct import construct_controller
from synthesis.models.motor import flux_observer_plant_discrete
from synthesis.lmi import ParameterSet, SynthesisProblem
from synthesis.models.flux_observer import flux_gamma_a, flux_lower_bound
from synthesis.verify import verify
from synthesis.models.current_controller import CurrentSpec, design_current_controller


def run(repeats: int = 1) -> dict:
    ps = ParameterSet.interval(1)
    out: dict = {"problem": "flux observer 5.6.2, sigma=1e-4, 3 kHz, full reading", "runs": []}
    for k in range(2 * repeats):
        w_max = 200.0 if k % 2 == 0 else 400.0
        P = flux_observer_plant_discrete(w_max, 1e-4, 1e-4)
        lb = flux_lower_bound(P).value
        t0 = time.perf_counter()
        b = flux_gamma_a(w_max, lower_bound=lb)
        t_bis = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = SynthesisProblem(P, ps, scaling=b.scaling).centered(1.1 * b.gamma_a)
        K = construct_controller(res)
        t_con = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = verify(P, K, 1.1 * b.gamma_a, ps.grid(41))
        t_ver = time.perf_counter() - t0
        out["runs"].append(dict(
            omega_r_max=w_max, gamma_lower_bound=lb, gap=b.gamma_a / lb, gamma_a=b.gamma_a, gamma=1.1 * b.gamma_a, n_solves=b.n_solves, rebalance_iterations=len(b.iterations),
            gamma_bisection_s=t_bis, per_solve_ms=1e3 * t_bis / b.n_solves, construction_s=t_con,
            verification_s=t_ver, construction_plus_verification_s=t_con + t_ver,
            verification_passed=rep.passed, verification_timings=rep.timings,
        ))  # fmt: skip
    out["gamma_bisection_s"] = float(np.median([r["gamma_bisection_s"] for r in out["runs"]]))
    out["construction_plus_verification_s"] = float(
        np.median([r["construction_plus_verification_s"] for r in out["runs"]])
    )
    out["env"] = dict(python=platform.python_version(), cvxpy=cp.__version__, cpus=os.cpu_count(),
                      machine=platform.machine())  # fmt: skip
    return out


def run_current(repeats: int = 1) -> dict:
    out: dict = {"problem": "quasi-LPV current controller 6.2.2, p_f=-100, sigma_u=1e-6, sigma_n=1e-8, "
                            "|delta1|<=800, |delta2|<=10", "designs": {}}  # fmt: skip
    for name, spec in (("causal_600Hz", CurrentSpec(rate_hz=600.0)), ("causal_3000Hz", CurrentSpec(rate_hz=3000.0)),
                       ("full_600Hz", CurrentSpec(rate_hz=600.0, discretisation="full"))):  # fmt: skip
        runs = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            d = design_current_controller(spec)
            runs.append(dict(wall_time_s=time.perf_counter() - t0, gamma_a=d.gamma_a, gamma=d.gamma,
                             n_c=d.controller.K.n_c, n_solves=d.bisection.n_solves, timings=d.timings,
                             verification_passed=d.verification.passed))  # fmt: skip
        out["designs"][name] = dict(runs=runs, wall_time_s_median=float(np.median([r["wall_time_s"] for r in runs])))
    out["env"] = dict(python=platform.python_version(), cvxpy=cp.__version__, cpus=os.cpu_count(),
                      machine=platform.machine())  # fmt: skip
    return out


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    if len(sys.argv) > 1 and sys.argv[1] == "current":
        print(json.dumps(run_current(int(sys.argv[2]) if len(sys.argv) > 2 else 1), indent=2, default=float))
    else:
        n = int(sys.argv[1]) if len(sys.argv) > 1 else 3
        print(json.dumps(run(n), indent=2, default=float))
