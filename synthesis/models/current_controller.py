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
from typing import Callable

import numpy as np

from synthesis.construct import ConstructionError, ScheduledController, construct_controller
from synthesis.discretize import bilinear_lft, d_bl
from synthesis.lft import LFTPlant, Partitioned, remove_feedthrough, star
from synthesis.lmi import BisectionResult, ParameterSet, SynthesisProblem, SynthesisResult, bisect_gamma
from synthesis.lower_bound import LowerBound, certificate, lpv_lower_bound
from synthesis.models.motor import MotorData
from synthesis.verify import VerificationError, VerificationReport, verify

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
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"CurrentSpec: {bad[0]} = {getattr(self, bad[0])!r} is out of range")

    @property
    def Ts(self) -> float:
        return 1.0 / self.rate_hz

    def as_dict(self) -> dict:
        d = asdict(self)
        d["Ts"] = self.Ts
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
    Md = star(d_bl(n, Ts), Partitioned(top, n, n)).M
    nwp = Pc.n_wp
    r = math.sqrt(Ts)  # ξ_k = √T_s x_k is the sampled physical state (balanced D_bl)
    return LFTPlant.from_blocks(
        Md[:n, :n], B_u=Md[:n, n : n + nu], B_p=Md[:n, n + nu : n + nu + nwp], B=Md[:n, n + nu + nwp :],
        C_u=Md[n:, :n], D_uu=Md[n:, n : n + nu], D_up=Md[n:, n + nu : n + nu + nwp], E_u=Md[n:, n + nu + nwp :],
        C_p=r * Pc.C_p, D_pu=Pc.D_pu, D_pp=Pc.D_pp, E_p=Pc.E_p,
        C=r * Pc.C, F_u=Pc.F_u, F_p=Pc.F_p, F_3=Pc.F_3, dt=Ts,
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
) -> CurrentControllerDesign:
    """Design, construct and verify the controller of 6.2.2 at γ = backoff·γ_a (raises on failure).

    The LMI solution for the construction minimises tr X + tr Y at half the maximal margin
    (`SynthesisProblem.centered(objective="trace")`): the problem is nearly singular (σ_u, σ_n tiny),
    the max-margin point has X at its bound and the App. B construction fails numerically there.
    Order reduction (6.2.2): eigenvalues of X − Y^{-1} below ``reduce_rel`` times the largest are
    dropped if the reduced controller satisfies the QMI and passes verification; otherwise the next
    larger order is tried, down to full order, which must verify. ``progress`` hears each stage.
    """
    say = progress or (lambda stage: None)
    t: dict[str, float] = {}
    say("bisection")
    t0 = time.perf_counter()
    Pd = current_plant_discrete(spec)
    P0, F3 = remove_feedthrough(Pd)
    params = parameter_set()
    bis = bisect_gamma(P0, params)
    t["bisection"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lb = lpv_lower_bound(P0, delta_grid(5))  # F_3 (D_22) does not change the optimum
    t["lower_bound"] = time.perf_counter() - t0
    gamma = backoff * bis.gamma_a
    say("construction")
    t0 = time.perf_counter()
    prob = SynthesisProblem(P0, params, scaling=bis.scaling)
    for frac in MARGIN_FRACTIONS:  # Clarabel sometimes fails the trace problem; then `centered` falls back
        res = prob.centered(gamma, margin_frac=frac, objective="trace")
        if res.settings["mode"] != "feasibility":
            break
    if not res.feasible:
        raise ConstructionError(f"no LMI solution at γ = {gamma:.4g} for the construction")
    tols = _reduction_tolerances(res, reduce_rel) + [1e-8]  # the last one: full order (construct's default)
    grid = delta_grid(n_grid)
    vkw = verify_kw or {}
    red: dict = {"reduce_rel": reduce_rel, "tried": [], "solution": res.settings["mode"], "margin_frac": frac}
    D = res.X - np.linalg.inv(res.Y)
    red["eig_X_minus_Yinv"] = np.sort(np.linalg.eigvalsh(0.5 * (D + D.conj().T))).tolist()
    ctrl = rep = None
    t["construction"] = time.perf_counter() - t0
    t["verification"] = 0.0
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
        ctrl, rep = c, r
        break
    return CurrentControllerDesign(spec, bis.gamma_a, gamma, ctrl, Pd, res, bis, rep, P0.n_x, red, t, lb)


def summary(d: CurrentControllerDesign) -> dict:
    """JSON-ready numbers of a design."""
    rep = d.verification.as_dict() if d.verification else None
    K = d.controller.K
    return dict(
        spec={k: v for k, v in d.spec.as_dict().items() if k != "motor"}, motor=d.spec.motor.as_dict(),
        gamma_a=d.gamma_a, gamma=d.gamma, thesis_gamma=THESIS_GAMMA, thesis_order=THESIS_ORDER,
        **certificate(d.lower_bound, d.gamma_a, d.gamma),
        n_c=K.n_c, full_order=d.full_order, m_c=K.n_wc, k_c=K.n_zc, order_reduction=d.order_reduction,
        bisection_iterations=d.bisection.iterations, n_solves=d.bisection.n_solves,
        lmi_settings=d.synthesis.settings, timings=d.timings, verification=rep,
    )  # fmt: skip


def gamma_evidence(rate_hz: float = 600.0) -> dict:
    """Numbers behind the comparison with the thesis' γ = 0.0011 (docs/RESULTS.md), as JSON-ready dict:

    - γ_a for both discretisations and both readings of the error filter (g_f = 1, g_f = −p_f);
    - the frozen-parameter LTI optimum (Thm 5.15 with an empty parameter set on the plant at a fixed δ)
      at the centre and the four corners of the δ box: a lower bound of the LPV γ_a;
    - γ_a with the variables' bound 1e4 and 1e8 instead of 1e6 (the numerics that moved the flux
      observer's γ_a, 5.6.2).
    """
    from synthesis.lmi import ParameterSet as _PS

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
    print(json.dumps(gamma_evidence(float(sys.argv[1]) if len(sys.argv) > 1 else 600.0), indent=2))
