"""The LPV speed controller of thesis 6.4.3 and its robust version of 7.2: set-up, design, verification.

Starting point: the quasi-LPV LFT of the NARX MLP (`synthesis.mlp_lft.MLPLFT`, 600 Hz, scaled signals,
state x = [w_k .. w_{k-3}, d_{k-1}, tau_{k-1}] - x°, input [i_k, d_k, tau_k] - u°, output w_k - w°), reduced
to the residual gains with the largest sector widths (`MLPLFT.widest`, the thesis keeps two; the others sit
at their sector centre). Fig. 6.13 builds the synthesis set-up around it:

* **i_mR observer** (6.29) di_mR/dt = (R_r/L_r)(i_sd - i_mR) with i_sd replaced by i_sd,ref, discretised
  exactly (zero-order hold) at the model's rate and written in the model's scaled units:
  i~_{k+1} = a_i i~_k + (1 - a_i)(s_d/s_i) d~_k, a_i = exp(-T_s R_r/L_r) (the operating point must have
  i_mR0 = i_sd,ref0, an equilibrium of (6.29); `Scaling.fit`'s default does). Its state replaces the model's
  input i_k, so the control inputs are u = [d~, tau~] (scaled i_sd,ref and i_tau = i_sq,ref i_mR).
* **performance filter** f_p, first order with a 5 Hz bandwidth, on the error e = w~ - w~_ref, discretised
  by zero-order hold: x_f,k+1 = a_f x_f,k + g (1 - a_f) e_k, z_p1 = x_f,k, a_f = exp(-2 pi 5 T_s). The thesis
  gives only the bandwidth. ``filter_reading="dc"`` (default) reads it as the unit-DC-gain low-pass
  w_p/(s + w_p) (g = 1); ``"pole"`` as 1/(s + w_p) (g = 1/w_p), the reading the current controller's
  "filter with a pole in p_f" takes in `synthesis.models.current_controller`. docs/RESULTS.md reports both.
* **measurement noise** w_n added to the fed-back error: y = e + s_n w_n, s_n = noise_rad_s / s_w (the
  thesis: "variance 0.5 s_w^{-1}", read as a 0.5 rad/s noise in scaled units, the bound 7.2 uses).
* **penalty** z_p2 = rho_d d~ on the scaled i_sd,ref (rho_d = 1): the design then leaves d~ ~ 0 and the
  runtime replaces it by the traditional P controller of i_mR (4.2.2), as the thesis does.

Performance input w_p = [w~_ref - w°; w_n], output z_p = [x_f; rho_d d~], index the l2 gain < gamma.
The plant has 8 states (4 speeds, 2 input delays, observer, filter: the thesis' "eighth order model"),
F_3 = 0 (y_k is formed from the state), and a real diagonal Delta = diag(delta_j), |delta_j| <= 1.

Design (`design_speed_controller`): gamma_a by bisection (`synthesis.lmi.bisect_gamma`, Thm 5.15 with
full-block multipliers on the 2^m corners of the box), the LTI bound "ignoring the residual gains"
(Delta = 0, no parameter channel), construction at backoff * gamma_a (`synthesis.construct`) and
independent verification on a grid of the box (`synthesis.verify`; a failure raises). The robust version
(`design_robust_speed_controller`) runs the epsilon iteration of 7.2 (`synthesis.robust.robust_iteration`)
for a bound e_bar on the scheduling error and constructs the controller of Thm 7.1.

`runtime_data` is what a run-time implementation needs besides the controller matrices (scaling,
equilibrium, the scheduling map xi = C_u x + E_u u and the residual functions), stored in the artifact's
JSON; `ScheduledSpeedLaw`/`narx_closed_loop` are the numpy reference implementation of the run-time
scheduling (thesis 6.4.3: the algebraic loop broken with u_{k-1}) and a closed loop with the MLP itself as
plant, used by the tests and the robust comparison.

Nothing here imports `bench` or `mock_hw`.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from synthesis.construct import ConstructionError, ScheduledController, construct_controller
from synthesis.lft import LFTPlant
from synthesis.lmi import BisectionResult, ParameterSet, SynthesisProblem, SynthesisResult, bisect_gamma
from synthesis.lower_bound import LowerBound, certificate, lpv_lower_bound
from synthesis.mlp_lft import MLPLFT, lft_from_model
from synthesis.models.motor import MotorData
from synthesis.narx import NarxModel, load_model
from synthesis.verify import VerificationError, VerificationReport, verify, frozen_closed_loop, hinf_norm
from synthesis.robust import construct_robust_controller, robust_iteration, verify_robust

__all__ = [
    "THESIS",
    "SpeedSpec",
    "spec_from_dict",
    "observer_coefficients",
    "controller_poles",
    "speed_plant",
    "SpeedControllerDesign",
    "design_speed_controller",
    "RobustSpeedDesign",
    "design_robust_speed_controller",
    "runtime_data",
    "ScheduledSpeedLaw",
    "narx_closed_loop",
    "NarxLoopResult",
    "sampled_plant",
    "sampled_report",
]

#: 6.4.3 and 7.2
THESIS: dict[str, Any] = {
    "gamma_lmi": 0.016, "gamma_constructed": 0.018, "gamma_ignoring_residual_gains": 0.011,
    "robust": {"gamma_nominal": 0.018, "gamma_robust": 0.034, "eps": [0.15, 0.16], "r": [3.8, 3.0],
               "rt": [4.0, 10.7], "e_bar": [0.031, 0.025]},
}  # fmt: skip
#: gamma / gamma_a tried in order for the construction (the thesis: 0.018/0.016 = 1.125)
BACKOFFS: tuple[float, ...] = (1.1, 1.25, 1.5, 2.0, 3.0)
#: (objective, margin fraction) tried in order for the solution the construction starts from
CENTERINGS: tuple[tuple[str, float], ...] = (("dual", 0.5), ("trace", 0.5), ("dual", 0.2), ("trace", 0.2),
                                             ("trace", 0.05))  # fmt: skip


@dataclass(frozen=True)
class SpeedSpec:
    """The set-up of Fig. 6.13 (SI units where physical)."""

    filter_hz: float = 5.0  # bandwidth of f_p [Hz]
    filter_reading: str = "dc"  # "dc": w_p/(s + w_p); "pole": 1/(s + w_p)
    noise_rad_s: float = 0.5  # measurement noise on the fed-back error [rad/s]
    penalty_d: float = 1.0  # weight of the scaled i_sd,ref in z_p2
    n_gains: int = 2  # residual gains kept (largest sector widths)
    motor: MotorData = field(default_factory=MotorData)  # R_r/L_r of the observer (6.29)

    def __post_init__(self) -> None:
        checks = {
            "filter_hz": self.filter_hz > 0 and math.isfinite(self.filter_hz),
            "filter_reading": self.filter_reading in ("dc", "pole"),
            "noise_rad_s": self.noise_rad_s >= 0 and math.isfinite(self.noise_rad_s),
            "penalty_d": self.penalty_d > 0 and math.isfinite(self.penalty_d),
            "n_gains": isinstance(self.n_gains, int) and self.n_gains >= 0,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"SpeedSpec: {bad[0]} = {getattr(self, bad[0])!r} is out of range")

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["motor"] = self.motor.as_dict()
        return d


def spec_from_dict(d: dict[str, Any]) -> SpeedSpec:
    """The inverse of `SpeedSpec.as_dict` (e.g. from an artifact's JSON)."""
    kw = {k: v for k, v in d.items() if k in SpeedSpec.__dataclass_fields__ and k != "motor"}
    return SpeedSpec(**kw, motor=MotorData(**d["motor"]) if "motor" in d else MotorData())


def observer_coefficients(lft: MLPLFT, motor: MotorData) -> tuple[float, float]:
    """(a_i, b_i) of the scaled, discretised observer (6.29): i~_{k+1} = a_i i~_k + b_i d~_k.

    Exact zero-order-hold discretisation of di_mR/dt = (R_r/L_r)(i_sd,ref - i_mR) at the model's rate.
    Raises ValueError unless the operating point is an equilibrium of (6.29) (u° consistent).
    """
    sc, T = lft.scaling, float(lft.plant.dt)
    a = math.exp(-T * motor.R_r / motor.L_r)
    b = (1.0 - a) * sc.sigma_d / sc.sigma_i
    # equilibrium: i~° = (s_d d~° + i_sd,ref0 - i_mR0)/s_i must equal the LFT's u°[0]
    i_eq = (sc.sigma_d * lft.u0[1] + sc.i_sd_ref0 - sc.i_mR0) / sc.sigma_i
    if abs(i_eq - lft.u0[0]) > 1e-9 * max(1.0, abs(i_eq)):
        raise ValueError(f"the LFT's input equilibrium {lft.u0.tolist()} is not an equilibrium of the i_mR "
                         f"observer (6.29) (needs i~° = {i_eq:.6g})")  # fmt: skip
    return a, b


def _filter(spec: SpeedSpec, T: float) -> tuple[float, float]:
    """(a_f, g_f (1 - a_f)) of the zero-order-hold f_p."""
    wp = 2.0 * math.pi * spec.filter_hz
    a = math.exp(-wp * T)
    g = 1.0 if spec.filter_reading == "dc" else 1.0 / wp
    return a, g * (1.0 - a)


def speed_plant(lft: MLPLFT, spec: SpeedSpec = SpeedSpec()) -> LFTPlant:
    """The synthesis set-up of Fig. 6.13 around ``lft`` (all of its residual gains; reduce it first).

    State [x (model), i~ (observer), x_f (filter)]; w_u/z_u the residual gains; w_p = [w~_ref - w°; w_n];
    z_p = [x_f; rho_d d~]; u = [d~, tau~] - u°[1:]; y = w~ - w~_ref + s_n w_n. Discrete at the model's rate.
    """
    p = lft.plant
    if p.n_u != 3 or p.n_y != 1:
        raise ValueError("expected the NARX LFT with inputs [i, d, tau] and output w")
    T = float(p.dt)
    a_i, b_i = observer_coefficients(lft, spec.motor)
    a_f, b_f = _filter(spec, T)
    s_n = spec.noise_rad_s / lft.scaling.sigma_omega
    n, m = p.n_x, p.n_wu
    N = n + 2
    A = np.zeros((N, N))
    A[:n, :n] = p.A
    A[:n, n] = p.B[:, 0]  # the model's i_k input is the observer state
    A[n, n] = a_i  # (6.29)
    A[n + 1, :n] = b_f * p.C[0]  # x_f+ = a_f x_f + g(1 - a_f)(w - w_ref)
    A[n + 1, n + 1] = a_f
    B_u = np.zeros((N, m))
    B_u[:n] = p.B_u
    B_p = np.zeros((N, 2))
    B_p[n + 1, 0] = -b_f
    B = np.zeros((N, 2))
    B[:n] = p.B[:, 1:]
    B[n, 0] = b_i
    C_u = np.zeros((m, N))
    C_u[:, :n] = p.C_u
    C_u[:, n] = p.E_u[:, 0]
    C_p = np.zeros((2, N))
    C_p[0, n + 1] = 1.0
    E_p = np.array([[0.0, 0.0], [spec.penalty_d, 0.0]])
    C = np.zeros((1, N))
    C[0, :n] = p.C[0]
    return LFTPlant.from_blocks(
        A, B_u=B_u, B_p=B_p, B=B,
        C_u=C_u, D_uu=np.zeros((m, m)), D_up=np.zeros((m, 2)), E_u=p.E_u[:, 1:],
        C_p=C_p, D_pu=np.zeros((2, m)), D_pp=np.zeros((2, 2)), E_p=E_p,
        C=C, F_u=np.zeros((1, m)), F_p=np.array([[-1.0, s_n]]), F_3=np.zeros((1, 2)), dt=T,
    )  # fmt: skip


def sampled_plant(lft: MLPLFT, spec: SpeedSpec = SpeedSpec()) -> LFTPlant:
    """The Fig. 6.13 set-up assembled from the *exactly sampled* continuous parts (sampled-data honesty).

    There is no continuous plant to discretise in the speed design: the NARX model (6.4.2) is identified in
    discrete time from the rig's own data, sampled at the model's rate with the rig's hold and delays
    (`bench collect narx`), so it already is the sampled model. The two continuous parts are the i_mR
    observer (6.29) with i_sd,ref held over the sample, and the performance filter f_p with the sampled error
    held. Here both are sampled by ``scipy.signal.cont2discrete(method="zoh")`` from their continuous
    state-space forms (in the model's scaled units) and put in place of `speed_plant`'s coefficients; the
    result equals `speed_plant` to round-off (test), i.e. the design model is its own exactly sampled model.
    """
    from scipy.signal import cont2discrete

    P = speed_plant(lft, spec)
    T = float(lft.plant.dt)
    n = lft.plant.n_x
    sc = lft.scaling
    a = spec.motor.R_r / spec.motor.L_r
    # (6.29) scaled: d i~/dt = a((s_d/s_i) d~ − i~) (about the equilibrium)
    Ao, Bo, *_ = cont2discrete((np.array([[-a]]), np.array([[a * sc.sigma_d / sc.sigma_i]]), np.eye(1),
                                np.zeros((1, 1))), T, method="zoh")  # fmt: skip
    wp = 2.0 * math.pi * spec.filter_hz
    g = 1.0 if spec.filter_reading == "dc" else 1.0 / wp
    # f_p: dx_f/dt = −w_p x_f + g w_p e
    Af, Bf, *_ = cont2discrete((np.array([[-wp]]), np.array([[g * wp]]), np.eye(1), np.zeros((1, 1))), T,
                               method="zoh")  # fmt: skip
    A, B, B_p = P.A.copy(), P.B.copy(), P.B_p.copy()
    A[n, n], B[n, 0] = Ao[0, 0], Bo[0, 0]
    A[n + 1, n + 1] = Af[0, 0]
    A[n + 1, :n] = Bf[0, 0] * lft.plant.C[0]
    B_p[n + 1, 0] = -Bf[0, 0]
    return LFTPlant.from_blocks(
        A, B_u=P.B_u, B_p=B_p, B=B, C_u=P.C_u, D_uu=P.D_uu, D_up=P.D_up, E_u=P.E_u,
        C_p=P.C_p, D_pu=P.D_pu, D_pp=P.D_pp, E_p=P.E_p, C=P.C, F_u=P.F_u, F_p=P.F_p, F_3=P.F_3, dt=T,
    )  # fmt: skip


def sampled_report(controller: ScheduledController, lft: MLPLFT, spec: SpeedSpec, gamma: float, k: int = 5) -> dict:
    """The sampled-data report of a speed design, in the shape of the flux observer's and the current
    controller's: the max frozen H∞ norm over a k^m grid of the Δ box on the design model and on
    `sampled_plant`, next to γ, and the largest difference of the two plants' matrices."""
    kept = lft.widest(spec.n_gains)
    P, Ps = speed_plant(kept, spec), sampled_plant(kept, spec)
    m = P.n_wu
    grid = _box_grid(m, k) if m else [np.zeros((0, 0))]
    out: dict = {"gamma": gamma, "grid": {"points_per_gain": k, "n_gains": m},
                 "definition": "the Fig. 6.13 model is discrete by construction (NARX identified from data sampled at "
                               "its rate; (6.29) and f_p by exact ZOH): frozen H-infinity norm on the design model and "
                               "on synthesis.models.speed_controller.sampled_plant (continuous parts sampled by scipy "
                               "cont2discrete zoh), max over the Delta grid",
                 "plant_max_abs_diff": float(np.max(np.abs(P.M - Ps.M)))}  # fmt: skip
    for key, plant in (("design_model", P), ("sampled_model", Ps)):
        best = (-1.0, None)
        for D in grid:
            S = frozen_closed_loop(plant, controller, D)
            g = hinf_norm(S)[0] if np.max(np.abs(np.linalg.eigvals(S.A))) < 1.0 else math.inf
            if g > best[0]:
                best = (g, np.diag(D).tolist())
        out[key] = dict(hinf_max=best[0], at_delta=best[1], ratio_to_gamma=best[0] / gamma)
    return out


# --------------------------------------------------------------------------------------------------
# design
# --------------------------------------------------------------------------------------------------
@dataclass(eq=False)
class SpeedControllerDesign:
    """One LPV speed-controller design (6.4.3) in the model's scaled units."""

    spec: SpeedSpec
    lft: MLPLFT  # the LFT with the kept residual gains
    plant: LFTPlant  # Fig. 6.13
    gamma_a: float  # LMI bound with the kept residual gains
    gamma: float  # the constructed controller's verified bound
    gamma_lti: float  # LMI bound ignoring the residual gains (Delta = 0)
    controller: ScheduledController
    verification: VerificationReport | None
    bisection: BisectionResult
    synthesis: SynthesisResult
    construction: dict = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    lower_bound: LowerBound | None = None  # independent: worst frozen LTI optimum on a 5^m grid of Δ

    def summary(self) -> dict[str, Any]:
        K = self.controller.K
        return dict(
            spec=self.spec.as_dict(), gamma_a=self.gamma_a, gamma=self.gamma, gamma_lti=self.gamma_lti,
            **certificate(self.lower_bound, self.gamma_a, self.gamma),
            thesis={k: THESIS[k] for k in ("gamma_lmi", "gamma_constructed", "gamma_ignoring_residual_gains")},
            n_c=K.n_c, m_c=K.n_wc, k_c=K.n_zc, n_x=self.plant.n_x, kept_gains=self.lft.neurons.tolist(),
            widths=self.lft.widths.tolist(), B_u=self.lft.plant.B_u[0].tolist(),
            bisection_iterations=self.bisection.iterations, n_solves=self.bisection.n_solves,
            construction=self.construction, timings=self.timings,
            verification=self.verification.as_dict() if self.verification else None,
        )  # fmt: skip


def _box_grid(m: int, k: int) -> list[np.ndarray]:
    """A k^m grid of the normalised box (corners included)."""
    if m == 0:
        return [np.zeros((0, 0))]
    return ParameterSet.diagonal(m).grid(k**m)


def controller_poles(ctrl: ScheduledController, grid: Sequence[np.ndarray]) -> float:
    """Largest pole magnitude of the frozen controller (5.63) over ``grid``: < 1 iff it is stable on its own."""
    return max(float(np.max(np.abs(np.linalg.eigvals(ctrl.frozen(D).A)), initial=0.0)) for D in grid)


def _construct_verified(prob: SynthesisProblem, gamma: float, grid: Sequence[np.ndarray],
                        build: Callable[[SynthesisResult], ScheduledController],
                        check: Callable[[ScheduledController], VerificationReport | None],
                        say: Callable[[str], None], stable: bool = True,
                        ) -> tuple[ScheduledController, VerificationReport | None, SynthesisResult, list]:  # fmt: skip
    """Try the centred solutions of `CENTERINGS` at ``gamma`` until one constructs (``build``), is (with
    ``stable``) a stable controller on the grid, and passes ``check``; raises the last error."""
    tried: list[dict] = []
    last: Exception | None = None
    for objective, frac in CENTERINGS:
        entry: dict = {"gamma": gamma, "objective": objective, "margin_frac": frac}
        tried.append(entry)
        res = prob.centered(gamma, margin_frac=frac, objective=objective)
        entry["solution"] = res.settings.get("mode")
        if not res.feasible:
            entry["result"] = "no LMI solution"
            last = ConstructionError(f"no LMI solution at γ = {gamma:.4g}")
            continue
        try:
            c = build(res)
            entry["n_c"] = c.K.n_c
            entry["controller_pole_max"] = rho = controller_poles(c, grid)
            if stable and not rho < 1.0:
                raise ConstructionError(f"the controller is unstable on its own (pole {rho:.4f} on the Δ grid)")
            say(f"verification (order {c.K.n_c})")
            rep = check(c)
        except (ConstructionError, VerificationError, np.linalg.LinAlgError) as e:
            entry["result"] = f"rejected: {e}"
            last = e
            continue
        entry["result"] = "accepted"
        return c, rep, res, tried
    assert last is not None
    raise last


def design_speed_controller(
    lft: MLPLFT,
    spec: SpeedSpec = SpeedSpec(),
    *,
    backoffs: Sequence[float] = BACKOFFS,
    stable: bool = True,
    n_grid: int = 5,
    check: bool = True,
    verify_kw: dict | None = None,
    progress: Callable[[str], None] | None = None,
) -> SpeedControllerDesign:
    """Design, construct and verify the controller of 6.4.3 (raises if no backoff gives one).

    ``lft`` is the full LFT of the model (`synthesis.mlp_lft.lft_from_model`); the spec's n_gains widest
    residual gains are kept. The controller is constructed at gamma = backoff * gamma_a for the first
    ``backoffs`` entry at which (with ``stable``) it is stable on its own at every grid point and passes
    verification: the set-up leaves i_tau unpenalised, so near gamma_a the construction returns controllers
    with poles outside the unit circle and a very large gain at the Nyquist frequency, which the thesis'
    u_{k-1} scheduling ("a reasonably low high-frequency gain") and the current limit do not survive
    (docs/RESULTS.md 6.2). The verification grid has n_grid points per gain (corners included).
    """
    say = progress or (lambda s: None)
    t: dict[str, float] = {}
    kept = lft.widest(spec.n_gains)
    P = speed_plant(kept, spec)
    m = P.n_wu
    params = ParameterSet.diagonal(m) if m else ParameterSet.empty()
    say("LMI bound ignoring the residual gains (Delta = 0)")
    t0 = time.perf_counter()
    lti = bisect_gamma(P.at(np.zeros((m, m))), ParameterSet.empty()) if m else None
    t["bisection_lti"] = time.perf_counter() - t0
    say(f"gamma bisection with {m} residual gains (Thm 5.15, full-block multipliers)")
    t0 = time.perf_counter()
    bis = bisect_gamma(P, params) if m else lti
    assert bis is not None
    t["bisection"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lb = lpv_lower_bound(P, _box_grid(m, 5))
    t["lower_bound"] = time.perf_counter() - t0
    say(f"gamma_a = {bis.gamma_a:.4g} (ignoring the residual gains: {lti.gamma_a if lti else bis.gamma_a:.4g}; "
        f"independent lower bound {lb.value:.4g})")
    t0 = time.perf_counter()
    prob = SynthesisProblem(P, params, scaling=bis.scaling)
    grid = _box_grid(m, n_grid)
    tried: list[dict] = []
    last: Exception | None = None
    for bo in backoffs:
        say(f"construction at gamma = {bo:g} gamma_a = {bo * bis.gamma_a:.4g}")
        try:
            g = bo * bis.gamma_a
            ctrl, rep, res, tr = _construct_verified(
                prob, g, grid, construct_controller,
                lambda c, g=g: verify(P, c, g, grid, **(verify_kw or {})) if check else None, say, stable)
        except (ConstructionError, VerificationError, np.linalg.LinAlgError) as e:
            tried.append({"backoff": bo, "result": f"rejected: {e}"})
            last = e
            continue
        tried.append({"backoff": bo, "result": "accepted", "tried": tr})
        t["construction_and_verification"] = time.perf_counter() - t0
        return SpeedControllerDesign(spec, kept, P, bis.gamma_a, bo * bis.gamma_a,
                                     lti.gamma_a if lti else bis.gamma_a, ctrl, rep, bis, res,
                                     {"backoff": bo, "backoffs": tried}, t, lb)  # fmt: skip
    assert last is not None
    raise last


@dataclass(eq=False)
class RobustSpeedDesign:
    """The robust speed controller of 7.2 (Thm 7.1 for the scheduling-error bound e_bar)."""

    e_bar: np.ndarray
    design: Any  # synthesis.robust.RobustDesign
    controller: ScheduledController | None
    gamma: float
    verification: VerificationReport | None
    timings: dict[str, float] = field(default_factory=dict)
    #: worst frozen LTI optimum with exact scheduling (E = 0): a lower bound on the nominal and the robust γ
    lower_bound: LowerBound | None = None

    def summary(self) -> dict[str, Any]:
        s = self.design.summary()
        cert = certificate(self.lower_bound, s["gamma_a_robust"], self.gamma)
        return dict(**s, **cert, gamma=self.gamma, thesis=THESIS["robust"],
                    construction=self.controller.info if self.controller else None,
                    verification=self.verification.as_dict() if self.verification else None,
                    timings=self.timings)  # fmt: skip


def design_robust_speed_controller(plant: LFTPlant, e_bar: Sequence[float], *, backoffs: Sequence[float] = BACKOFFS,
                                   stable: bool = True, eps_step: float = 0.01, max_steps: int = 60,
                                   check: bool = True, n_grid: int = 5, verify_kw: dict | None = None,
                                   tied: bool = False, progress: Callable[[str], None] | None = None) -> RobustSpeedDesign:  # fmt: skip
    """The epsilon iteration of 7.2 on the Fig. 6.13 plant (`speed_plant`), construction (Thm 7.1) and
    `synthesis.robust.verify_robust` over (Delta, Delta + E), |e_i| <= e_bar_i (a failure raises).

    As for the nominal design, the iteration runs at gamma = backoff * gamma_a for the first ``backoffs``
    entry whose controller is stable on its own (with ``stable``). Returns the design even when the
    iteration does not end robust (``controller`` is then None).
    """
    say = progress or (lambda s: None)
    e = np.asarray(e_bar, float)
    t: dict[str, float] = {"iteration": 0.0, "construction_and_verification": 0.0}

    def step(st: Any) -> None:
        say(f"  step {st.step}: eps = {np.round(st.eps, 4).tolist()}, gamma = {st.gamma:.4g}, "
            f"robust = {st.robust}, certified e_bar = {np.round(st.certified_e, 4).tolist()}")  # fmt: skip

    grid = _box_grid(plant.n_wu, n_grid)
    t0 = time.perf_counter()
    lb = lpv_lower_bound(plant, _box_grid(plant.n_wu, 5))
    t["lower_bound"] = time.perf_counter() - t0
    d = None
    for bo in backoffs:
        say(f"epsilon iteration of 7.2 for e_bar = {np.round(e, 5).tolist()} at gamma = {bo:g} gamma_a")
        t0 = time.perf_counter()
        d = robust_iteration(plant, e, eps_step=eps_step, max_steps=max_steps, backoff=bo, tied=tied, progress=step)
        t["iteration"] += time.perf_counter() - t0
        if not d.success or d.result is None or d.problem is None:
            return RobustSpeedDesign(e, d, None, math.nan, None, t, lb)
        t0 = time.perf_counter()
        gamma = d.final.gamma
        try:
            K, rep, _, tried = _construct_verified(
                d.problem, gamma, grid, lambda res: construct_robust_controller(res, e),
                lambda c: verify_robust(plant, c, gamma, e, **(verify_kw or {})) if check else None, say, stable)
        except (ConstructionError, VerificationError, np.linalg.LinAlgError) as ex:
            say(f"  no controller at this backoff ({ex})")
            t["construction_and_verification"] += time.perf_counter() - t0
            continue
        K.info.update(backoff=bo, tried=tried)
        t["construction_and_verification"] += time.perf_counter() - t0
        return RobustSpeedDesign(e, d, K, gamma, rep, t, lb)
    assert d is not None
    raise ConstructionError(f"no stable robust controller constructed for backoffs {list(backoffs)}")


# --------------------------------------------------------------------------------------------------
# run-time data and the numpy reference implementation of the scheduled law
# --------------------------------------------------------------------------------------------------
def runtime_data(lft: MLPLFT, spec: SpeedSpec, log_filter_hz: float = 100.0) -> dict[str, Any]:
    """Everything a run-time speed controller needs besides K and Delta_c (JSON-ready): the model's scaling
    and equilibrium, the scheduling map xi = C_u x + E_u u (x = [w_k .. w_{k-n+1}, (i..), d_{k-1} .., tau_{k-1} ..]
    - x°, u = [i_k, d_k, tau_k] - u°), and the residual functions (theta_b, centre c, half-width h):
    delta_j = (sigma'_j(xi_j)/xi_j - c_j)/h_j; ``log_filter_hz`` is the first-order filter the model's data went
    through (6.4.2: 100 Hz), which the run-time speed feedback must reproduce."""
    p = lft.plant
    return {
        "scaling": lft.scaling.to_dict(), "orders": asdict(lft.orders), "dt": float(p.dt),
        "x0": lft.x0.tolist(), "u0": lft.u0.tolist(), "w0": float(lft.w0),
        "C_u": p.C_u.tolist(), "E_u": p.E_u.tolist(), "theta_b": lft.theta_b.tolist(),
        "c": (0.5 * (lft.k_min + lft.k_max)).tolist(), "h": (0.5 * (lft.k_max - lft.k_min) + lft.eps).tolist(),
        "neurons": lft.neurons.tolist(), "observer": dict(zip(("a_i", "b_i"), observer_coefficients(lft, spec.motor))),
        "log_filter_hz": float(log_filter_hz),
    }  # fmt: skip


class ScheduledSpeedLaw:
    """The run-time speed law of 6.4.3 in numpy (the reference the bench plugin is tested against).

    ``step(w, w_ref, i, d)`` takes the scaled measured speed, reference, i_mR estimate and the applied
    i_sd,ref at sample k and returns the controller's u = [d~_lpv, tau~] (scaled, with u° added back).
    Delta_k is computed from the measured histories and u_{k-1} in place of u_k (the algebraic loop broken
    as the thesis does); ``iterations`` > 0 re-evaluates Delta_k with the new tau_k that many times
    (without advancing the controller) before committing. The applied tau is what the caller reports back
    through ``applied_tau`` (after limiting); by default the controller's own tau.
    """

    def __init__(self, controller: ScheduledController, lft: MLPLFT, *, iterations: int = 0) -> None:
        self.K = controller
        self.lft = lft
        self.iterations = iterations
        K = controller.K
        self._blocks = [np.array(getattr(K, k)) for k in ("A_c", "B_c1", "B_c2", "C_c1", "D_c11", "D_c12",
                                                          "C_c2", "D_c21", "D_c22")]  # fmt: skip
        self.reset()

    def reset(self) -> None:
        o = self.lft.orders
        self.x = np.zeros(self.K.K.n_c)
        self.w_hist = np.zeros(o.n)  # newest first
        self.i_hist = np.zeros(max(o.n_i - 1, 0))
        self.d_hist = np.zeros(o.n_u - 1)
        self.t_hist = np.zeros(o.n_u - 1)
        self.tau_prev = 0.0
        self.delta = np.zeros(self.lft.plant.n_wu)

    def _u(self, y: float, Delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Ac, Bc1, Bc2, Cc1, Dc11, Dc12, Cc2, Dc21, Dc22 = self._blocks
        if Bc2.shape[1]:
            Dc = self.K.delta_c(Delta)
            zt = Cc2 @ self.x + Dc21[:, 0] * y
            wc = Dc @ np.linalg.solve(np.eye(Dc.shape[1]) - Dc22 @ Dc, zt)
        else:
            wc = np.zeros(0)
        u = Cc1 @ self.x + Dc11[:, 0] * y + Dc12 @ wc
        xn = Ac @ self.x + Bc1[:, 0] * y + Bc2 @ wc
        return u, xn

    def schedule(self, i: float, d: float, tau: float) -> np.ndarray:
        """Delta at the current histories and inputs (i, d, tau), clipped to the box."""
        lft = self.lft
        x = np.concatenate([self.w_hist, self.i_hist, self.d_hist, self.t_hist]) - lft.x0
        u = np.array([i, d, tau]) - lft.u0
        return np.diag(np.clip(lft.gains(lft.xi(x, u)), -1.0, 1.0))

    def step(self, w: float, w_ref: float, i: float, d: float) -> np.ndarray:
        self.w_hist = np.concatenate([[w], self.w_hist[:-1]])
        y = w - w_ref
        tau = self.tau_prev
        Delta = self.schedule(i, d, tau)
        u, xn = self._u(y, Delta)
        for _ in range(self.iterations):
            Delta = self.schedule(i, d, float(u[1]) + self.lft.u0[2])
            u, xn = self._u(y, Delta)
        self.delta = np.diag(Delta).copy()
        self.x = xn
        self._pending = (i, d)
        return u + self.lft.u0[1:]

    def applied(self, tau: float) -> None:
        """Record the tau~ actually applied at this sample (before the next `step`)."""
        i, d = self._pending
        if self.i_hist.size:
            self.i_hist = np.concatenate([[i], self.i_hist[:-1]])
        if self.d_hist.size:
            self.d_hist = np.concatenate([[d], self.d_hist[:-1]])
            self.t_hist = np.concatenate([[tau], self.t_hist[:-1]])
        self.tau_prev = tau


@dataclass
class NarxLoopResult:
    """Closed loop of the MLP model with a scheduled speed controller (physical units)."""

    t: np.ndarray
    omega: np.ndarray  # [rad/s] the model's speed (the "true" speed of this loop)
    omega_ref: np.ndarray
    i_mR: np.ndarray  # [A]
    i_sd_ref: np.ndarray
    i_tau: np.ndarray  # [A^2] applied
    delta: np.ndarray  # (N, m) scheduling used
    delta_true: np.ndarray  # (N, m) scheduling from the noise-free signals

    def tracking(self, t_from: float = 0.0) -> dict[str, float]:
        sel = self.t >= t_from
        e = (self.omega - self.omega_ref)[sel]
        return {"rms_rad_s": float(np.sqrt(np.mean(e**2))), "max_abs_rad_s": float(np.max(np.abs(e)))}


def narx_closed_loop(model: NarxModel, law: ScheduledSpeedLaw, omega_ref: Sequence[float], *, i_mR_ref: float = 2.2,
                     motor: MotorData = MotorData(), K_m: float = 4.0, noise_rad_s: float = 0.0, seed: int = 0,
                     i_tau_max: float | None = None) -> NarxLoopResult:  # fmt: skip
    """The MLP NARX model (all neurons, exact) in closed loop with ``law`` at the model's rate, physical units.

    The speed the controller sees (error and scheduling) is the model's speed plus uniform noise in
    ±noise_rad_s (the 0.5 rad/s bound of 7.2). i_mR follows the observer (6.29) driven by i_sd,ref from the
    traditional P controller i_sd,ref = K_m((K_m + 1)/K_m i_mR,ref - i_mR) (4.2.2), which replaces the
    controller's own d~ (6.4.3). ``i_tau_max`` limits |i_tau|.
    """
    o, sc = model.orders, model.scaling
    T = model.dt
    a_i = math.exp(-T * motor.R_r / motor.L_r)
    rng = np.random.default_rng(seed)
    ref = np.asarray(omega_ref, float)
    N = ref.size
    lag = o.lag
    w = [0.0] * lag  # physical histories, newest last
    i_m = [sc.i_mR0] * lag
    dd = [sc.i_sd_ref0] * lag
    tt = [sc.i_tau0] * lag
    # the i_mR observer state (6.29), in A
    imr = sc.i_mR0
    out = {k: np.zeros(N) for k in ("omega", "i_mR", "i_sd_ref", "i_tau")}
    dl, dlt = np.zeros((N, law.lft.plant.n_wu)), np.zeros((N, law.lft.plant.n_wu))
    law.reset()
    # warm start: the law's histories at the operating point
    w0 = sc.scale("omega_r", 0.0)
    law.w_hist[:] = w0
    law.i_hist[:] = sc.scale("i_mR", imr)
    law.d_hist[:] = sc.scale("i_sd_ref", sc.i_sd_ref0)
    law.t_hist[:] = sc.scale("i_tau", sc.i_tau0)
    law.tau_prev = sc.scale("i_tau", sc.i_tau0)
    for k in range(N):
        omega = w[-1]
        meas = omega + (noise_rad_s * (2.0 * rng.random() - 1.0) if noise_rad_s > 0 else 0.0)
        i_sd = K_m * ((K_m + 1.0) / K_m * i_mR_ref - imr)  # (4.2.2)
        ws, rs, is_, ds = (sc.scale("omega_r", meas), sc.scale("omega_r", ref[k]), sc.scale("i_mR", imr),
                           sc.scale("i_sd_ref", i_sd))  # fmt: skip
        # the noise-free scheduling at the same point, for comparison
        saved = law.w_hist
        law.w_hist = np.array([sc.scale("omega_r", v) for v in w[::-1][: o.n]])
        dlt[k] = np.diag(law.schedule(sc.scale("i_mR", imr), ds, law.tau_prev))
        law.w_hist = saved
        u = law.step(ws, rs, is_, ds)
        i_tau = sc.unscale("i_tau", float(u[1]))
        if i_tau_max is not None:
            i_tau = min(max(i_tau, -i_tau_max), i_tau_max)
        law.applied(sc.scale("i_tau", i_tau))
        dl[k] = law.delta
        for key, v in (("omega", omega), ("i_mR", imr), ("i_sd_ref", i_sd), ("i_tau", i_tau)):
            out[key][k] = v
        # the model: w_{k+1} from z_{k+1} = [w_k.., i_k.., d_k.., tau_k..] (scaled)
        i_m.append(imr)
        dd.append(i_sd)
        tt.append(i_tau)
        z = np.concatenate([
            [sc.scale("omega_r", v) for v in w[::-1][: o.n]], [sc.scale("i_mR", v) for v in i_m[::-1][: o.n_i]],
            [sc.scale("i_sd_ref", v) for v in dd[::-1][: o.n_u]], [sc.scale("i_tau", v) for v in tt[::-1][: o.n_u]],
        ])  # fmt: skip
        w.append(sc.unscale("omega_r", float(model.mlp.predict(z))))
        imr = a_i * imr + (1.0 - a_i) * i_sd  # (6.29), zero-order hold
        w, i_m, dd, tt = w[-lag:], i_m[-lag:], dd[-lag:], tt[-lag:]
    return NarxLoopResult(np.arange(N) * T, out["omega"], ref, out["i_mR"], out["i_sd_ref"], out["i_tau"], dl, dlt)


def artifact_certificate(doc: dict, lft: MLPLFT) -> dict[str, dict]:
    """The `[lower bound, γ_a, γ]` records (`synthesis.lower_bound.certificate`) of a speed artifact made before
    the designs carried them: the independent lower bound (worst frozen Riccati optimum on the 5^m Δ grid, as
    `design_speed_controller`) on the Fig. 6.13 plant rebuilt from the artifact's model ``lft`` and spec, next to
    the stored γ_a and γ. Returns {"nominal": ..., "top": ...}: the nominal design's record, and the artifact's own
    (for a robust artifact: γ_a of the robust iteration and its γ; the bound with exact scheduling, E = 0, bounds
    both)."""
    meta = doc["meta"]
    spec = spec_from_dict(meta["nominal"]["spec"])
    P = speed_plant(lft.widest(spec.n_gains), spec)
    lb = lpv_lower_bound(P, _box_grid(P.n_wu, 5))
    nominal = certificate(lb, float(meta["nominal"]["gamma_a"]), float(meta["nominal"]["gamma"]))
    rob = meta.get("robust_design")
    top = certificate(lb, float(rob["gamma_a_robust"]), float(doc["gamma"])) if rob else nominal
    return {"nominal": nominal, "top": top}


if __name__ == "__main__":
    # python -m synthesis.models.speed_controller sampled|certificate ARTIFACT [--write]: the sampled-data report,
    # or the lower bound / gap / gammas (`artifact_certificate`), of a speed artifact (model from its
    # meta.model.path, resolved next to the artifact if relative paths fail); --write stores it in the artifact's
    # JSON meta (the JSON is not covered by the artifact's SHA-256, which is the npz's)
    import json
    import sys
    import warnings

    from synthesis.artifacts import _jsonable, load_controller

    warnings.simplefilter("ignore")
    if len(sys.argv) < 3 or sys.argv[1] not in ("sampled", "certificate"):
        sys.exit("usage: python -m synthesis.models.speed_controller sampled|certificate ARTIFACT [--write]")
    art = Path(sys.argv[2])
    ctrl, doc = load_controller(art)
    mp = Path(doc["meta"]["model"]["path"])
    model = load_model(mp if mp.with_suffix(".json").exists() else art.parent / mp.name)
    js = art.with_suffix(".json") if art.suffix != ".json" else art
    full = json.loads(js.read_text())
    if sys.argv[1] == "sampled":
        spec = spec_from_dict(doc["meta"]["nominal"]["spec"])
        rep = sampled_report(ctrl, lft_from_model(model), spec, float(doc["gamma"]))
        print(json.dumps(rep, indent=2))
        full["meta"]["sampled_data"] = rep
    else:
        cert = _jsonable(artifact_certificate(doc, lft_from_model(model)))
        print(json.dumps({k: {n: v for n, v in c.items() if n != "lower_bound"} for k, c in cert.items()}, indent=2))
        full["meta"]["nominal"].update(cert["nominal"])
        full["meta"].update(cert["top"])
    if "--write" in sys.argv[3:]:
        js.write_text(json.dumps(full, indent=2, sort_keys=True))


def gamma_a_of_model(model_path: Path) -> dict[str, Any]:
    """γ_a of the Fig. 6.13 set-up for one saved NARX model (its two widest residual gains, 6.4.2's selection rule)
    and the LTI bound (the same plant with Δ = 0)."""
    lft = lft_from_model(load_model(model_path))
    P = speed_plant(lft.widest(2), SpeedSpec())
    return {"gamma_a": bisect_gamma(P, ParameterSet.diagonal(2)).gamma_a,
            "gamma_lti": bisect_gamma(P.at(np.zeros((2, 2))), ParameterSet.empty()).gamma_a,
            "widths": lft.widths.tolist()}  # fmt: skip
