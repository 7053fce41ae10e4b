"""Robust LPV synthesis with diagonal variation and uncertain scheduling (thesis Ch. 7, Thm 7.1, Cor. 7.5, 7.2).

The plant (5.55) has w_u = Δ z_u with Δ = diag(δ_i), |δ_i| ≤ 1, but the controller only knows
Δ̂ = Δ + E, E = diag(e_i), |e_i| ≤ ē_i (e.g. Δ computed from a noisy speed, 6.3.3). The synthesis is
Thm 5.15 (`synthesis.lmi`, discrete time; Remark 7.8: the robustness conditions involve only the
multipliers) restricted to diagonal multipliers

    P = diag(Q, R), P̃ = diag(Q̃, R̃), Q = diag(q_i) ≺ 0, R = diag(r_i) ≻ 0, Q̃ ≺ 0, R̃ ≻ 0, S = S̃ = 0  (7.2)-(7.6)

plus the convex constraints

    R + (I + 𝓔)Q ≻ 0 (7.29),   Q̃ + (I + 𝓔)R̃ ≺ 0 (7.30),   ε_i > 2ē_i + ē_i² (7.31)

and, for Cor. 7.5, [[R, A_f^{-1/2}], [A_f^{-1/2}, R̃]] ≻ 0 (7.35)/(7.36) and α²R + A_f R̃ ≺ 2αA_f (7.37).
(7.30) is written linearly: with q̃_i < 0, r̃_i > 0, Cor. 7.5's R̃^{-1} + (I + 𝓔)Q̃^{-1} ≻ 0 is
q̃_i + (1 + ε_i) r̃_i < 0, i.e. (7.30).

A solution is robust for ē when, per channel, (7.7), (7.8) and one of the three conditions
(7.9), (7.10)+(7.11), (7.12)+(7.13) hold (`robustness_checks`). The controller is then the ordinary
construction (5.27)-(5.36) of `synthesis.construct` -- with U made of unit vectors, as the proof of
Thm 7.1 needs -- whose scheduling function Δ_c is evaluated at Δ̂ instead of Δ.

Two ways to get such a solution:

- `corollary_7_5`: choose a_i, α_i and ε_i above the largest real root of (7.38); one solve.
- `robust_iteration`: the procedure of 7.2 -- solve with (7.29)-(7.31), check (7.9)-(7.13), raise ε_i
  of the channels that fail, repeat -- starting from the nominal (ε = 0) diagonal design; every step
  reports γ_a, the design γ, ε, q, r, q̃, r̃ and the ē each channel is certified for.

`verify_robust` checks a controller independently (`synthesis.verify` with the controller scheduled on
Δ̂ = Δ + E over a grid of (Δ, E)); `extended_multiplier_margin` evaluates (7.1) itself, the inequality
that Thm 7.1's conditions are sufficient for.

Multiplier values are reported for the plant as given (undoing `balance_plant`'s channel scaling d and
performance scaling g0) with the l2-gain index diag(−γI, γ^{-1}I); the conditions (7.9)-(7.13) are
invariant under those scalings (each side of (7.11)/(7.13) is homogeneous), and so are the products
r_i r̃_i and the ratios q_i/r_i, q̃_i/r̃_i. The thesis' absolute r values depend on its own scalings.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike

from synthesis.construct import (
    ConstructionError,
    ScheduledController,
    Scheduling,
    construct_controller,
    extend_multiplier,
)
from synthesis.lft import LFTPlant
from synthesis.lmi import (
    ParameterSet,
    PlantScaling,
    SynthesisProblem,
    SynthesisResult,
    balance_plant,
    bisect_gamma,
    minimize_gamma,
)
from synthesis.verify import VerificationReport, verify

__all__ = [
    "DiagonalMultipliers",
    "ChannelCheck",
    "robustness_checks",
    "certified_uncertainty",
    "lemma_7_3_epsilon",
    "RobustConstraints",
    "RobustProblem",
    "RobustStep",
    "RobustDesign",
    "robust_iteration",
    "corollary_7_5",
    "construct_robust_controller",
    "extended_multiplier_margin",
    "robustness_margin_on_grid",
    "scheduling_error_grid",
    "verify_robust",
]


# --------------------------------------------------------------------------------------------------
# multipliers and the robustness conditions of Thm 7.1
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DiagonalMultipliers:
    """q, r, q̃, r̃ per channel: P = diag(Q, R), P̃ = diag(Q̃, R̃) (7.2)-(7.6)."""

    q: np.ndarray
    r: np.ndarray
    qt: np.ndarray
    rt: np.ndarray

    @classmethod
    def from_matrices(cls, P: ArrayLike, Pt: ArrayLike, *, rtol: float = 1e-9) -> "DiagonalMultipliers":
        P, Pt = np.real(np.asarray(P)), np.real(np.asarray(Pt))
        for name, M in (("P", P), ("P̃", Pt)):
            off = M - np.diag(np.diag(M))
            if np.abs(off).max(initial=0.0) > rtol * max(np.abs(M).max(), 1e-300):
                raise ValueError(f"{name} is not diagonal (Thm 7.1 needs diagonal multipliers, S = 0)")
        n = P.shape[0] // 2
        return cls(np.diag(P)[:n].copy(), np.diag(P)[n:].copy(), np.diag(Pt)[:n].copy(), np.diag(Pt)[n:].copy())

    @property
    def P(self) -> np.ndarray:
        return np.diag(np.concatenate([self.q, self.r]))

    @property
    def Pt(self) -> np.ndarray:
        return np.diag(np.concatenate([self.qt, self.rt]))

    def scaled(self, k: float) -> "DiagonalMultipliers":
        """P → kP, P̃ → P̃/k (a channel or performance scaling; leaves (7.9)-(7.13) unchanged)."""
        return DiagonalMultipliers(k * self.q, k * self.r, self.qt / k, self.rt / k)


@dataclass(frozen=True)
class ChannelCheck:
    """Thm 7.1 for one channel: which case applies and whether its conditions hold.

    case 1: (q − q̃^{-1})(r − r̃^{-1}) > 0 (7.9) -- no scheduling on this channel;
    case 2: q > q̃^{-1}, r < r̃^{-1} (7.10), needs (7.11); case 3: q < q̃^{-1}, r > r̃^{-1} (7.12), needs
    (7.13); case 0: N = P − P̃^{-1} is singular on this channel (Remark 7.2; the element is dropped).
    `ratio` is lhs/rhs of (7.11)/(7.13) (> 1 holds; inf for ē = 0 or cases 0/1).
    """

    case: int
    signs_ok: bool  # (7.2)-(7.5)
    c77: float  # q(1+ē)² + r  (> 0)
    c78: float  # q̃^{-1}(1+ē)² + r̃^{-1}  (> 0)
    ratio: float
    holds: bool


def _channel(q: float, r: float, qt: float, rt: float, e: float) -> ChannelCheck:
    b, c = 1.0 + e, (1.0 + e) ** 2
    signs = q < 0 < r and qt < 0 < rt
    qi, ri = 1.0 / qt, 1.0 / rt  # q̃^{-1}, r̃^{-1}
    c77 = q * c + r  # (7.7)
    c78 = qi * c + ri  # (7.8)
    nq, nr = q - qi, r - ri  # the diagonal of N = P − P̃^{-1} (5.27)
    ratio = math.inf
    if nq == 0.0 or nr == 0.0:
        case, ok = 0, True
    elif nq * nr > 0:  # (7.9)
        case, ok = 1, True
    elif nq > 0:  # (7.10): q > q̃^{-1}, r < r̃^{-1}; (7.11)
        case = 2
        lhs = (c * q + ri) ** 2 * (qi + ri) * (q + r)
        rhs = (b * q - ri) ** 2 * e**2 * (ri - r) * (q - qi)
        ratio = lhs / rhs if rhs > 0 else (math.inf if lhs > 0 else -math.inf)
        ok = lhs > rhs
    else:  # (7.12): q < q̃^{-1}, r > r̃^{-1}; (7.13)
        case = 3
        lhs = (c * qi + r) ** 2 * (q + r) * (qi + ri)
        rhs = (b * qi - r) ** 2 * e**2 * (r - ri) * (qi - q)
        ratio = lhs / rhs if rhs > 0 else (math.inf if lhs > 0 else -math.inf)
        ok = lhs > rhs
    holds = bool(signs and c77 > 0 and c78 > 0 and ok)
    return ChannelCheck(case, bool(signs), float(c77), float(c78), float(ratio), holds)


def robustness_checks(mult: DiagonalMultipliers, e_bar: ArrayLike) -> list[ChannelCheck]:
    """The conditions of Thm 7.1, (7.2)-(7.5), (7.7)-(7.13), per channel for the bounds ē_i."""
    e = np.broadcast_to(np.asarray(e_bar, float), mult.q.shape)
    return [_channel(*(float(v[i]) for v in (mult.q, mult.r, mult.qt, mult.rt)), float(e[i])) for i in range(len(e))]


def certified_uncertainty(mult: DiagonalMultipliers, *, e_cap: float = 10.0, n_scan: int = 400) -> np.ndarray:
    """Per channel the largest ē (≤ e_cap) for which Thm 7.1's conditions hold on all of [0, ē].

    Scans ē on a geometric grid from 1e-6 and bisects the first failure to 1e-6 relative. 0 if they fail
    already at ē = 0 (e.g. wrong signs); e_cap if they never fail (case 1 channels are limited only by
    (7.7)/(7.8)).
    """
    out = np.zeros(len(mult.q))
    grid = np.concatenate([[0.0], np.geomspace(1e-6, e_cap, n_scan)])
    for i in range(len(mult.q)):
        args = (float(mult.q[i]), float(mult.r[i]), float(mult.qt[i]), float(mult.rt[i]))
        if not _channel(*args, 0.0).holds:
            continue
        lo, hi = 0.0, None
        for e in grid[1:]:
            if _channel(*args, float(e)).holds:
                lo = float(e)
            else:
                hi = float(e)
                break
        if hi is None:
            out[i] = e_cap
            continue
        while hi - lo > 1e-6 * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _channel(*args, mid).holds else (lo, mid)
        out[i] = lo
    return out


def lemma_7_3_epsilon(a: ArrayLike, e_bar: ArrayLike) -> np.ndarray:
    """Per channel the bound that Cor. 7.5 needs ε_i to exceed: the largest real root of P_{a_i} (7.38)
    (Lemma 7.3, (7.32)) and (1 + ē_i)² − 1 = 2ē_i + ē_i² (7.31)."""
    a_arr, e_arr = np.broadcast_arrays(np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(e_bar, float)))
    out = np.zeros(a_arr.shape)
    for i, (ai, ei) in enumerate(zip(a_arr.ravel(), e_arr.ravel())):
        coef = [  # (7.38)
            ai**2,
            ei**2 * (ai**2 - ai**3 - ai) + ai**2 - ai - 2 * ai * ei,
            2 * ei**2 * (ai - ai**3),
            ei**2 * (ai - ai**3 - ai**2 + 1),
        ]
        roots = np.roots(coef)
        real = roots[np.abs(roots.imag) <= 1e-9 * max(1.0, np.abs(roots).max())].real
        top = float(real.max()) if real.size else -math.inf
        out.flat[i] = max(top, 2 * ei + ei**2)
    return out


# --------------------------------------------------------------------------------------------------
# the convex constraints (7.29)-(7.31), (7.35)-(7.37) as a `synthesis.lmi` hook
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RobustConstraints:
    """(7.29)/(7.30) with 𝓔 = diag(eps); optionally Cor. 7.5's (7.35)/(7.36) (a) and (7.37) (alpha).

    ``tied=True`` is the parametrisation of 7.2: q_i = −r_i/(1 + ε_i), q̃_i = −(1 + ε_i) r̃_i, i.e.
    (7.29)/(7.30) held with equality (one free r_i, r̃_i per channel).
    """

    eps: np.ndarray
    a: np.ndarray | None = None
    alpha: np.ndarray | None = None
    tied: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "eps", np.atleast_1d(np.asarray(self.eps, float)))
        if np.any(self.eps < 0):
            raise ValueError("ε_i must be ≥ 0 (7.31)")
        if self.alpha is not None and self.a is None:
            raise ValueError("(7.37) needs a with alpha")

    @property
    def n(self) -> int:
        return len(self.eps)

    def build(self, P: cp.Expression, Pt: cp.Expression, margin: cp.Expression) -> list:
        n = self.n
        d, dt_ = cp.diag(P), cp.diag(Pt)
        q, r, qt, rt = d[:n], d[n:], dt_[:n], dt_[n:]
        one = 1.0 + self.eps
        cons = []
        if self.tied:
            cons += [cp.multiply(one, q) + r == 0, qt + cp.multiply(one, rt) == 0]
        else:
            cons += [r + cp.multiply(one, q) >= margin, qt + cp.multiply(one, rt) <= -margin]  # (7.29), (7.30)
        if self.a is not None:
            g = np.asarray(self.a, float) ** -0.5  # (7.36)
            for i in range(n):  # (7.35), channel by channel (everything is diagonal)
                M = cp.bmat([[cp.reshape(r[i], (1, 1), order="F"), np.array([[g[i]]])],
                             [np.array([[g[i]]]), cp.reshape(rt[i], (1, 1), order="F")]])
                cons.append(0.5 * (M + M.T) - margin * np.eye(2) >> 0)
        if self.alpha is not None:
            al, a = np.asarray(self.alpha, float), np.asarray(self.a, float)
            cons.append(cp.multiply(al**2, r) + cp.multiply(a, rt) <= 2 * al * a - margin)  # (7.37)
        return cons

    def residuals(self, P: np.ndarray, Pt: np.ndarray) -> dict[str, float]:
        m = DiagonalMultipliers.from_matrices(P, Pt)
        one = 1.0 + self.eps
        out: dict[str, float] = {}
        if self.tied:
            scale = max(np.abs(m.r).max(), np.abs(m.rt).max(), 1e-300)
            out["7.2 tied"] = float(max(np.abs(one * m.q + m.r).max(), np.abs(m.qt + one * m.rt).max()) / scale) - 1e-6
        else:
            out["(7.29)"] = float(np.max(-(m.r + one * m.q)))
            out["(7.30)"] = float(np.max(m.qt + one * m.rt))
        if self.a is not None:
            g = np.asarray(self.a, float) ** -0.5
            lam = [np.linalg.eigvalsh(np.array([[m.r[i], g[i]], [g[i], m.rt[i]]]))[0] for i in range(self.n)]
            out["(7.35)"] = float(np.max(-np.asarray(lam)))
        if self.alpha is not None:
            al, a = np.asarray(self.alpha, float), np.asarray(self.a, float)
            out["(7.37)"] = float(np.max(al**2 * m.r + a * m.rt - 2 * al * a))
        return out


def _centering(n_x: int, n_u: int) -> Callable[[dict], cp.Expression]:
    """7.1: "the multipliers should be kept small, for instance by minimising the trace of R − Q̃";
    tr(Y)/n_x is added as in `SynthesisProblem.centered` to keep 𝒳 of (5.32) well conditioned."""

    def obj(got: dict) -> cp.Expression:
        d, dt_ = cp.diag(got["P_expr"]), cp.diag(got["Pt_expr"])
        return cp.trace(got["Y_expr"]) / n_x + (cp.sum(d[n_u:]) - cp.sum(dt_[:n_u])) / n_u

    return obj


class RobustProblem(SynthesisProblem):
    """Thm 5.15 with diagonal multipliers and `RobustConstraints` (Cor. 7.5 / 7.2), one ε (and a, α).

    The design γ of `centered` minimises tr(Y)/n + tr(R − Q̃)/n_u at half the maximal margin (7.1's
    advice); everything else (scaling, bounds, margins, Clarabel settings, re-checks) is
    `SynthesisProblem`'s.
    """

    def __init__(self, plant: LFTPlant, params: ParameterSet, constraints: RobustConstraints, **kw) -> None:
        if params.box is None or any(b != (-1.0, 1.0) for b in params.box):
            raise ValueError("Thm 7.1 is stated for Δ = diag(δ_i), |δ_i| ≤ 1: use ParameterSet.diagonal(n)")
        if constraints.n != plant.n_wu:
            raise ValueError(f"ε has {constraints.n} entries, the plant has {plant.n_wu} parameter channels")
        kw.setdefault("centering", _centering(plant.n_x, plant.n_wu))
        super().__init__(plant, params, multipliers="diagonal", constraints=constraints, **kw)
        self.robust = constraints

    def multipliers_of(self, res: SynthesisResult) -> DiagonalMultipliers:
        """The solution's q, r, q̃, r̃ in the units of the plant as given (index diag(−γI, I/γ))."""
        m = DiagonalMultipliers.from_matrices(res.P, res.Pt)
        return m.scaled(res.scaling.g0 * res.scaling.d**2)


def _params_for(plant: LFTPlant) -> ParameterSet:
    if plant.n_wu != plant.n_zu:
        raise ValueError("Thm 7.1 needs a square diagonal Δ (n_wu = n_zu)")
    if np.iscomplexobj(plant.M) and np.any(np.imag(plant.M)):
        raise ValueError("Ch. 7 assumes real matrices (7.1); the plant is complex")
    return ParameterSet.diagonal(plant.n_wu)


def _e_vec(e_bar: ArrayLike, n: int) -> np.ndarray:
    e = np.broadcast_to(np.asarray(e_bar, float), (n,)).copy()
    if np.any(e < 0) or np.any(~np.isfinite(e)):
        raise ValueError("the scheduling-error bounds ē_i must be finite and ≥ 0")
    return e


# --------------------------------------------------------------------------------------------------
# the iteration of 7.2 and Cor. 7.5
# --------------------------------------------------------------------------------------------------
@dataclass
class RobustStep:
    """One solve of the ε iteration: the quantities 7.2 reports (γ, ε, r, r̃) and the checks."""

    step: int
    eps: list[float]
    gamma_a: float  # γ minimised over (5.59)-(5.62) + (7.29)/(7.30) at this ε
    gamma: float  # the design γ = backoff · γ_a at which the multipliers below were found
    feasible: bool
    q: list[float]
    r: list[float]
    qt: list[float]
    rt: list[float]
    cases: list[int]
    ratios: list[float]  # lhs/rhs of (7.11)/(7.13) at the target ē (inf: not needed)
    certified_e: list[float]  # the largest ē per channel for which Thm 7.1's conditions hold
    robust: bool  # all channels hold at the target ē
    solve_time: float

    @property
    def r_rt(self) -> list[float]:
        """r_i r̃_i, the scale-invariant quantity behind the case distinction."""
        return [a * b for a, b in zip(self.r, self.rt)]


@dataclass(eq=False)
class RobustDesign:
    """Result of `robust_iteration` / `corollary_7_5`: every step, and the final solution if robust."""

    e_bar: list[float]
    steps: list[RobustStep]
    success: bool
    result: SynthesisResult | None  # the solution of the last robust step (for the construction)
    problem: RobustProblem | None
    scaling: PlantScaling
    wall_time: float
    reason: str = ""
    settings: dict = field(default_factory=dict)
    results: list[SynthesisResult | None] = field(default_factory=list)  # the solution of every step

    @property
    def nominal(self) -> RobustStep:
        return self.steps[0]

    @property
    def final(self) -> RobustStep:
        return self.steps[-1]

    def summary(self) -> dict:
        """The numbers 7.2 quotes: γ nominal → robust, final ε, r, r̃ (plus ē and what was certified)."""
        f = self.final
        return dict(
            e_bar=self.e_bar, success=self.success, gamma_nominal=self.nominal.gamma, gamma_robust=f.gamma,
            gamma_a_nominal=self.nominal.gamma_a, gamma_a_robust=f.gamma_a, eps=f.eps, r=f.r, rt=f.rt, q=f.q,
            qt=f.qt, r_rt=f.r_rt, cases=f.cases, certified_e=f.certified_e, steps=len(self.steps) - 1,
            wall_time_s=self.wall_time, reason=self.reason,
        )  # fmt: skip

    def as_dict(self) -> dict:
        return dict(summary=self.summary(), steps=[asdict(s) | {"r_rt": s.r_rt} for s in self.steps],
                    settings=self.settings)  # fmt: skip


def _solve_step(
    plant: LFTPlant, params: ParameterSet, cons: RobustConstraints, e: np.ndarray, k: int, scaling: PlantScaling,
    backoff: float, kw: dict, gamma_method: str = "minimize",
) -> tuple[RobustStep, SynthesisResult | None, RobustProblem]:
    """γ_a at this ε (one SDP, or bisection), the centred solution at backoff·γ_a, and its checks.

    If the one-SDP minimisation or the centred solution fails, `bisect_gamma` (feasibility tests with
    re-balancing, `synthesis.lmi`) is tried before the step is declared infeasible.
    """
    t0 = time.perf_counter()
    prob = RobustProblem(plant, params, cons, scaling=scaling, **kw)
    ga, res = math.inf, None
    if gamma_method == "minimize":
        ga = prob.minimize().gamma  # the minimiser sits on the boundary, the design point does not
        res = prob.centered(backoff * ga) if np.isfinite(ga) else None
    elif gamma_method != "bisect":
        raise ValueError("gamma_method must be 'minimize' or 'bisect'")
    if res is None or not res.feasible:
        try:
            b = bisect_gamma(plant, params, g0=scaling.g0, multipliers="diagonal", constraints=cons,
                             centering=prob.centering, **kw)  # fmt: skip
        except RuntimeError:  # no feasible γ at all
            b = None
        if b is not None:
            ga = b.gamma_a
            prob = RobustProblem(plant, params, cons, scaling=b.scaling, **kw)
            res = prob.centered(backoff * ga)
    dt = time.perf_counter() - t0
    n = plant.n_wu
    if res is None or not res.feasible:
        nan = [math.nan] * n
        st = RobustStep(k, cons.eps.tolist(), float(ga), float(backoff * ga), False, nan, nan, nan, nan, [-1] * n,
                        nan, [0.0] * n, False, dt)  # fmt: skip
        return st, None, prob
    m = prob.multipliers_of(res)
    chk = robustness_checks(m, e)
    cert = certified_uncertainty(m)
    st = RobustStep(
        k, cons.eps.tolist(), float(ga), float(res.gamma), True, m.q.tolist(), m.r.tolist(), m.qt.tolist(),
        m.rt.tolist(), [c.case for c in chk], [c.ratio for c in chk], cert.tolist(), all(c.holds for c in chk), dt,
    )  # fmt: skip
    return st, res, prob


def robust_iteration(
    plant: LFTPlant,
    e_bar: ArrayLike,
    *,
    eps_step: float | ArrayLike = 0.01,
    eps_start: ArrayLike | None = None,
    max_steps: int = 40,
    backoff: float = 1.1,
    tied: bool = False,
    g0: float | None = None,
    gamma_method: str = "minimize",
    progress: Callable[[RobustStep], None] | None = None,
    **kw,
) -> RobustDesign:
    """The iterative ε increase of 7.2.

    Step 0 is the nominal design (ε = 0: diagonal multipliers, no robustness constraint). Then
    ε_i starts just above 2ē_i + ē_i² (7.31) (or at `eps_start`), and after each solve every channel
    whose conditions (7.7)-(7.13) fail at ē gets ε_i += eps_step, until all hold (`success`), the
    LMIs become infeasible, or `max_steps` is reached. Each step minimises γ under (7.29)/(7.30) (γ_a)
    and then takes the solution at γ = backoff·γ_a that keeps R and −Q̃ small (7.1). The plant is
    scaled once, from the nominal diagonal γ_a (`balance_plant` with that g0), for all steps.
    ``tied=True`` uses the one-parameter multipliers of 7.2. ``gamma_method="bisect"`` finds γ_a by
    `bisect_gamma` (with re-balancing) instead of one SDP; it is also the automatic fallback. `kw` goes
    to `SynthesisProblem` (x_bound, mult_bound, eps, tol, solver_opts, beta).
    """
    t0 = time.perf_counter()
    params = _params_for(plant)
    n = plant.n_wu
    e = _e_vec(e_bar, n)
    step = np.broadcast_to(np.asarray(eps_step, float), (n,))
    if np.any(step <= 0):
        raise ValueError("eps_step must be > 0")
    if eps_start is None:
        eps = (2 * e + e**2) * (1 + 1e-6) + 1e-9
    else:
        eps = np.broadcast_to(np.asarray(eps_start, float), (n,)).copy()
        if np.any(eps <= 2 * e + e**2):
            raise ValueError("eps_start must exceed 2ē + ē² (7.31)")
    scaling, g0 = _scaling(plant, params, g0, kw)
    steps: list[RobustStep] = []
    results: list[SynthesisResult | None] = []
    success, reason, final = False, f"no robust solution in {max_steps} steps", (None, None)
    for k in range(max_steps + 1):
        cons = RobustConstraints(np.zeros(n)) if k == 0 else RobustConstraints(eps.copy(), tied=tied)
        st, res, prob = _solve_step(plant, params, cons, e, k, scaling, backoff, kw, gamma_method)
        steps.append(st)
        results.append(res)
        if progress:
            progress(st)
        if not st.feasible:
            reason = "nominal infeasible" if k == 0 else f"infeasible at ε = {eps.tolist()}"
            break
        if st.robust and (k > 0 or not np.any(e > 0)):
            success, final, reason = True, (res, prob), "robust" if k else "nominal is robust (ē = 0)"
            break
        if k > 0:
            eps = eps + step * np.array([not c.holds for c in robustness_checks(_mult(st), e)])
    settings = dict(eps_step=step.tolist(), max_steps=max_steps, backoff=backoff, tied=tied, g0=g0, gamma_method=gamma_method,
                    **{k: v for k, v in kw.items() if isinstance(v, (int, float, str, bool))})  # fmt: skip
    return RobustDesign(e.tolist(), steps, success, final[0], final[1], scaling, time.perf_counter() - t0, reason,
                        settings, results)  # fmt: skip


def _mult(st: RobustStep) -> DiagonalMultipliers:
    return DiagonalMultipliers(*(np.array(v) for v in (st.q, st.r, st.qt, st.rt)))


def _scaling(plant: LFTPlant, params: ParameterSet, g0: float | None, kw: dict) -> tuple[PlantScaling, float]:
    """One scaling for all steps: g0 = the nominal diagonal γ_a (one SDP) unless given."""
    if g0 is None:
        extra = {k: kw[k] for k in ("beta",) if k in kw}
        g0 = minimize_gamma(plant, params, multipliers="diagonal", **extra).gamma
        if not (np.isfinite(g0) and g0 > 0):
            g0 = 1.0
    return balance_plant(plant, g0), float(g0)


def corollary_7_5(
    plant: LFTPlant,
    e_bar: ArrayLike,
    *,
    a: ArrayLike | None = None,
    alpha: ArrayLike | None = None,
    eps_slack: float = 1e-3,
    backoff: float = 1.1,
    g0: float | None = None,
    gamma_method: str = "minimize",
    **kw,
) -> RobustDesign:
    """Cor. 7.5 in one solve: ε_i = (largest root of (7.38), or 2ē_i + ē_i²) + eps_slack, with (7.35)-(7.37).

    a_i defaults to 0.01/ē_i² (the text after (7.41): a_i ∝ ē_i^{-2}; Example 7.6 has a = 100 for
    ē = 0.01). α_i defaults to the point where the half-plane (7.37) touches r_i r̃_i = a_i on the ray of
    the nominal solution's (r_i, r̃_i) (an a-priori choice from step 0); a given α is in plant units.
    Returns a two-step `RobustDesign` (nominal, Cor. 7.5); `success` iff the Cor. 7.5 solve is feasible
    and the checks (7.9)-(7.13) hold -- which Lemma 7.3 guarantees, so a failure of the checks after a
    feasible solve is reported as such (`reason`).
    """
    t0 = time.perf_counter()
    params = _params_for(plant)
    n = plant.n_wu
    e = _e_vec(e_bar, n)
    if a is None:
        if np.any(e <= 0):
            raise ValueError("a must be given when some ē_i = 0")
        a_v = 0.01 / e**2
    else:
        a_v = np.broadcast_to(np.asarray(a, float), (n,)).copy()
    if np.any(a_v <= 1):
        raise ValueError("Cor. 7.5 needs a_i > 1 ((7.35) and (7.37) together ask 1/a_i < r_i r̃_i < a_i)")
    scaling, g0 = _scaling(plant, params, g0, kw)
    nom, res0, _ = _solve_step(plant, params, RobustConstraints(np.zeros(n)), e, 0, scaling, backoff, kw, gamma_method)
    if not nom.feasible:
        return RobustDesign(e.tolist(), [nom], False, None, None, scaling, time.perf_counter() - t0,
                            "nominal infeasible", {}, [res0])  # fmt: skip
    sc = scaling.g0 * scaling.d**2  # plant units ↔ scaled problem: r = sc·r', r̃ = r̃'/sc
    if alpha is None:
        # the tangency point of α²r + a r̃ = 2αa with r r̃ = a is (a/α, α); put it on the nominal ray
        m0 = DiagonalMultipliers.from_matrices(res0.P, res0.Pt)
        alpha_s = np.sqrt(a_v * m0.rt / m0.r)
    else:
        alpha_s = np.broadcast_to(np.asarray(alpha, float), (n,)) * sc  # (7.37) in scaled units: α' = α·sc
    eps = lemma_7_3_epsilon(a_v, e) + eps_slack
    cons = RobustConstraints(eps, a=a_v, alpha=alpha_s)
    st, res, prob = _solve_step(plant, params, cons, e, 1, scaling, backoff, kw, gamma_method)
    ok = st.feasible and st.robust
    reason = "robust" if ok else ("infeasible" if not st.feasible else "Cor. 7.5 solution fails (7.9)-(7.13)")
    settings = dict(a=a_v.tolist(), alpha=(alpha_s / sc).tolist(), eps=eps.tolist(), backoff=backoff, g0=g0)
    return RobustDesign(e.tolist(), [nom, st], ok, res if ok else None, prob if ok else None, scaling,
                        time.perf_counter() - t0, reason, settings, [res0, res])  # fmt: skip


# --------------------------------------------------------------------------------------------------
# construction, (7.1), verification
# --------------------------------------------------------------------------------------------------
def construct_robust_controller(res: SynthesisResult, e_bar: ArrayLike, **kw) -> ScheduledController:
    """The controller of Thm 7.1 from a robust solution: `construct_controller` (5.27)-(5.36) with unit-vector
    U; its `delta_c` is to be evaluated at Δ̂ = Δ + E. Raises ConstructionError if the multipliers are not
    diagonal or fail (7.7)-(7.13) for ē."""
    if res.plant.n_wu == 0:
        raise ConstructionError("no parameter channel")
    try:
        m = DiagonalMultipliers.from_matrices(res.P, res.Pt)
    except ValueError as ex:
        raise ConstructionError(str(ex)) from None
    e = _e_vec(e_bar, len(m.q))
    bad = [i for i, c in enumerate(robustness_checks(m, e)) if not c.holds]
    if bad:
        raise ConstructionError(f"channels {bad} fail the conditions (7.7)-(7.13) of Thm 7.1 for ē = {e.tolist()}")
    K = construct_controller(res, **kw)
    K.info.update(e_bar=e.tolist(), cases=[c.case for c in robustness_checks(m, e)], robust=True)
    return K


def extended_multiplier_margin(P: np.ndarray, Pt: np.ndarray, Delta: ArrayLike, Delta_hat: ArrayLike) -> float:
    """λ_min of S_e^T P_e S_e, S_e = blockdiag([Δ; I], [Δ_c(Δ̂); I]): (7.1) holds at (Δ, Δ̂) iff > 0.

    P_e is (5.30) from `extend_multiplier`, Δ_c is (5.36) from `Scheduling`, both of `synthesis.construct`.
    """
    return _margin(P, *extend_multiplier(P, Pt), Delta, Delta_hat)


def _margin(P: np.ndarray, U: np.ndarray, lam: np.ndarray, Pe: np.ndarray, Delta: ArrayLike, Delta_hat: ArrayLike) -> float:
    D, Dh = np.atleast_2d(np.asarray(Delta, float)), np.atleast_2d(np.asarray(Delta_hat, float))
    n = D.shape[0]
    Dc = Scheduling(P, U, lam, n, n)(Dh)
    S = np.zeros((Pe.shape[0], n + Dc.shape[1]))
    S[:n, :n], S[n : 2 * n, :n] = D, np.eye(n)
    k = Dc.shape[1]
    S[2 * n : 2 * n + Dc.shape[0], n:] = Dc
    S[2 * n + Dc.shape[0] :, n:] = np.eye(k)
    M = S.T @ Pe @ S
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])


def scheduling_error_grid(n: int, e_bar: ArrayLike, *, k_delta: int = 5, k_e: int = 3, clip: bool = False
                          ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Pairs (Δ, Δ̂ = Δ + E) on a tensor grid: δ_i on k_delta points of [−1, 1], e_i on k_e points of [−ē_i, ē_i].

    ``clip=True`` clips Δ̂ to [−1, 1] (what an implementation that knows |δ_i| ≤ 1 would do; it keeps
    |δ̂_i − δ_i| ≤ |e_i|, so the pair stays in the set of Thm 7.1).
    """
    e = _e_vec(e_bar, n)
    per = [list(itertools.product(np.linspace(-1, 1, k_delta), np.linspace(-ei, ei, k_e if ei > 0 else 1))) for ei in e]
    D, Dh = [], []
    for combo in itertools.product(*per):
        d = np.array([c[0] for c in combo])
        dh = d + np.array([c[1] for c in combo])
        D.append(np.diag(d))
        Dh.append(np.diag(np.clip(dh, -1.0, 1.0) if clip else dh))
    return D, Dh


def robustness_margin_on_grid(P: np.ndarray, Pt: np.ndarray, e_bar: ArrayLike, *, k_delta: int = 41,
                              k_e: int = 21) -> float:
    """min over a (Δ, E) grid of `extended_multiplier_margin`, normalised by ‖P_e‖: (7.1) on the grid iff > 0.

    Everything is diagonal, so (7.1) splits into channels; the grid is per channel (k_delta·k_e points
    each) with the other channels at Δ̂ = Δ = 0.
    """
    e = _e_vec(e_bar, P.shape[0] // 2)
    n = len(e)
    ext = extend_multiplier(P, Pt)
    scale = np.linalg.norm(ext[2], 2)
    worst = math.inf
    for i in range(n):
        for d in np.linspace(-1, 1, k_delta):
            for ei in np.linspace(-e[i], e[i], k_e if e[i] > 0 else 1):
                D = np.zeros((n, n))
                Dh = np.zeros((n, n))
                D[i, i], Dh[i, i] = d, d + ei
                worst = min(worst, _margin(P, *ext, D, Dh) / scale)
    return worst


def verify_robust(
    plant: LFTPlant, controller: ScheduledController, gamma: float, e_bar: ArrayLike, *, k_delta: int = 5,
    k_e: int = 3, clip: bool = False, **kw,
) -> VerificationReport:
    """`synthesis.verify.verify` over (Δ, Δ̂ = Δ + E), |δ_i| ≤ 1, |e_i| ≤ ē_i (`scheduling_error_grid`):
    frozen stability and H∞ ≤ γ, a fresh common-𝒳 analysis LMI (5.52) over the pairs, and the
    time-varying loop with Δ and E jumping every sample. Raises VerificationError on failure unless
    ``raise_on_fail=False``. ``clip`` clips Δ̂ to [−1, 1] (`scheduling_error_grid`)."""
    D, Dh = scheduling_error_grid(plant.n_wu, e_bar, k_delta=k_delta, k_e=k_e, clip=clip)
    return verify(plant, controller, gamma, D, schedule=Dh, **kw)
