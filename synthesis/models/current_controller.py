"""The quasi-LPV stator current controller of thesis Sec. 6.2 (model, LFT, design, verification).

Model (6.10)-(6.17). In the frame of the estimated rotor flux (angle ρ_cc, speed ω_cc), with the
current-model observer (6.12)/(6.13) ω_cc = ω_r + i_sq/(T_r î_mR) inserted, the stator/magnetising
current subsystem is quasi-LPV (6.15):

    ẋ_cc = (A_0 + δ_1 A_1 + δ_2 A_2) x_cc + B_sc ū_s,cc,   x_cc = [ī_s,cc; ī_m,cc],
    δ_1 = ω_cc ∈ [−800, 800] rad/s,   δ_2 = i_sq/î_mR ∈ [−10, 10],

    A_0 = [[−(R_s + R'_r)/L'_s, R'_r/L'_s], [R'_r/L'_m, −R'_r/L'_m]]   (errata: R'_r, not R'_s, in (2,2)),
    A_1 = [[−j, −j L'_m/L'_s], [0, 0]],   A_2 = [[0, j L'_m/(T_r L'_s)], [0, −j/T_r]],   B_sc = [1/L'_s; 0].

A_1 and A_2 have rank one, so (6.16)/(6.17) pull them out as B_u0 diag(δ_1, δ_2) C_u0. Here each δ_i is
normalised to [−1, 1] (Δ = diag(δ_1/δ_1,max, δ_2/δ_2,max)) and the rank-one factor of δ_i,max·A_i is
split evenly between B_u0 and C_u0 (the SVD factors of 6.2.1 times √(σ_i δ_i,max)); Δ is real.

Augmentation (6.2.2): w_p = [ī_ref; n_m], z_p = [W(s)(ī_s − ī_ref); σ_u ū_s], y = ī_s − ī_ref + σ_n n_m
(C_p, D_pp, E_p, C, F_p as printed), where the first performance output passes a first-order low-pass
with its pole at s = p_f. The thesis gives only the pole; we read "a first-order low-pass filter with a
pole in s = p_f" as W(s) = g_f/(s − p_f) with g_f = 1 (``filter_gain``); g_f = −p_f (unit DC gain) is
the other reading, and docs/RESULTS.md reports γ_a for both. Realisation: ẋ_f = p_f x_f + g_f(ī_s − ī_ref),
z_p1 = x_f. The plant state is x = [ī_s; ī_m; x_f] (complex).

Discretisation (5.4.1, Δ frozen over a sample), ``CurrentSpec.discretisation``:

- ``"causal"`` (default): D_bl acts on the state and parameter rows only; y_k and z_p,k are formed from
  the sampled state ξ_k (what the ADC sees at t_k, before u_k is applied), so F_3 = 0. This is the
  thesis' habit for the flux observer (5.6.1) and gives controllers that are stable on the exactly
  sampled motor.
- ``"full"``: D_bl ⋆ M of the whole plant. y_k is then formed from the trapezoidal state, so u_k reaches
  y_k in the same sample (F_3 = (T_s/2) C (I − T_s A/2)^{-1} B ≠ 0, removed by Γ (Example 2.22) before
  synthesis and restored in the controller). Synthesis on it is exactly continuous-time synthesis (γ_a
  does not depend on the rate), and the controller relies on the instant feedthrough: at 600 Hz it is
  unstable against the sampled motor (docs/RESULTS.md 4.2).

Synthesis: Thm 5.15 with P_p = l2 gain, the 4 corners of the δ box as generators (Q ≺ 0, R̃ ≻ 0,
5.3.3), γ bisection (`synthesis.lmi.bisect_gamma`), construction at backoff·γ_a, optional order
reduction when X − Y^{-1} is nearly singular (6.2.2: the thesis reduced to order 2), and independent
verification on a δ grid (`synthesis.verify`; a failure raises).

Nothing here imports `bench` or `mock_hw`.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np

from synthesis.construct import MAX_BACKOFF, ConstructionError, ScheduledController, backoff_ladder, construct_controller
from synthesis.discretize import bilinear_lft, d_bl, tustin_period
from synthesis.lft import LFTPlant, Partitioned, StateSpace, remove_feedthrough, star
from synthesis.lmi import (
    BisectionResult, ParameterSet, PlantScaling, SynthesisProblem, SynthesisResult, balanced_centre, bisect_gamma,
    ParameterSet as _PS,
)
from synthesis.lower_bound import LowerBound, certificate, lpv_lower_bound
from synthesis.models.motor import MotorData
from synthesis.verify import VerificationError, VerificationReport, verify, hinf_norm

__all__ = [
    "CurrentSpec",
    "CurrentControllerDesign",
    "cc_matrices",
    "a_cc",
    "current_plant",
    "current_plant_discrete",
    "parameter_set",
    "delta_grid",
    "normalised_delta",
    "design_current_controller",
    "summary",
    "HOLDS",
    "sampled_loop",
    "sampled_hinf",
    "sampled_report",
    "sampled_time_gain",
    "artifact_certificate",
    "THESIS_GAMMA",
    "THESIS_ORDER",
]

#: 6.2.2: "a γ = 0.0011 was achieved", controller order 2.
THESIS_GAMMA: float = 0.0011
THESIS_ORDER: int = 2
#: margin fractions tried, in order, for the trace-minimising solution used by the construction
MARGIN_FRACTIONS: tuple[float, ...] = (0.5, 0.2, 0.1, 0.05)


@dataclass(frozen=True)
class CurrentSpec:
    """Design parameters of 6.2.2 (SI units; δ_1 in rad/s, δ_2 dimensionless)."""

    p_f: float = -100.0  # pole of the error filter [rad/s]
    sigma_u: float = 1e-6  # weight of ū_s in z_p
    sigma_n: float = 1e-8  # weight of the measurement noise
    delta1_max: float = 800.0  # |ω_cc| ≤ δ_1,max [rad/s]
    delta2_max: float = 10.0  # |i_sq/î_mR| ≤ δ_2,max
    rate_hz: float = 600.0  # sampling rate (the thesis: 600 Hz)
    filter_gain: float = 1.0  # g_f in W(s) = g_f/(s − p_f)
    discretisation: str = "causal"  # "causal" (outputs from the sampled state) or "full" D_bl ⋆ M (5.4.1)
    motor: MotorData = field(default_factory=MotorData)
    #: computation delay in the design model, as a fraction f of the sample (issue 12, hold-aware try): the
    #: motor gets (1 − f) u_k + f u_{k−1} (a state u_{k−1} is added); 0 = the thesis' model, 0.2 = one 3 kHz
    #: base tick at 600 Hz (the mock inverter's delay), 1 = a whole sample
    input_delay: float = 0.0
    #: prewarp frequency [rad/s] of the "causal" Tustin (issue 12, hold-aware try; None = the thesis' model):
    #: the rotation by δ_1 T_s over a sample is then exact at |δ_1| = prewarp
    prewarp: float | None = None

    def __post_init__(self) -> None:
        checks = {
            "p_f": self.p_f < 0 and math.isfinite(self.p_f),
            "sigma_u": self.sigma_u > 0 and math.isfinite(self.sigma_u),
            "sigma_n": self.sigma_n > 0 and math.isfinite(self.sigma_n),
            "delta1_max": self.delta1_max > 0 and math.isfinite(self.delta1_max),
            "delta2_max": self.delta2_max > 0 and math.isfinite(self.delta2_max),
            "rate_hz": self.rate_hz > 0 and math.isfinite(self.rate_hz),
            "filter_gain": self.filter_gain > 0 and math.isfinite(self.filter_gain),
        }
        checks["discretisation"] = self.discretisation in ("full", "causal")
        f = self.input_delay
        checks["input_delay"] = 0.0 <= f <= 1.0 and (f == 0.0 or self.discretisation == "causal")
        w = self.prewarp
        checks["prewarp"] = w is None or (0 < w < math.pi * self.rate_hz and self.discretisation == "causal")
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"CurrentSpec: {bad[0]} = {getattr(self, bad[0])!r} is out of range")

    @property
    def Ts(self) -> float:
        return 1.0 / self.rate_hz

    def as_dict(self) -> dict:
        d = asdict(self)
        d["Ts"] = self.Ts
        for k in ("input_delay", "prewarp"):
            if not d[k]:
                del d[k]  # the thesis' model: artifacts as before
        return d


def cc_matrices(m: MotorData = MotorData()) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A_0, A_1, A_2, B_sc) of (6.15), with R'_r in A_0's (2,2) entry (errata)."""
    Ls, Lm, Rr, Tr = m.Ls_p, m.Lm_p, m.Rr_p, m.T_r
    A0 = np.array([[-(m.R_s + Rr) / Ls, Rr / Ls], [Rr / Lm, -Rr / Lm]], dtype=complex)
    A1 = np.array([[-1j, -1j * Lm / Ls], [0.0, 0.0]], dtype=complex)
    A2 = np.array([[0.0, 1j * Lm / (Tr * Ls)], [0.0, -1j / Tr]], dtype=complex)
    B = np.array([[1.0 / Ls], [0.0]], dtype=complex)
    return A0, A1, A2, B


def a_cc(delta1: float, delta2: float, m: MotorData = MotorData()) -> np.ndarray:
    """A_0 + δ_1 A_1 + δ_2 A_2 of (6.15) (δ_1 = ω_cc [rad/s], δ_2 = i_sq/î_mR)."""
    A0, A1, A2, _ = cc_matrices(m)
    return A0 + delta1 * A1 + delta2 * A2


def _rank_one(A: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, c) with b c = scale·A for a rank-one A, split evenly: ‖b‖ = ‖c‖ (6.16)/(6.17)."""
    U, s, Vh = np.linalg.svd(A)
    if s[1] > 1e-12 * s[0]:
        raise ValueError("A_i is not of rank one")
    r = math.sqrt(scale * s[0])
    return r * U[:, [0]], r * Vh[[0], :]


def current_plant(spec: CurrentSpec = CurrentSpec()) -> LFTPlant:
    """Continuous complex LFT plant of 6.2.2: state [ī_s; ī_m; x_f], Δ = diag(δ_1/δ_1,max, δ_2/δ_2,max).

    Channels: w_u/z_u 2 (real diagonal Δ), w_p = [ī_ref; n_m], z_p = [x_f; σ_u ū_s], y = ī_s − ī_ref + σ_n n_m,
    u = ū_s,cc.
    """
    A0, A1, A2, B = cc_matrices(spec.motor)
    b1, c1 = _rank_one(A1, spec.delta1_max)
    b2, c2 = _rank_one(A2, spec.delta2_max)
    g, pf = spec.filter_gain, spec.p_f
    A = np.zeros((3, 3), dtype=complex)
    A[:2, :2] = A0
    A[2, 0], A[2, 2] = g, pf  # ẋ_f = p_f x_f + g_f (ī_s − ī_ref)
    Bu = np.zeros((3, 2), dtype=complex)
    Bu[:2, :] = np.hstack([b1, b2])  # B_u0 (6.16)
    Cu = np.zeros((2, 3), dtype=complex)
    Cu[:, :2] = np.vstack([c1, c2])  # C_u0 (6.16)
    Bp = np.zeros((3, 2), dtype=complex)
    Bp[2, 0] = -g
    Bc = np.zeros((3, 1), dtype=complex)
    Bc[:2] = B
    return LFTPlant.from_blocks(
        A, B_u=Bu, B_p=Bp, B=Bc,
        C_u=Cu, D_uu=np.zeros((2, 2)), D_up=np.zeros((2, 2)), E_u=np.zeros((2, 1)),
        C_p=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]), D_pu=np.zeros((2, 2)), D_pp=np.zeros((2, 2)),
        E_p=np.array([[0.0], [spec.sigma_u]]),
        C=np.array([[1.0, 0.0, 0.0]]), F_u=np.zeros((1, 2)), F_p=np.array([[-1.0, spec.sigma_n]]),
        F_3=np.zeros((1, 1)),
    )  # fmt: skip


def current_plant_discrete(spec: CurrentSpec = CurrentSpec()) -> LFTPlant:
    """The plant discretised at spec.rate_hz (5.4.1), by ``spec.discretisation``:

    - ``"full"``: D_bl ⋆ M of the whole plant; y_k and z_p,k are formed from the trapezoidal state
      (ξ_k + ξ_{k+1})/2, so u_k reaches y_k directly (F_3 ≠ 0, see the module docstring);
    - ``"causal"``: D_bl ⋆ only the state and parameter rows [[A, B_u, B_p, B], [C_u, D_uu, D_up, E_u]];
      y_k and z_p,k are formed from the sampled state ξ_k = √T_s x_k (what an ADC sees at t_k, before
      u_k is applied), so F_3 = 0.
    """
    Pc = current_plant(spec)
    Ts = spec.Ts
    if spec.discretisation == "full":
        return bilinear_lft(Pc, Ts)
    n, nu = Pc.n_x, Pc.n_zu
    top = np.block([[Pc.A, Pc.B_u, Pc.B_p, Pc.B], [Pc.C_u, Pc.D_uu, Pc.D_up, Pc.E_u]])
    Md = star(d_bl(n, Ts, prewarp=spec.prewarp), Partitioned(top, n, n)).M
    nwp = Pc.n_wp
    r = math.sqrt(tustin_period(Ts, spec.prewarp))  # ξ_k = √T_s x_k is the sampled physical state (balanced D_bl)
    A, Bu, Bp, B = Md[:n, :n], Md[:n, n : n + nu], Md[:n, n + nu : n + nu + nwp], Md[:n, n + nu + nwp :]
    Cu, Duu, Dup, Eu = Md[n:, :n], Md[n:, n : n + nu], Md[n:, n + nu : n + nu + nwp], Md[n:, n + nu + nwp :]
    Cp, C = r * Pc.C_p, r * Pc.C
    f = spec.input_delay
    if f:
        # state [ξ; u_{k−1}]: the motor (and the parameter rows) see (1 − f) u_k + f u_{k−1}; z_p still σ_u u_k
        z = lambda a, b: np.zeros((a, b), dtype=complex)  # noqa: E731
        A = np.block([[A, f * B], [z(1, n), z(1, 1)]])
        Bu, Bp = np.vstack([Bu, z(1, nu)]), np.vstack([Bp, z(1, nwp)])
        B = np.vstack([(1 - f) * B, np.ones((1, 1))])
        Cu, Eu = np.hstack([Cu, f * Eu]), (1 - f) * Eu
        Cp, C = np.hstack([Cp, z(Cp.shape[0], 1)]), np.hstack([C, z(1, 1)])
    return LFTPlant.from_blocks(
        A, B_u=Bu, B_p=Bp, B=B, C_u=Cu, D_uu=Duu, D_up=Dup, E_u=Eu,
        C_p=Cp, D_pu=Pc.D_pu, D_pp=Pc.D_pp, E_p=Pc.E_p,
        C=C, F_u=Pc.F_u, F_p=Pc.F_p, F_3=Pc.F_3, dt=Ts,
    )  # fmt: skip


def normalised_delta(delta1: float, delta2: float, spec: CurrentSpec = CurrentSpec()) -> np.ndarray:
    """Δ = diag(δ_1/δ_1,max, δ_2/δ_2,max) for physical δ_1 = ω_cc [rad/s], δ_2 = i_sq/î_mR."""
    return np.diag([delta1 / spec.delta1_max, delta2 / spec.delta2_max]).astype(float)


def parameter_set() -> ParameterSet:
    """Δ̄ = Co{diag(±1, ±1)}: the four corners of the normalised δ box (5.3.3)."""
    return ParameterSet(tuple(np.diag([a, b]).astype(float) for a in (-1.0, 1.0) for b in (-1.0, 1.0)))


def delta_grid(k: int = 9) -> list[np.ndarray]:
    """A k x k grid of the normalised box (corners included), for verification."""
    xs = np.linspace(-1.0, 1.0, k)
    return [np.diag([a, b]) for a in xs for b in xs]


@dataclass(eq=False)
class CurrentControllerDesign:
    """One quasi-LPV current-controller design (6.2.2); γ for the setup above, SI units."""

    spec: CurrentSpec
    gamma_a: float
    gamma: float
    controller: ScheduledController
    plant: LFTPlant  # discrete, with its F_3 (what the controller is verified against)
    synthesis: SynthesisResult
    bisection: BisectionResult
    verification: VerificationReport | None
    full_order: int
    order_reduction: dict
    timings: dict[str, float] = field(default_factory=dict)
    lower_bound: LowerBound | None = None  # independent: worst frozen LTI optimum on a 5x5 δ grid
    rescale: str = "diagonal"  # the bisection's re-balancing (`bisect_gamma`)
    centring: str = "scaled"  # where the construction's LMI solution is centred (`design_current_controller`)
    objective: str = "trace"  # what that centring minimises (`SynthesisProblem.centered`)

    def delta(self, delta1: float, delta2: float) -> np.ndarray:
        return normalised_delta(delta1, delta2, self.spec)


def _reduction_tolerances(res: SynthesisResult, rel: float) -> list[float]:
    """rank_tol_x values for `construct_controller` that drop the eigenvalues of X − Y^{-1} below
    rel·(largest eigenvalue), the most aggressive reduction first (each tolerance lies halfway, in log
    scale, between a dropped and the next kept eigenvalue, relative to ‖X‖ as (5.32)'s code measures it)."""
    D = res.X - np.linalg.inv(res.Y)
    ev = np.sort(np.linalg.eigvalsh(0.5 * (D + D.conj().T)))
    ev = ev[ev > 0]
    nx = np.linalg.norm(res.X, 2)
    out = [math.sqrt(ev[k - 1] * ev[k]) / nx for k in range(1, len(ev)) if ev[k - 1] < rel * ev[-1]]
    return out[::-1]


def design_current_controller(
    spec: CurrentSpec = CurrentSpec(),
    *,
    backoff: float = 1.1,
    reduce_rel: float = 1e-3,
    n_grid: int = 9,
    check: bool = True,
    verify_kw: dict | None = None,
    progress: Callable[[str], None] | None = None,
    rescale: str = "diagonal",
    rescale_iters: int = 14,
    centring: str = "scaled",
    objective: str = "trace",
) -> CurrentControllerDesign:
    """Design, construct and verify the controller of 6.2.2 at γ = backoff·γ_a (raises on failure).

    ``rescale`` (issue 12): "diagonal" (default) is the re-balancing the shipped artifacts were made with;
    "full" bisects with the full re-balancing of `bisect_gamma` (state similarity + parameter-channel
    scalar), started from the independent lower bound (5 x 5 δ grid), at most ``rescale_iters`` rounds: it
    reaches the LMIs' own optimum (3 kHz: gap 1.031 instead of 1.146), but that controller is worse on the
    mock rig, whose one-tick computation delay the 6.2.2 design model leaves out (docs/results/synthesis.md
    4.0), so it is opt-in.

    The LMI solution for the construction minimises tr X + tr Y at half the maximal margin
    (`SynthesisProblem.centered(objective="trace")`): the problem is nearly singular (σ_u, σ_n tiny),
    the max-margin point has X at its bound and the App. B construction fails numerically there.
    Order reduction (6.2.2): eigenvalues of X − Y^{-1} below ``reduce_rel`` times the largest are
    dropped if the reduced controller satisfies the QMI and passes verification; otherwise the next
    larger order is tried, down to full order, which must verify. ``progress`` hears each stage.

    ``centring``: "scaled" (default; the shipped artifacts) solves that centring in the coordinates the bisection
    ended in, so the design depends on which scaling that was: on three fleet motors a 10⁻⁶ or 10⁻⁴ change of R_r
    moved the controller by 59-129 %. "balanced" solves it in its own balanced coordinates
    (`synthesis.lmi.balanced_centre`, the trace objective, a failed re-balancing step tried again from half-way):
    a design that follows its model continuously (docs/results/fleet-commission.md). ``objective``: what the
    centring minimises, "trace" (above; the shipped artifacts) or "dual" (`_centring`).
    """
    if rescale not in ("full", "diagonal"):
        raise ValueError(f"rescale must be 'full' or 'diagonal', got {rescale!r}")
    if centring not in ("scaled", "balanced"):
        raise ValueError(f"centring must be 'scaled' or 'balanced', got {centring!r}")
    if objective not in ("trace", "dual"):
        raise ValueError(f"objective must be 'trace' or 'dual', got {objective!r}")
    say = progress or (lambda stage: None)
    t: dict[str, float] = {}
    say("bisection")
    t0 = time.perf_counter()
    Pd = current_plant_discrete(spec)
    P0, F3 = remove_feedthrough(Pd)
    params = parameter_set()
    lb = lpv_lower_bound(P0, delta_grid(5))  # F_3 (D_22) does not change the optimum
    t["lower_bound"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if rescale == "full":  # issue 12: full re-balancing from the certified lower bound (the 6.2.2 γ bisection)
        bis = bisect_gamma(P0, params, rescale="full", rescale_iters=rescale_iters, lower_bound=lb.value)
    else:
        bis = bisect_gamma(P0, params)
    t["bisection"] = time.perf_counter() - t0
    t["construction"] = t["verification"] = 0.0
    centre = _centring(centring, objective, P0, params, bis.scaling)
    grid = delta_grid(n_grid)
    vkw = verify_kw or {}
    rungs: list[dict] = []
    # γ = backoff·γ_a; where no LMI solution at that γ is had for the construction (measured: a random motor,
    # R_r 0.63x, L_m 1.18x, L_σ 0.74x of (3.57), whose centring problem Clarabel calls infeasible at 1.1·γ_a) or
    # its controller does not verify, the next rung of the ladder (`synthesis.construct.BACKOFFS`)
    for bo in backoff_ladder(backoff):
        gamma = bo * bis.gamma_a
        say("construction" if not rungs else f"construction at {bo:g}·γ_a")
        try:
            ctrl, rep, res, red = _construct_at(centre, gamma, Pd, F3, grid, check, vkw, reduce_rel, t, say)
            break
        except (ConstructionError, VerificationError) as e:
            rungs.append({"backoff": bo, "result": f"rejected: {e}"})
            if bo >= max(backoff, MAX_BACKOFF):
                raise ConstructionError(f"no verified controller up to γ = {bo:g}·γ_a (γ_a = {bis.gamma_a:.4g}): "
                                        + "; ".join(r["result"] for r in rungs)) from None  # fmt: skip
    red["backoffs_rejected"] = rungs
    return CurrentControllerDesign(spec, bis.gamma_a, gamma, ctrl, Pd, res, bis, rep, P0.n_x, red, t, lb, rescale,
                                   centring, objective)  # fmt: skip


def _centring(kind: str, objective: str, P0: LFTPlant, params: ParameterSet,
              scaling: PlantScaling) -> Callable[[float, float], SynthesisResult]:
    """The LMI solution for the construction at (γ, margin fraction), minimising ``objective``: at the bisection's
    ``scaling`` ("scaled") or in its own balanced coordinates ("balanced", `design_current_controller`). "trace" is
    tr X + tr Y; "dual" is tr Y + ‖P̃‖ (`SynthesisProblem.centered`): no push towards a singular X − Y^{-1}, so a
    controller of lower gain, often of full order (in balanced coordinates 5-25x lower at 1 Hz than the trace
    objective's on two fleet motors' truths)."""
    if kind == "balanced":
        return lambda gamma, frac: balanced_centre(P0, params, gamma, scaling, margin_frac=frac, objective=objective,
                                                   max_steps=10, halvings=4)  # fmt: skip
    prob = SynthesisProblem(P0, params, scaling=scaling)
    return lambda gamma, frac: prob.centered(gamma, margin_frac=frac, objective=objective)


def _construct_at(centre: Callable[[float, float], SynthesisResult], gamma: float, Pd: LFTPlant, F3: np.ndarray,
                  grid: list, check: bool,
                  vkw: dict, reduce_rel: float, t: dict, say: Callable[[str], None]
                  ) -> tuple[ScheduledController, VerificationReport | None, SynthesisResult, dict]:  # fmt: skip
    """Construct (with order reduction, 6.2.2) and verify at one γ, from the LMI solution ``centre(γ, margin
    fraction)``; raises if no order constructs and verifies."""
    t0 = time.perf_counter()
    for frac in MARGIN_FRACTIONS:  # Clarabel sometimes fails the trace problem; then `centered` falls back
        res = centre(gamma, frac)
        if res.settings["mode"] != "feasibility":
            break
    if not res.feasible:
        t["construction"] += time.perf_counter() - t0
        raise ConstructionError(f"no LMI solution at γ = {gamma:.4g} for the construction")
    tols = _reduction_tolerances(res, reduce_rel) + [1e-8]  # the last one: full order (construct's default)
    red: dict = {"reduce_rel": reduce_rel, "tried": [], "solution": res.settings["mode"], "margin_frac": frac}
    D = res.X - np.linalg.inv(res.Y)
    red["eig_X_minus_Yinv"] = np.sort(np.linalg.eigvalsh(0.5 * (D + D.conj().T))).tolist()
    t["construction"] += time.perf_counter() - t0
    for k, tol in enumerate(tols):
        entry: dict = {"rank_tol_x": tol}
        red["tried"].append(entry)
        stage = "construction"
        t0 = time.perf_counter()
        try:
            c = construct_controller(res, feedthrough=F3, rank_tol_x=tol)
            entry["n_c"] = c.K.n_c
            t[stage] += time.perf_counter() - t0
            r = None
            if check:
                say(f"verification (order {c.K.n_c})")
                stage, t0 = "verification", time.perf_counter()
                r = verify(Pd, c, gamma, grid, **vkw)
                t[stage] += time.perf_counter() - t0
        except (ConstructionError, VerificationError) as e:
            t[stage] += time.perf_counter() - t0
            entry["result"] = f"rejected: {e}"
            if k == len(tols) - 1:  # full order must construct and verify
                raise
            continue
        entry["result"] = "accepted"
        return c, r, res, red
    raise AssertionError("unreachable: the full order either returns or raises")


def summary(d: CurrentControllerDesign, sampled_grid: tuple[int, int] | None = (9, 5)) -> dict:
    """JSON-ready numbers of a design; ``sampled_data`` (`sampled_report`) on a ``sampled_grid`` of the δ box
    (the shipped artifacts carry the 17 x 11 grid of `SAMPLED_GRID`; None leaves the report out)."""
    rep = d.verification.as_dict() if d.verification else None
    K = d.controller.K
    return dict(
        spec={k: v for k, v in d.spec.as_dict().items() if k != "motor"}, motor=d.spec.motor.as_dict(),
        gamma_a=d.gamma_a, gamma=d.gamma, thesis_gamma=THESIS_GAMMA, thesis_order=THESIS_ORDER,
        **certificate(d.lower_bound, d.gamma_a, d.gamma),
        n_c=K.n_c, full_order=d.full_order, m_c=K.n_wc, k_c=K.n_zc, order_reduction=d.order_reduction,
        bisection_iterations=d.bisection.iterations, n_solves=d.bisection.n_solves, rescale=d.rescale,
        centring=d.centring, objective=d.objective,
        lmi_settings=d.synthesis.settings, timings=d.timings, verification=rep,
        sampled_data=sampled_report(d.controller, d.spec, d.gamma, sampled_grid) if sampled_grid else None,
    )  # fmt: skip


# --------------------------------------------------------------------------------------------------
# sampled-data honesty (issue 12): the frozen loop against the exactly sampled motor
# --------------------------------------------------------------------------------------------------
#: how the controller's voltage reaches the motor between samples (see `sampled_loop`)
HOLDS: tuple[str, ...] = ("controller_frame", "stator_frame", "runtime")
#: the δ grid of `sampled_report`: δ_1 in steps of 100 rad/s, δ_2 in steps of 2 (17 x 11 points)
SAMPLED_GRID: tuple[int, int] = (17, 11)


def _voltage_pieces(hold: str, omega: float, Ts: float, base_hz: float, delay_comp: float
                    ) -> list[tuple[float, float, int, complex]]:
    """The voltage over one controller sample [t_k, t_k + T_s) in the controller frame, as pieces
    (start, length, which, factor): u_cc(t) = factor · e^{−jω(t − start)} · (u_k if which == 0 else u_{k−1}),
    times relative to t_k, for a frame turning at ω = δ_1 (frozen); "controller_frame" has no rotation
    (the caller sets ω = 0 for it)."""
    if hold == "controller_frame":
        return [(0.0, Ts, 0, 1.0)]
    if hold == "stator_frame":
        return [(0.0, Ts, 0, 1.0)]
    if hold != "runtime":
        raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
    Tb = 1.0 / base_hz
    N = round(Ts / Tb)
    if N < 1 or abs(N * Tb - Ts) > 1e-9 * Ts:
        raise ValueError(f"the controller period {Ts:g} s is not a multiple of the base period {Tb:g} s")
    # the reference of base tick j is u e^{jω(j T_b + c T_b)} (stator frame, advanced by c periods), applied
    # over [(j+1) T_b, (j+2) T_b): in the controller frame u e^{jω(c − 1) T_b} e^{−jω(t − (j+1) T_b)}
    f = complex(np.exp(1j * omega * (delay_comp - 1.0) * Tb))
    return [(i * Tb, Tb, 0 if i else 1, f) for i in range(N)]


def sampled_loop(
    controller: ScheduledController,
    spec: CurrentSpec,
    delta1: float,
    delta2: float,
    *,
    hold: str = "controller_frame",
    base_hz: float = 3000.0,
    delay_comp: float = 1.5,
) -> StateSpace:
    """The frozen performance loop of 6.2.2 with the *exactly sampled* motor (sampled-data honesty).

    The continuous set-up of `current_plant` (motor (6.15) at frozen δ_1 = ω_cc, δ_2 plus the error filter
    W(s) = g_f/(s − p_f)) is sampled exactly (matrix exponentials): the exogenous [ī_ref; n_m] are held
    over the controller sample in the controller frame, y_k = ī_s(t_k) − ī_ref,k + σ_n n_m,k and
    z_k = [x_f(t_k); σ_u u_k]; the frozen controller ``controller.frozen(Δ)`` closes the loop. The voltage:

    - ``"controller_frame"``: u_k held in the controller (rotor-flux) frame over [t_k, t_k+1), no delay
      (the Fig. 6.1 simulation);
    - ``"stator_frame"``: u_k held in the stator frame (it turns by −ω_cc T_s in the controller frame over
      the sample), no delay;
    - ``"runtime"``: what the FOC and the mock inverter do: u_k is held in the controller frame and
      re-rotated every base tick (``base_hz``) with an angle advance of ``delay_comp`` base periods; each
      reference is applied one base tick later, held in the stator frame (`mock_hw.inverter`). At the base
      rate (3 kHz) this is the stator-frame hold plus a one-sample delay.

    Inputs [ī_ref; n_m], outputs z_p; state [ī_s; ī_m; x_f; (u_{k−1} for "runtime"); x_c].
    """
    import scipy.linalg as sla

    Sc = current_plant(spec).frozen(normalised_delta(delta1, delta2, spec))
    A, B = Sc.A, Sc.B  # inputs [ī_ref, n_m, u]
    Ts, n = spec.Ts, Sc.A.shape[0]
    omega = float(delta1)
    E = sla.expm(np.block([[A, B[:, :2]], [np.zeros((2, n + 2))]]) * Ts)
    Phi, Gw = E[:n, :n], E[:n, n:]
    runtime = hold == "runtime"
    Gu = [np.zeros((n, 1), complex), np.zeros((n, 1), complex)]  # coefficients of u_k and u_{k−1}
    pieces = _voltage_pieces(hold, omega, Ts, base_hz, delay_comp)
    rot = 0.0 if hold == "controller_frame" else omega
    for start, length, which, fac in pieces:
        Mx = np.zeros((n + 1, n + 1), complex)
        Mx[:n, :n], Mx[:n, n:] = A, B[:, 2:]
        Mx[n, n] = -1j * rot
        Ep = sla.expm(Mx * length)
        # the piece's effect at t_k + T_s: propagate from its end to the end of the sample
        Gu[which] += sla.expm(A * (Ts - start - length)) @ (Ep[:n, n:] * fac)
    K = controller.frozen(normalised_delta(delta1, delta2, spec))
    C, D = Sc.C, Sc.D
    Cy, Dyw = C[[2]], D[[2], :2]
    Cz, Dzw, Dzu = C[:2], D[:2, :2], D[:2, [2]]
    nc, ne = K.A.shape[0], (1 if runtime else 0)
    # u_k = K.C x_c + K.D y_k,  y_k = Cy x_k + Dyw w_k
    N = n + ne + nc
    Acl = np.zeros((N, N), complex)
    Bcl = np.zeros((N, 2), complex)
    Gk = Gu[0]
    Acl[:n, :n] = Phi + Gk @ K.D @ Cy
    Acl[:n, n + ne :] = Gk @ K.C
    Bcl[:n] = Gw + Gk @ K.D @ Dyw
    if runtime:
        Acl[:n, n : n + 1] = Gu[1]
        Acl[n, :n] = (K.D @ Cy)[0]
        Acl[n, n + ne :] = K.C[0]
        Bcl[n] = (K.D @ Dyw)[0]
    Acl[n + ne :, :n] = K.B @ Cy
    Acl[n + ne :, n + ne :] = K.A
    Bcl[n + ne :] = K.B @ Dyw
    Ccl = np.zeros((2, N), complex)
    Ccl[:, :n] = Cz + Dzu @ K.D @ Cy
    Ccl[:, n + ne :] = Dzu @ K.C
    Dcl = Dzw + Dzu @ K.D @ Dyw
    return StateSpace(Acl, Bcl, Ccl, Dcl, Ts)


def sampled_hinf(controller: ScheduledController, spec: CurrentSpec, delta1: float, delta2: float,
                 **kw: object) -> tuple[float, float, float]:
    """(‖z/w‖_∞, θ_peak [rad/sample], spectral radius) of `sampled_loop` (∞ if unstable)."""
    S = sampled_loop(controller, spec, delta1, delta2, **kw)  # type: ignore[arg-type]
    rho = float(np.max(np.abs(np.linalg.eigvals(S.A))))
    if rho >= 1.0:
        return math.inf, math.nan, rho
    g, th = hinf_norm(S)
    return float(g), float(th), rho


def sampled_report(controller: ScheduledController, spec: CurrentSpec, gamma: float,
                   grid: tuple[int, int] = SAMPLED_GRID, holds: Sequence[str] = HOLDS) -> dict:
    """Max of `sampled_hinf` over a grid of the δ box (``grid`` = points in δ_1, δ_2), per hold, next to γ."""
    d1s = np.linspace(-spec.delta1_max, spec.delta1_max, grid[0])
    d2s = np.linspace(-spec.delta2_max, spec.delta2_max, grid[1])
    out: dict = {"gamma": gamma, "grid": {"delta1": [float(d1s[0]), float(d1s[-1]), len(d1s)],
                                          "delta2": [float(d2s[0]), float(d2s[-1]), len(d2s)]},
                 "definition": "frozen H-infinity norm of the 6.2.2 performance loop against the ZOH-sampled motor "
                               "(synthesis.models.current_controller.sampled_hinf), max over the delta grid; "
                               "gamma bounds the Tustin design model only"}  # fmt: skip
    for hold in holds:
        best = (-1.0, 0.0, 0.0, 0.0, 0.0)
        for a in d1s:
            for b in d2s:
                g, th, rho = sampled_hinf(controller, spec, float(a), float(b), hold=hold)
                if g > best[0]:
                    best = (g, float(a), float(b), th, rho)
        g, a, b, th, rho = best
        out[hold] = dict(hinf_max=g, at_delta1=a, at_delta2=b, ratio_to_gamma=g / gamma,
                         peak_hz=abs(th) / (2 * math.pi * spec.Ts) if math.isfinite(th) else None,
                         spectral_radius=rho)  # fmt: skip
    return out


def sampled_time_gain(
    controller: ScheduledController,
    spec: CurrentSpec,
    delta1: float,
    delta2: float,
    theta: float,
    *,
    hold: str = "controller_frame",
    samples: int = 1000,
    tail: int = 200,
    substeps: int = 10,
    base_hz: float = 3000.0,
    delay_comp: float = 1.5,
) -> float:
    """Independent check of `sampled_hinf`: the l2 gain measured in a time-domain simulation.

    The motor (6.15) is integrated in the *stator* frame by RK4 (``substeps`` per base period), the frame
    turning at ω = δ_1 (frozen), the error filter in the controller frame; the controller is the
    sample-by-sample scheduled runtime (`LPVRuntime`, 5.4.4) at constant Δ; the voltage reaches the motor
    as ``hold`` says (`sampled_loop`); ī_ref,k = e^{jθk} held over the sample, n_m = 0. Returns
    sqrt(Σ|z_k|² / Σ|ī_ref,k|²) over the last ``tail`` samples (after the transient), which cannot exceed
    the H∞ norm and reaches |G(e^{jθ})| e_1 at the peak frequency.
    """
    Ts = spec.Ts
    D = normalised_delta(delta1, delta2, spec)
    A = a_cc(delta1, delta2, spec.motor)
    w = float(delta1)
    As = A + 1j * w * np.eye(2)  # stator frame: x_s = e^{jωt} x_cc
    a00, a01, a10, a11 = (complex(v) for v in As.ravel())
    b0 = complex(cc_matrices(spec.motor)[3][0, 0])
    pf, gf = spec.p_f, spec.filter_gain
    if hold == "runtime":
        Tb = 1.0 / base_hz
        N = round(Ts / Tb)
    else:
        Tb, N = Ts, 1
    h = Tb / substeps
    rt = controller.runtime()
    s0 = s1 = 0j  # stator-frame currents
    xf = 0j
    applied = 0j  # runtime: the stator-frame reference latched for the current base period
    zz = ww = 0.0

    def f(t: float, s0: complex, s1: complex, xf: complex, us: complex, iref: complex) -> tuple[complex, ...]:
        rot = complex(np.cos(w * t), -np.sin(w * t))  # e^{−jωt}
        return (a00 * s0 + a01 * s1 + b0 * us, a10 * s0 + a11 * s1, pf * xf + gf * (s0 * rot - iref))

    for k in range(samples):
        tk = k * Ts
        iref = complex(np.exp(1j * theta * k))
        rot_k = complex(np.exp(-1j * w * tk))
        y = s0 * rot_k - iref
        u = complex(rt.step([y], D)[0])
        if k >= samples - tail:
            zz += abs(xf) ** 2 + abs(spec.sigma_u * u) ** 2
            ww += abs(iref) ** 2
        for j in range(N):
            t0 = tk + j * Tb
            if hold == "runtime":
                # reference of this tick (u held in the controller frame, re-rotated, advanced), applied next tick
                nxt = u * complex(np.exp(1j * w * (t0 + delay_comp * Tb)))
                us_fn = lambda tt, v=applied: v  # noqa: E731
            elif hold == "stator_frame":
                us_fn = lambda tt, v=u * complex(np.exp(1j * w * tk)): v  # noqa: E731
            else:
                us_fn = lambda tt, v=u: v * complex(np.cos(w * tt), np.sin(w * tt))  # noqa: E731
            for i in range(substeps):
                ta = t0 + i * h
                k1 = f(ta, s0, s1, xf, us_fn(ta), iref)
                k2 = f(ta + h / 2, s0 + h / 2 * k1[0], s1 + h / 2 * k1[1], xf + h / 2 * k1[2], us_fn(ta + h / 2), iref)
                k3 = f(ta + h / 2, s0 + h / 2 * k2[0], s1 + h / 2 * k2[1], xf + h / 2 * k2[2], us_fn(ta + h / 2), iref)
                k4 = f(ta + h, s0 + h * k3[0], s1 + h * k3[1], xf + h * k3[2], us_fn(ta + h), iref)
                s0 += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
                s1 += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
                xf += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
            if hold == "runtime":
                applied = nxt
    return math.sqrt(zz / ww)


def artifact_certificate(ctrl_doc: dict) -> dict:
    """The `[lower bound, γ_a, γ]` record (`synthesis.lower_bound.certificate`, issue 12) of an artifact's JSON
    document: the independent lower bound (worst frozen Riccati optimum, 5 x 5 δ grid, as `design_current_controller`)
    on the plant rebuilt from the artifact's spec (6.2.2), next to its γ_a and γ."""
    meta = ctrl_doc["meta"]
    spec = CurrentSpec(**{k: v for k, v in meta["spec"].items() if k != "Ts"})
    P0, _ = remove_feedthrough(current_plant_discrete(spec))
    return certificate(lpv_lower_bound(P0, delta_grid(5)), float(meta["gamma_a"]), float(ctrl_doc["gamma"]))


def gamma_evidence(rate_hz: float = 600.0) -> dict:
    """Numbers behind the comparison with the thesis' γ = 0.0011 (docs/RESULTS.md), as JSON-ready dict:

    - γ_a for both discretisations and both readings of the error filter (g_f = 1, g_f = −p_f);
    - the frozen-parameter LTI optimum (Thm 5.15 with an empty parameter set on the plant at a fixed δ)
      at the centre and the four corners of the δ box: a lower bound of the LPV γ_a;
    - γ_a with the variables' bound 1e4 and 1e8 instead of 1e6 (the numerics that moved the flux
      observer's γ_a, 5.6.2).
    """
    out: dict = {"rate_hz": rate_hz, "gamma_a": {}, "frozen_lti_gamma_a": {}, "bound_sensitivity": {}}
    for disc in ("causal", "full"):
        for g in (1.0, 100.0):
            spec = CurrentSpec(rate_hz=rate_hz, discretisation=disc, filter_gain=g)
            P0, _ = remove_feedthrough(current_plant_discrete(spec))
            out["gamma_a"][f"{disc}, g_f={g:g}"] = bisect_gamma(P0, parameter_set()).gamma_a
        spec = CurrentSpec(rate_hz=rate_hz, discretisation=disc)
        Pd = current_plant_discrete(spec)
        lti = {}
        for d in ((0.0, 0.0), (1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
            Pf, _ = remove_feedthrough(Pd.at(np.diag(d)))
            lti[f"{d[0]:+g},{d[1]:+g}"] = bisect_gamma(Pf, _PS.empty()).gamma_a
        out["frozen_lti_gamma_a"][disc] = lti
    P0, _ = remove_feedthrough(current_plant_discrete(CurrentSpec(rate_hz=rate_hz)))
    for bound in (1e4, 1e8):
        out["bound_sensitivity"][f"causal, bound={bound:g}"] = bisect_gamma(
            P0, parameter_set(), x_bound=bound, mult_bound=bound).gamma_a
    return out


if __name__ == "__main__":
    import json
    import sys
    import warnings

    warnings.simplefilter("ignore")
    if len(sys.argv) > 2 and sys.argv[1] == "certificate":
        # python -m synthesis.models.current_controller certificate ARTIFACT [--write]: gamma_lower_bound, gap,
        # gammas of a 6.2.2 artifact made before the designs carried them; --write stores them in its JSON's meta
        # (not under the artifact's SHA-256, which is the npz's)
        from pathlib import Path

        from synthesis.artifacts import _jsonable, load_controller

        _, doc = load_controller(sys.argv[2])
        cert = _jsonable(artifact_certificate(doc))
        print(json.dumps({k: v for k, v in cert.items() if k != "lower_bound"}, indent=2))
        if "--write" in sys.argv[3:]:
            js = Path(sys.argv[2]).with_suffix(".json")
            full = json.loads(js.read_text())
            full["meta"].update(cert)
            js.write_text(json.dumps(full, indent=2, sort_keys=True))
    elif len(sys.argv) > 2 and sys.argv[1] == "sampled":
        # python -m synthesis.models.current_controller sampled ARTIFACT [--write]: the sampled-data report of
        # an artifact (its JSON's meta.spec, gamma); --write stores it as meta.sampled_data (the JSON is not
        # covered by the artifact's SHA-256, which is the npz's)
        from pathlib import Path

        from synthesis.artifacts import load_controller

        ctrl, doc = load_controller(sys.argv[2])
        spec = CurrentSpec(**{k: v for k, v in doc["meta"]["spec"].items() if k != "Ts"})
        rep = sampled_report(ctrl, spec, float(doc["gamma"]))
        print(json.dumps(rep, indent=2))
        if "--write" in sys.argv[3:]:
            js = Path(sys.argv[2]).with_suffix(".json")
            full = json.loads(js.read_text())
            full["meta"]["sampled_data"] = rep
            js.write_text(json.dumps(full, indent=2, sort_keys=True))
    else:
        print(json.dumps(gamma_evidence(float(sys.argv[1]) if len(sys.argv) > 1 else 600.0), indent=2))
