"""Dual certificates for the optimum of the synthesis LMIs of Thm 5.15 (issue 12: numerics or the method?).

`synthesis.lmi.bisect_gamma` finds γ_a from above: a γ is accepted when the solver's max-margin point passes
the numpy re-check. Whether a γ_a above the frozen lower bound (`synthesis.lower_bound`) is numerics
(scaling, variable bounds, solver accuracy) or the LMIs' own optimum is decided here from below, by
Lagrange duality, with the LMI matrices assembled in numpy (`lmi_system`, from the constant blocks of
`synthesis.lmi._lmi_blocks`, not from the cvxpy expressions; `tests/test_lmi_dual.py` checks the assembly):

Every inequality of Thm 5.15 -- (5.59) on the generators, Q ≺ 0, R̃ ≻ 0 (5.3.3), (5.60), (5.61), (5.62) in the
Schur form of `synthesis.lmi`, and the search box X, Y ⪯ B·I, ‖P‖, ‖P̃‖ ≤ B -- is written in real form as
F_i(V, γ) = C_i + γ G_i + Σ c·sym(Lᵀ V R) ⪯ 0, V ∈ {X, Y, P, P̃}. For dual matrices Z_i ⪰ 0 (taken from the
solver of the max-margin problem at a fixed γ, then PSD-projected here), any V with the strict LMIs ⪯ −t·I
and the others ⪯ 0 satisfies

    s·t ≤ −c − Σ_V ⟨R_V, V⟩,   c = Σ_i ⟨Z_i, C_i + γ G_i⟩,   s = Σ_strict tr Z_i,   R_V = Σ c·sym(L Z_i Rᵀ),

and the last term is maximised exactly over the box. A negative right-hand side (`InfeasibilityCertificate.
infeasible`) proves that no V in the box solves the LMIs at that γ, not even non-strictly. Only the Z_i come
from the solver; c, s, R_V and the PSD projection are computed in numpy, and the solver's status is ignored.
`lmi_optimum_evidence` combines the certificate (from below) with a direct minimisation of γ whose minimiser
is re-checked in numpy (from above).

    python -m synthesis.lmi_dual flux --omega-max 400 --discretisation thesis [--rate 600]
    python -m synthesis.lmi_dual current --rate 3000
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from synthesis.lft import LFTPlant
from synthesis.lmi import (
    ParameterSet, PlantScaling, SynthesisProblem, _Field, _lmi_blocks, balance_from_solution, bisect_gamma,
)
from synthesis.models.flux_observer import VARIANTS, flux_gamma_a, flux_lower_bound
from synthesis.models.motor import flux_observer_plant_discrete
from synthesis.models.current_controller import CurrentSpec, current_plant_discrete, delta_grid, parameter_set
from synthesis.lower_bound import lpv_lower_bound

__all__ = ["AffineLMI", "lmi_system", "lmi_evaluate", "InfeasibilityCertificate", "check_infeasibility",
           "infeasibility_certificate", "lmi_optimum_evidence", "CERTIFICATE_SOLVER_OPTS"]


@dataclass(frozen=True, eq=False)
class AffineLMI:
    """F(V, γ) = C + γ G + Σ_k coef_k·sym(L_kᵀ V_k R_k) ⪯ 0 (real symmetric); `strict` marks ≺."""

    name: str
    C: np.ndarray
    G: np.ndarray
    terms: tuple[tuple[str, np.ndarray, np.ndarray, float], ...]
    strict: bool = True


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.T)


def lmi_system(plant: LFTPlant, params: ParameterSet, beta: float = 0.0, bound: float | None = None
               ) -> tuple[list[AffineLMI], dict[str, int]]:
    """The inequalities of Thm 5.15 for a (scaled) discrete plant as `AffineLMI`s in real form.

    Returns the list and the real dimension of each variable (X, Y: n_x; P, P̃: n_wu + n_zu; doubled for
    complex plants, whose data enter through the real form (3.45)). The discrete Lyapunov blocks use the
    cancellation-free form of `synthesis.lmi._lyap` (b*Vb − a*Va = r*Vv + v*Vr). ``bound``: add
    X, Y ⪯ bound·I and −bound·I ⪯ P, P̃ ⪯ bound·I (the search box of `SynthesisProblem`), non-strict.
    """
    p = plant
    F = _Field(np.iscomplexobj(p.M) and bool(np.any(np.imag(p.M))) or
               any(np.iscomplexobj(g) and np.any(np.imag(g)) for g in params.generators))  # fmt: skip
    b = _lmi_blocks(p)
    n, nwu, nzu, nzp, nwp = p.n_x, p.n_wu, p.n_zu, p.n_zp, p.n_wp
    rho = 1.0 - beta
    sq = math.sqrt(p.dt)
    nr = F.eye(n).shape[0]
    dims = {"X": nr, "Y": nr}
    out: list[AffineLMI] = []
    # (5.60): −[X I; I Y] ⪯ 0 (non-strict)
    E1 = np.hstack([np.eye(nr), np.zeros((nr, nr))])
    E2 = np.hstack([np.zeros((nr, nr)), np.eye(nr)])
    C60 = -np.block([[np.zeros((nr, nr)), np.eye(nr)], [np.eye(nr), np.zeros((nr, nr))]])
    out.append(AffineLMI("(5.60)", C60, np.zeros_like(C60), (("X", E1, E1, -1.0), ("Y", E2, E2, -1.0)), False))

    def lyap_terms(var: str, a: np.ndarray, bb: np.ndarray, c: float, E: np.ndarray, sign: float) -> list:
        r = F.c(sq * 0.5 * (a + bb)) @ E
        v = F.c((bb - a) / sq) @ E
        t = [(var, r, v, 2.0 * sign)]
        if c != 0.0:
            t.append((var, F.c(bb) @ E, F.c(bb) @ E, c * sign))
        return t

    # (5.61): [[Ψ*M_XΨ, Ψ*C_r*], [C_rΨ, −γI]] ≺ 0
    Psi = b["Psi"]
    dpsi = F.c(Psi).shape[1]
    kz = F.eye(nzp).shape[0]
    Ea = np.hstack([np.eye(dpsi), np.zeros((dpsi, kz))])
    terms = lyap_terms("X", b["x_now"] @ Psi, b["x_next"] @ Psi, rho**-2 - 1.0, Ea, 1.0)
    if nwu + nzu:
        W = F.c(np.vstack([b["w_u"], b["z_u"]]) @ Psi) @ Ea
        terms.append(("P", W, W, 1.0))
    CrPsi = F.c(b["z_p"] @ Psi)
    C61 = np.block([[np.zeros((dpsi, dpsi)), CrPsi.T], [CrPsi, np.zeros((kz, kz))]])
    G61 = -np.block([[F.c(Psi.conj().T @ b["w_p"].conj().T @ b["w_p"] @ Psi), np.zeros((dpsi, kz))],
                     [np.zeros((kz, dpsi)), np.eye(kz)]])  # fmt: skip
    out.append(AffineLMI("(5.61)", C61, G61, tuple(terms)))
    # (5.62): [[Φ*M_YΦ, Φ*G*], [GΦ, γI]] ≻ 0, written as −(·) ⪯ 0
    Phi = b["Phi"]
    dphi = F.c(Phi).shape[1]
    kw = F.eye(nwp).shape[0]
    Eb = np.hstack([np.eye(dphi), np.zeros((dphi, kw))])
    terms = lyap_terms("Y", b["y_1"] @ Phi, b["y_2"] @ Phi, rho**2 - 1.0, Eb, -1.0)
    if nwu + nzu:
        Wt = F.c(np.vstack([b["wt_u"], b["zt_u"]]) @ Phi) @ Eb
        terms.append(("Pt", Wt, Wt, -1.0))
    GPhi = F.c(b["G"] @ Phi)
    C62 = -np.block([[np.zeros((dphi, dphi)), GPhi.T], [GPhi, np.zeros((kw, kw))]])
    G62 = -np.block([[F.c(Phi.conj().T @ b["zt_p"].conj().T @ b["zt_p"] @ Phi), np.zeros((dphi, kw))],
                     [np.zeros((kw, dphi)), np.eye(kw)]])  # fmt: skip
    out.append(AffineLMI("(5.62)", C62, G62, tuple(terms)))
    if nwu + nzu:
        m = F.eye(nwu + nzu).shape[0]
        dims.update(P=m, Pt=m)
        for i, D in enumerate(params.generators):  # (5.59) on the generators
            S = F.c(np.vstack([D, np.eye(nzu)]))
            St = F.c(np.vstack([np.eye(nwu), -D.conj().T]))
            z1, z2 = np.zeros((S.shape[1],) * 2), np.zeros((St.shape[1],) * 2)
            out.append(AffineLMI(f"(5.59) P, generator {i}", z1, z1, (("P", S, S, -1.0),)))
            out.append(AffineLMI(f"(5.59) Pt, generator {i}", z2, z2, (("Pt", St, St, 1.0),)))
        Ew = F.c(np.vstack([np.eye(nwu), np.zeros((nzu, nwu))]))
        Ez = F.c(np.vstack([np.zeros((nwu, nzu)), np.eye(nzu)]))
        zq, zr = np.zeros((Ew.shape[1],) * 2), np.zeros((Ez.shape[1],) * 2)
        out.append(AffineLMI("Q<0", zq, zq, (("P", Ew, Ew, 1.0),)))  # 5.3.3
        out.append(AffineLMI("Rt>0", zr, zr, (("Pt", Ez, Ez, -1.0),)))
    if bound is not None:
        for v, k in dims.items():
            I = np.eye(k)
            out.append(AffineLMI(f"{v} <= bound", -bound * I, np.zeros((k, k)), ((v, I, I, 1.0),), False))
            if v in ("P", "Pt"):
                out.append(AffineLMI(f"{v} >= -bound", -bound * I, np.zeros((k, k)), ((v, I, I, -1.0),), False))
    return out, dims


def lmi_evaluate(system: list[AffineLMI], V: dict[str, np.ndarray], gamma: float) -> dict[str, np.ndarray]:
    """Each F_i(V, γ) in numpy (V in real form)."""
    return {L.name: _sym(L.C + gamma * L.G + sum(c * _sym(Lk.T @ V[v] @ Rk) for v, Lk, Rk, c in L.terms))
            for L in system}  # fmt: skip


def _adjoint(system: list[AffineLMI], Z: list[np.ndarray], dims: dict[str, int]) -> dict[str, np.ndarray]:
    """R_V = Σ_i Σ_k coef·sym(L_k Z_i R_kᵀ): ⟨R_V, V⟩ is the V-part of Σ_i ⟨Z_i, F_i⟩."""
    R = {v: np.zeros((d, d)) for v, d in dims.items()}
    for L, Zi in zip(system, Z):
        for v, Lk, Rk, c in L.terms:
            R[v] += c * _sym(Lk @ Zi @ Rk.T)
    return R


@dataclass
class InfeasibilityCertificate:
    """A numpy-checked proof that Thm 5.15's LMIs have no solution at a γ inside a search box.

    From dual matrices Z_i ⪰ 0 (PSD-projected here) of the max-margin problem, with c = Σ⟨Z_i, C_i + γ'G_i⟩,
    s = Σ_strict tr Z_i and the adjoint residuals R_V: every (V, t) with all strict LMIs ⪯ −t·I and the
    non-strict ones ⪯ 0 has s·t ≤ −c − Σ_V ⟨R_V, V⟩. ``t_upper`` = −c/s (R = 0); ``t_upper_box`` bounds t over
    the search box of `SynthesisProblem` (0 ⪯ X, Y ⪯ bound·I, ‖P‖, ‖P̃‖ ≤ bound) with the exact maximum of
    ⟨R_V, V⟩ there: negative means no solution in the box at that γ, not even a non-strict one.
    """

    gamma: float
    t_upper: float
    t_upper_box: float
    residual: float
    s: float
    bound: float
    min_eig_rel: float
    status: str

    @property
    def infeasible(self) -> bool:
        return bool(self.t_upper_box < 0.0)

    def as_dict(self) -> dict:
        return dict(gamma=self.gamma, t_upper=self.t_upper, t_upper_box=self.t_upper_box, residual=self.residual,
                    s=self.s, bound=self.bound, min_eig_rel=self.min_eig_rel, status=self.status,
                    infeasible=self.infeasible)


def _average_complex_formed(Z: np.ndarray) -> np.ndarray:
    """(Z + Jᵀ Z J)/2 with J the real form of j·I: the orthogonal projection onto complex-formed matrices."""
    k = Z.shape[0] // 2
    J = np.block([[np.zeros((k, k)), -np.eye(k)], [np.eye(k), np.zeros((k, k))]])
    return 0.5 * (Z + J.T @ Z @ J)


def check_infeasibility(system: list[AffineLMI], dims: dict[str, int], Z: list[np.ndarray], gamma_s: float,
                        bound: float, g0: float = 1.0, *, complex_formed: bool = False, status: str = "",
                        ) -> InfeasibilityCertificate:
    """Check dual matrices of the max-margin problem at the scaled γ' = gamma_s in numpy (see the class)."""
    Zp, worst = [], 0.0
    for Zi in Z:
        Zi = _sym(np.asarray(Zi, float))
        w, U = np.linalg.eigh(Zi) if Zi.size else (np.zeros(0), Zi)
        if w.size:
            worst = min(worst, float(w.min()) / max(float(np.abs(w).max()), 1e-300))
        Zp.append((U * np.maximum(w, 0.0)) @ U.T if w.size else Zi)
    c = sum(float(np.sum((L.C + gamma_s * L.G) * Zi)) for L, Zi in zip(system, Zp))
    s = sum(float(np.trace(Zi)) for L, Zi in zip(system, Zp) if L.strict)
    R = _adjoint(system, Zp, dims)
    if complex_formed:  # only complex-formed V are searched (w.l.o.g., Cor. 5.33): ⟨R, V⟩ = ⟨proj R, V⟩
        R = {v: _average_complex_formed(Rv) for v, Rv in R.items()}
    res = float(sum(np.linalg.norm(Rv, "fro") for Rv in R.values()))
    # s·t ≤ −c − ⟨R, V⟩; the max of −⟨R_V, V⟩ over the box 0 ⪯ X, Y ⪯ bound·I ((5.60) gives X, Y ⪰ 0),
    # −bound·I ⪯ P, P̃ ⪯ bound·I is bound times the negative eigenvalues of R_X, R_Y and ‖R_P‖_*, ‖R_P̃‖_*
    box = 0.0
    for v, Rv in R.items():
        w = np.linalg.eigvalsh(_sym(Rv)) if Rv.size else np.zeros(0)
        box += bound * float(np.sum(np.maximum(-w, 0.0)) if v in ("X", "Y") else np.sum(np.abs(w)))
    return InfeasibilityCertificate(gamma_s * g0, -c / s, (-c + box) / s, res, s, bound, worst, status)


#: Clarabel settings for the certificates: without equilibration the dual matrices come out 100-1000x more
#: accurate on these problems (adjoint residual 1e-9 ... 1e-11 instead of 1e-7 ... 1e-5, measured on the 3 kHz
#: current controller and the flux observer, thesis' reading, at ω_r,max = 400 rad/s)
CERTIFICATE_SOLVER_OPTS: dict = dict(static_regularization_constant=1e-12, tol_feas=1e-10, tol_gap_abs=1e-10,
                                     tol_gap_rel=1e-10, equilibrate_enable=False, max_iter=300)


def infeasibility_certificate(plant: LFTPlant, params: ParameterSet, gamma: float, *,
                              scaling: PlantScaling | None = None, beta: float = 0.0, bound: float = 1e6,
                              g0: float = 1.0, solver_opts: dict | None = None) -> InfeasibilityCertificate:
    """Solve `SynthesisProblem.feasibility(gamma)` (box ``bound``) and check the solver's dual matrices with
    `check_infeasibility`. ``scaling`` (else `balance_plant` with ``g0``) is the coordinates of the box.

    The LMI matrices are rebuilt here (`lmi_system`), not taken from the cvxpy problem; only the Z_i come from
    the solver, and they are projected onto the PSD cone before anything is computed from them.
    """
    opts = CERTIFICATE_SOLVER_OPTS if solver_opts is None else solver_opts
    prob = SynthesisProblem(plant, params, beta=beta, scaling=scaling, g0=g0, x_bound=bound, mult_bound=bound,
                            solver_opts=opts)  # fmt: skip
    r = prob.feasibility(gamma)
    cons = prob._feas[0].constraints[:-1]  # the compiled max-margin problem; the last constraint is t ≤ 1
    system, dims = lmi_system(prob.plant, params, beta, bound)
    by_name = {L.name: L for L in system}
    order = ["(5.60)", "(5.61)", "(5.62)", "X <= bound", "Y <= bound"]  # the order of SynthesisProblem._build
    if "P" in dims:
        for i in range(len(params.generators)):
            order += [f"(5.59) P, generator {i}", f"(5.59) Pt, generator {i}"]
        order += ["Q<0", "Rt>0", "P <= bound", "P >= -bound", "Pt <= bound", "Pt >= -bound"]
    if len(cons) != len(order):
        raise RuntimeError(f"{len(cons)} solver constraints, {len(order)} expected")
    Z = [np.zeros_like(by_name[n].C) if c.dual_value is None else np.asarray(c.dual_value) for n, c in zip(order, cons)]
    return check_infeasibility([by_name[n] for n in order], dims, Z, gamma / prob.scaling.g0, bound,
                               prob.scaling.g0, complex_formed=prob.cplx, status=f"{r.status}, t = {r.margin:.3g}")


def lmi_optimum_evidence(plant: LFTPlant, params: ParameterSet, gamma_a: float, scaling: PlantScaling, *,
                         lower_bound: float | None = None, factors: tuple[float, ...] = (0.99,),
                         bounds: tuple[float, ...] = (1e8, 1e7, 1e6, 1e5), beta: float = 0.0) -> dict:
    """Where the optimum of Thm 5.15's LMIs lies relative to a bisection's γ_a, independently of the bisection.

    1. The plant is re-balanced from a trace-minimising solution at 1.02·γ_a with g0 = γ_a
       (`balance_from_solution`), so that γ' = 1 and X = Y, ‖P‖ = ‖P̃‖ at that point.
    2. From above: γ is minimised directly (`SynthesisProblem.minimize`) and the minimiser re-checked in numpy
       (``gamma_min``, ``gamma_min_verified``; in a poor basin it can come out above γ_a). Where that fails in the
       balanced coordinates, it is minimised again in the bisection's own (``gamma_min_coordinates`` says where).
    3. From below: at each γ = f·γ_a (f in ``factors``) and, if a ``lower_bound`` is given, at 1.01·lower_bound
       (the issue-12 target), the dual certificate of `infeasibility_certificate` for the largest search box in
       ``bounds`` for which it holds (``certified_box``; None if none), and for every box the certified
       max margin and its box bound (``t_upper_by_box``: t* not moving with the box means the bounds are not
       what makes the LMIs infeasible).

    ``lmi_optimum_bracket`` = [highest certified-infeasible γ, lowest verified-feasible γ].
    """
    t0 = time.perf_counter()
    sc1 = PlantScaling(scaling.T, scaling.d, gamma_a)
    c = SynthesisProblem(plant, params, beta=beta, scaling=sc1).centered(1.02 * gamma_a, objective="trace")
    scb = balance_from_solution(sc1, c.X, c.Y, c.P, c.Pt) if c.feasible else sc1
    m = SynthesisProblem(plant, params, beta=beta, scaling=scb).minimize()
    where = "balanced at 1.02 gamma_a"
    if not m.feasible:  # (Clarabel 0.11 stops with a numerical error there on the 3 kHz current controller; the
        # LMIs' feasibility does not depend on the coordinates, so the bisection's own are as good a place to look)
        m2 = SynthesisProblem(plant, params, beta=beta, scaling=scaling).minimize()
        if m2.feasible:
            m, where = m2, "the bisection's"
    out: dict = dict(gamma_a=gamma_a, gamma_min=m.gamma, gamma_min_verified=bool(m.feasible),
                     gamma_min_over_gamma_a=m.gamma / gamma_a, gamma_min_coordinates=where,
                     certificates=[])  # fmt: skip
    levels = [(f"{f} gamma_a", f * gamma_a) for f in factors]
    if lower_bound is not None:
        out.update(gamma_lower_bound=lower_bound, gap=gamma_a / lower_bound, gap_lmi_optimum=m.gamma / lower_bound)
        if 1.01 * lower_bound < gamma_a:
            levels.append(("1.01 lower bound", 1.01 * lower_bound))
    for name, g in levels:
        rec: dict = dict(level=name, gamma=g, certified_box=None, t_upper_by_box={})
        for B in sorted(bounds, reverse=True):
            cert = infeasibility_certificate(plant, params, g, scaling=scb, beta=beta, bound=B)
            rec["t_upper_by_box"][f"{B:g}"] = [cert.t_upper, cert.t_upper_box]  # the max margin t*, its bound
            if cert.infeasible and rec["certified_box"] is None:
                rec.update(certified_box=B, certificate=cert.as_dict())
        out["certificates"].append(rec)
    best = min([gamma_a] + ([m.gamma] if m.feasible else []))
    certified = [c["gamma"] for c in out["certificates"] if c["certified_box"] is not None]
    out["lmi_optimum_bracket"] = [max(certified) if certified else None, best]  # [certified infeasible, feasible]
    out["seconds"] = time.perf_counter() - t0
    return out


def _main(argv: list[str] | None = None) -> None:
    """CLI: the bisection, the frozen lower bound and `lmi_optimum_evidence` for one design, as JSON."""
    import argparse
    import json

    ap = argparse.ArgumentParser(prog="python -m synthesis.lmi_dual", description=_main.__doc__)
    sub = ap.add_subparsers(dest="design", required=True)
    f = sub.add_parser("flux", help="LPV flux observer (5.6)")
    f.add_argument("--omega-max", type=float, default=400.0)
    f.add_argument("--discretisation", choices=("full", "thesis"), default="thesis")
    f.add_argument("--rate", type=float, default=3000.0, help="sampling rate [Hz] (default the lab's 3 kHz)")
    c = sub.add_parser("current", help="quasi-LPV current controller (6.2), causal discretisation")
    c.add_argument("--rate", type=float, default=3000.0)
    for p in (f, c):
        p.add_argument("--multipliers", choices=("full", "multiconvex"), default="full",
                       help="multiconvex: Q_ii < 0, R̃_ii > 0 only (diagonal Δ boxes); bisection only, no certificate")
    a = ap.parse_args(argv)

    t0 = time.perf_counter()
    if a.design == "flux":
        variant = VARIANTS[a.discretisation]
        P = flux_observer_plant_discrete(a.omega_max, Ts=1.0 / a.rate, variant=variant)
        params = ParameterSet.interval(1)
        lb = flux_lower_bound(P).value
        t1 = time.perf_counter()
        b = flux_gamma_a(a.omega_max, Ts=1.0 / a.rate, variant=variant, lower_bound=lb, multipliers=a.multipliers)
        head = dict(design="flux observer", omega_r_max=a.omega_max, rate_hz=a.rate, discretisation=a.discretisation)
    else:
        P = current_plant_discrete(CurrentSpec(rate_hz=a.rate))
        params = parameter_set()
        lb = lpv_lower_bound(P, delta_grid(5)).value
        t1 = time.perf_counter()
        b = bisect_gamma(P, params, rescale="full", rescale_iters=14, lower_bound=lb, multipliers=a.multipliers)
        head = dict(design="current controller", rate_hz=a.rate, discretisation="causal")
    t_lb, t_bis = t1 - t0, b.wall_time
    out = dict(head, multipliers=a.multipliers, gamma_lower_bound=lb, gamma_a=b.gamma_a, gap=b.gamma_a / lb,
               seconds_lower_bound=t_lb, seconds_bisection=t_bis)  # fmt: skip
    if a.multipliers == "full":
        out["evidence"] = lmi_optimum_evidence(P, params, b.gamma_a, b.scaling, lower_bound=lb)
    print(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    _main()
