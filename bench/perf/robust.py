"""Robust LPV synthesis benchmark (Ch. 7): ``python -m bench.perf.robust [repeats]`` prints JSON.

Problem: `random_diagonal_lpv(2)` (3 states, Δ = diag(δ_1, δ_2), 1 input, 1 output), scheduling errors
|e_i| ≤ ē = 0.1. Per run:

- ``iteration``: the ε iteration of 7.2 (`robust_iteration`, eps_step 0.02) with its steps (γ_a, γ, ε, r, r̃);
- ``construction`` and ``verification`` (`verify_robust`: 225 (Δ, E) pairs, analysis LMI, 1500-step
  time-varying loop) of the robust controller;
- ``nominal_under_errors``: the nominal (ē = 0) controller checked on the same (Δ, E) set, with and without
  clipping Δ̂ to [−1, 1] (frozen loops only);
- ``corollary_7_5``: the one-shot Cor. 7.5 design on `random_diagonal_lpv(0)`, ē = 0.05, a = 10.

Once (not timed): ``corollary_7_5_a_scan`` -- Cor. 7.5 on the main problem for a = 3, 5, 10, 30; ``thesis_7_2`` -- the thesis' final multipliers (r = 3.8/3.0, r̃ = 4.0/10.7,
ε = 0.15/0.16, tied form of 7.2) against (7.9)-(7.13) at ē = 3.1 %/2.5 %: the certified ē and the smallest
ε that passes at those r, r̃; ``theorem_7_1_grid`` -- 400 random one-channel multipliers: how often
(7.7)-(7.13) hold, how often (7.1) holds on a 41 × 21 (δ, e) grid, and violations (conditions hold, (7.1)
fails: must be 0).

Wall times are for this machine, one process; the build VM is shared, so treat them as indicative.
"""

from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
import warnings

import cvxpy as cp
import numpy as np

from synthesis.construct import construct_controller
from synthesis.models.examples import random_diagonal_lpv
from synthesis.robust import (
    construct_robust_controller, corollary_7_5, robust_iteration, verify_robust, DiagonalMultipliers,
    certified_uncertainty, robustness_checks, robustness_margin_on_grid,
)


def _clean(x: object) -> object:
    """JSON-safe: non-finite floats as strings, numpy scalars as Python numbers."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def run(repeats: int = 1) -> dict:
    e_bar = 0.1
    P = random_diagonal_lpv(2)
    out: dict = {"problem": "random_diagonal_lpv(2): n_x=3, 2 diagonal channels, e_bar=0.1", "runs": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        d = robust_iteration(P, e_bar, eps_step=0.02, max_steps=30)
        t_it = time.perf_counter() - t0
        t0 = time.perf_counter()
        K = construct_robust_controller(d.result, e_bar)
        t_con = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = verify_robust(P, K, d.final.gamma, e_bar)
        t_ver = time.perf_counter() - t0
        Kn = construct_controller(d.results[0])
        g_n = d.steps[0].gamma
        nom = {}
        for clip in (False, True):
            r = verify_robust(P, Kn, g_n, e_bar, clip=clip, tv_steps=0, lmi_points=0, raise_on_fail=False)
            nom["clipped" if clip else "unclipped"] = dict(max_frozen_hinf=r.max_frozen_hinf,
                                                          max_spectral_radius=r.max_spectral_radius, passed=r.passed)
        t0 = time.perf_counter()
        c = corollary_7_5(random_diagonal_lpv(0), 0.05, a=10.0)
        t_cor = time.perf_counter() - t0
        out["runs"].append(dict(
            iteration_s=t_it, n_steps=len(d.steps) - 1, per_step_s=[s.solve_time for s in d.steps],
            construction_s=t_con, verification_s=t_ver, verification_timings=rep.timings, summary=d.summary(),
            steps=[dict(step=s.step, eps=s.eps, gamma_a=s.gamma_a, gamma=s.gamma, r=s.r, rt=s.rt, r_rt=s.r_rt,
                        cases=s.cases, certified_e=s.certified_e, robust=s.robust) for s in d.steps],
            robust_controller=dict(gamma=d.final.gamma, passed=rep.passed, max_frozen_hinf=rep.max_frozen_hinf,
                                   lmi_gamma=rep.lmi_gamma, tv_gain=rep.tv_gain, n_c=K.K.n_c, m_c=K.info["m_c"],
                                   k_c=K.info["k_c"]),
            nominal_controller=dict(gamma=g_n, under_errors=nom),
            corollary_7_5=dict(wall_s=t_cor, success=c.success, gamma_a=c.final.gamma_a, gamma=c.final.gamma,
                               eps=c.final.eps, r_rt=c.final.r_rt, gamma_a_nominal=c.nominal.gamma_a),
        ))  # fmt: skip
    out["corollary_7_5_a_scan"] = {
        str(a): dict(success=c.success, gamma=c.final.gamma, eps=c.final.eps)
        for a in (3.0, 5.0, 10.0, 30.0)
        for c in [corollary_7_5(P, e_bar, a=a)]
    }
    out["thesis_7_2"] = thesis_7_2()
    out["theorem_7_1_grid"] = theorem_7_1_grid(400)
    for k in ("iteration_s", "construction_s", "verification_s"):
        out[k] = float(np.median([r[k] for r in out["runs"]]))
    out["env"] = dict(python=platform.python_version(), cvxpy=cp.__version__, cpus=os.cpu_count(),
                      machine=platform.machine())  # fmt: skip
    return _clean(out)  # type: ignore[return-value]


def _tied(r: list[float], rt: list[float], eps: list[float]):  # noqa: ANN202

    r_, rt_, e_ = (np.asarray(x, float) for x in (r, rt, eps))
    return DiagonalMultipliers(-r_ / (1 + e_), r_, -(1 + e_) * rt_, rt_)


def thesis_7_2() -> dict:
    """The published multipliers of 7.2 against our (7.9)-(7.13)."""
    r, rt, eps, e = [3.8, 3.0], [4.0, 10.7], [0.15, 0.16], [0.031, 0.025]
    m = _tied(r, rt, eps)
    chk = robustness_checks(m, e)
    eps_min = []
    for i in range(2):  # smallest ε_i (tied form, same r_i, r̃_i) that passes, by bisection on [2ē+ē², 1]
        lo, hi = 2 * e[i] + e[i] ** 2, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            ee = list(eps)
            ee[i] = mid
            lo, hi = (lo, mid) if robustness_checks(_tied(r, rt, ee), e)[i].holds else (mid, hi)
        eps_min.append(hi)
    return dict(r=r, rt=rt, eps=eps, e_bar=e, r_rt=[a * b for a, b in zip(r, rt)], cases=[c.case for c in chk],
                holds=[c.holds for c in chk], ratio_lhs_rhs=[c.ratio for c in chk],
                certified_e=certified_uncertainty(m).tolist(), smallest_passing_eps=eps_min)  # fmt: skip


def theorem_7_1_grid(n: int, seed: int = 0) -> dict:
    """Random one-channel multipliers with (5.20) at δ = ±1 and ē ∈ [0, 0.2]: conditions vs (7.1) on a grid."""
    rng = np.random.default_rng(seed)
    counts = dict(samples=n, conditions_hold=0, grid_7_1_holds=0, both=0, violations=0)
    t0 = time.perf_counter()
    for _ in range(n):
        r, rt = math.exp(rng.uniform(-2, 2)), math.exp(rng.uniform(-2, 2))
        m = DiagonalMultipliers(np.array([-r / math.exp(rng.uniform(0, 0.6))]), np.array([r]),
                                np.array([-rt * math.exp(rng.uniform(0, 0.6))]), np.array([rt]))  # fmt: skip
        e = rng.uniform(0, 0.2)
        holds = robustness_checks(m, e)[0].holds
        try:
            g = robustness_margin_on_grid(m.P, m.Pt, e) > 0
        except np.linalg.LinAlgError:
            g = False
        counts["conditions_hold"] += holds
        counts["grid_7_1_holds"] += g
        counts["both"] += holds and g
        counts["violations"] += holds and not g
    counts["wall_s"] = time.perf_counter() - t0
    return counts


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    print(json.dumps(run(n), indent=2))
