"""Discrete-time LPV synthesis LMIs with full-block multipliers (thesis Thm 5.15, 5.3.3, 5.4.4, 5.5.4).

Given a discrete LFT plant (5.55) with F_3 = 0 and a parameter set Δ̄ = Co{Δ_1, ..., Δ_N} (standard
LFT dependence w_u = Δ z_u, S(Δ) = [Δ; I]), find Hermitian X, Y and multipliers
P = [[Q, S], [S^*, R]], P̃ = [[Q̃, S̃], [S̃^*, R̃]] with

    [X I; I Y] ⪰ 0                                                         (5.60)
    Ψ^* (·)^* diag(−X, ρ^{-2} X, P, P_p) (·) Ψ ≺ 0                        (5.61)
    Φ^* (·)^* diag(−Y, ρ² Y, P̃, P̃_p) (·) Φ ≻ 0                           (5.62)
    [Δ_i; I]^* P [Δ_i; I] ≻ 0,  [I; −Δ_i^*]^* P̃ [I; −Δ_i^*] ≺ 0,  Q ≺ 0,  R̃ ≻ 0   (5.59), 5.3.3

with Ψ = ker [C F_u F_p], Φ = ker [B^* E_u^* E_p^*], ρ = 1 − β the decay-rate margin of 5.4.4.
The l2-gain index is used in the scaled form P_p = diag(−γ I, γ^{-1} I) (equivalent to
diag(−γ² I, I) for the gain < γ; then P̃_p = P_p^{-1} = diag(−γ^{-1} I, γ I)) and the γ^{-1} terms
are moved into Schur complements, so every inequality is affine in (X, Y, P, P̃, γ):

    [[Ψ^* M_X Ψ, Ψ^* C_r^*], [C_r Ψ, −γ I]] ≺ 0,   C_r = [C_p D_pu D_pp],
    [[Φ^* M_Y Φ, Φ^* G^*],  [G Φ,   γ I]] ≻ 0,   G   = −[B_p^* D_up^* D_pp^*].

Q ≺ 0 and R̃ ≻ 0 make (5.59) on the generators imply (5.59) on Δ̄ (5.3.3); together with
P ≻ 0 / P̃ ≺ 0 at Δ = 0 they also fix in(P̃) = (n_wu, 0, n_zu), the condition (5.26) of the constructive
proof (for square Δ, n_wu = n_zu).

Complex plants (the motor, Sec. 5.5) are handled *in real arithmetic*: every complex Hermitian
variable H = H_r + j H_i is a real symmetric H_r and a skew H_i, entering the solver as its real form
[[H_r, −H_i], [H_i, H_r]] (3.45); constant complex data likewise. An LMI on the real form holds iff it
holds on the complex matrix, so this is exactly the complex-Hermitian problem -- restricted, as
Cor. 5.33 allows without loss, to complex-formed solutions -- without cvxpy's complex layer.

Numerics (DESIGN.md, "LMI numerics"): the plant is balanced (diagonal state similarity, one scalar on
the parameter channel, which commutes with any Δ) and its performance output is scaled so that
γ is O(1); X, Y ⪯ x_bound·I and ‖P‖, ‖P̃‖ ⪯ mult_bound·I; strictness is a margin t·I with I =
`np.eye` (never `X >> eps`); matrices are symmetrised before `>>`; `optimal_inaccurate` is a
warning and every returned solution is re-checked by evaluating the LMIs in numpy. None of the
scalings changes the controller's input/output behaviour, so a controller constructed for the
scaled plant is a controller for the given plant.
"""

from __future__ import annotations

import itertools
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import cvxpy as cp
import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from synthesis.complex_formed import real_form
from synthesis.lft import LFTPlant

__all__ = [
    "ParameterSet",
    "PlantScaling",
    "SynthesisResult",
    "SynthesisProblem",
    "balance_plant",
    "synthesize",
    "minimize_gamma",
    "bisect_gamma",
    "BisectionResult",
    "rescale_from_solution",
    "balance_from_solution",
    "balanced_centre",
    "lmi_residuals",
    "null_basis",
    "LMIWarning",
    "MultiplierConstraints",
]


#: Clarabel settings. The default static regularisation (1e-8) visibly biases the margin of these
#: badly scaled problems (measured on the flux observer: γ_a 1.4e-4 with the defaults, 6e-5 with these).
DEFAULT_SOLVER_OPTS: dict = dict(
    static_regularization_constant=1e-12, tol_feas=1e-10, tol_gap_abs=1e-10, tol_gap_rel=1e-10, max_iter=300
)


class LMIWarning(UserWarning):
    """The solver returned an inaccurate solution (re-checked numerically)."""


class MultiplierConstraints(Protocol):
    """Extra convex constraints on the multipliers P, P̃ (a hook; e.g. the robustness constraints of Ch. 7).

    `build` returns cvxpy constraints on the solver-side expressions (strict ones use `margin`, a scalar
    expression, times an identity); `residuals` evaluates the same constraints in numpy on a solution
    and returns signed margins (< 0 means satisfied), which enter the re-check of every result.
    """

    def build(self, P: cp.Expression, Pt: cp.Expression, margin: cp.Expression) -> list: ...

    def residuals(self, P: np.ndarray, Pt: np.ndarray) -> dict[str, float]: ...


# --------------------------------------------------------------------------------------------------
# parameter sets
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ParameterSet:
    """Δ̄ = Co{generators} (5.3.3); each generator is an n_wu x n_zu matrix.

    ``ParameterSet.interval(n, lo, hi)`` is the repeated real scalar δ·I_n, δ ∈ [lo, hi], the case of
    the flux observer (n = 1, [−1, 1]). ``grid(k)`` gives points of Δ̄ for verification.
    """

    generators: tuple[np.ndarray, ...]
    scalar_interval: tuple[float, float] | None = None
    box: tuple[tuple[float, float], ...] | None = None

    @classmethod
    def interval(cls, n: int = 1, lo: float = -1.0, hi: float = 1.0) -> "ParameterSet":
        return cls((lo * np.eye(n), hi * np.eye(n)), (float(lo), float(hi)))

    @classmethod
    def diagonal(cls, n: int, lo: ArrayLike = -1.0, hi: ArrayLike = 1.0) -> "ParameterSet":
        """Δ = diag(δ_1, ..., δ_n), δ_i ∈ [lo_i, hi_i] independently (Ch. 7): the 2^n vertices generate Δ̄."""
        lo_a, hi_a = np.broadcast_to(np.asarray(lo, float), (n,)), np.broadcast_to(np.asarray(hi, float), (n,))
        if np.any(lo_a > hi_a):
            raise ValueError("diagonal parameter set needs lo <= hi in every channel")
        corners = itertools.product(*[(a, b) for a, b in zip(lo_a, hi_a)])
        gens = tuple(np.diag(np.array(c, float)) for c in corners)
        return cls(gens, None, tuple((float(a), float(b)) for a, b in zip(lo_a, hi_a)))

    @classmethod
    def empty(cls) -> "ParameterSet":
        """No parameter channel (LTI synthesis)."""
        return cls((np.zeros((0, 0)),), None)

    @property
    def shape(self) -> tuple[int, int]:
        return self.generators[0].shape

    def grid(self, k: int = 41) -> list[np.ndarray]:
        """Points of Δ̄: k for an interval; a tensor grid of ⌈k^{1/n}⌉ (≥ 2) per channel for a diagonal box
        (vertices included); else generators plus convex combinations of pairs."""
        if self.scalar_interval is not None:
            n = self.shape[0]
            return [d * np.eye(n) for d in np.linspace(*self.scalar_interval, k)]
        if self.box is not None:
            m = max(2, math.ceil(k ** (1.0 / len(self.box)) - 1e-9))
            axes = [np.linspace(a, b, m) for a, b in self.box]
            return [np.diag(np.array(c, float)) for c in itertools.product(*axes)]
        g = list(self.generators)
        out = list(g)
        ts = np.linspace(0, 1, max(3, k // max(1, len(g) * (len(g) - 1) // 2)))[1:-1]
        for i in range(len(g)):
            for j in range(i + 1, len(g)):
                out += [(1 - t) * g[i] + t * g[j] for t in ts]
        return out


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------
def null_basis(M: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Orthonormal basis of ker M (columns) -- the annihilators Ψ, Φ of (5.24)."""
    M = np.asarray(M)
    if M.shape[0] == 0:
        return np.eye(M.shape[1], dtype=M.dtype)
    return sla.null_space(M, rcond=rtol)


def _herm(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.conj().T)


def _is_complex(M: np.ndarray) -> bool:
    return bool(np.iscomplexobj(M) and np.any(np.abs(np.imag(M)) > 0))


class _Field:
    """Real or complex-formed bookkeeping: constants go through (3.45), Hermitian variables are real forms."""

    def __init__(self, cplx: bool) -> None:
        self.cplx = cplx

    def c(self, M: ArrayLike) -> np.ndarray:
        M = np.atleast_2d(np.asarray(M))
        return real_form(M) if self.cplx else np.real(M).astype(float)

    def eye(self, n: int) -> np.ndarray:
        return np.eye(2 * n if self.cplx else n)

    def herm(self, n: int, name: str) -> tuple[cp.Expression, Callable[[], np.ndarray]]:
        """A Hermitian n x n decision variable: (solver-side expression, numpy value getter)."""
        if n == 0:
            z = np.zeros((0, 0))
            return z, lambda: z  # type: ignore[return-value]
        Vr = cp.Variable((n, n), symmetric=True, name=f"{name}_r")
        if not self.cplx:
            return Vr, lambda: np.array(Vr.value)
        # the skew part with exactly n(n−1)/2 free entries: a variable that appears in no constraint
        # (e.g. the symmetric half of a full n x n matrix) makes the KKT system singular, and the
        # solver's regularisation then costs accuracy.
        k = n * (n - 1) // 2
        if k == 0:
            expr = cp.bmat([[Vr, np.zeros((n, n))], [np.zeros((n, n)), Vr]])
            return expr, lambda: np.array(Vr.value) + 0j
        iu = np.triu_indices(n, 1)
        Mmap = np.zeros((n * n, k))
        for c, (i, j) in enumerate(zip(*iu)):
            Mmap[i + n * j, c] = 1.0  # column-major vec
            Mmap[j + n * i, c] = -1.0
        v = cp.Variable(k, name=f"{name}_i")
        Vs = cp.reshape(Mmap @ v, (n, n), order="F")
        expr = cp.bmat([[Vr, -Vs], [Vs, Vr]])

        def value() -> np.ndarray:
            S = (Mmap @ np.asarray(v.value)).reshape((n, n), order="F")
            return np.array(Vr.value) + 1j * S

        return expr, value

    def quad(self, O: np.ndarray, V: cp.Expression) -> cp.Expression:
        """O^* V O for constant O."""
        Oc = self.c(O)
        return Oc.T @ V @ Oc


def _lyap(F: _Field, a: np.ndarray, b: np.ndarray, V: cp.Expression, c: float, T: float) -> cp.Expression:
    """b^* V b − a^* V a + c·b^* V b, written without cancellation (the Cayley form behind 5.4.1).

    With r = √T (a + b)/2 and v = (b − a)/√T one has b^* V b − a^* V a = r^* V v + v^* V r exactly: the
    discrete block diag(−V, V) on (a, b) is the continuous block [[0, V], [V, 0]] on (r, v). For
    poles near z = 1 (fast sampling) b − a is small, and forming it in numpy keeps the solver from
    having to resolve the difference of two large terms.
    """
    r = F.c(math.sqrt(T) * 0.5 * (a + b))
    v = F.c((b - a) / math.sqrt(T))
    out = r.T @ V @ v + v.T @ V @ r
    if c != 0.0:
        out = out + c * F.quad(b, V)
    return out


def _sym(E: cp.Expression) -> cp.Expression:
    return 0.5 * (E + E.T)


def _diag_var(n: int, name: str) -> tuple[cp.Expression, Callable[[], np.ndarray]]:
    """A real diagonal n x n decision variable (the diagonal multipliers of Thm 7.1)."""
    v = cp.Variable(n, name=name)
    return cp.diag(v), lambda: np.diag(np.asarray(v.value, float))


# --------------------------------------------------------------------------------------------------
# balancing / scaling
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlantScaling:
    """x' = T^{-1} x (T a vector: diagonal; or a full n x n matrix), z_u' = d z_u, w_u' = d w_u, z_p' = z_p / g0.

    Controller I/O unchanged (a state similarity and a scalar on the parameter channel, which commutes with Δ).
    """

    T: np.ndarray
    d: float
    g0: float

    def apply(self, plant: LFTPlant) -> LFTPlant:
        n, nzu, nzp, ny = plant.n_x, plant.n_zu, plant.n_zp, plant.n_y
        nwu, nwp, nu = plant.n_wu, plant.n_wp, plant.n_u
        T = np.asarray(self.T)
        full = T.ndim == 2
        Td = np.ones(n) if full else T
        rs = np.concatenate([1.0 / Td, np.full(nzu, self.d), np.full(nzp, 1.0 / self.g0), np.ones(ny)])
        cs = np.concatenate([Td, np.full(nwu, 1.0 / self.d), np.ones(nwp), np.ones(nu)])
        M = rs[:, None] * plant.M * cs[None, :]
        if full:  # x = T x' with a full (possibly complex) similarity T: A' = T^{-1} A T, ...
            M = M.astype(np.result_type(M, T))
            M[:n, :] = np.linalg.solve(T, M[:n, :])
            M[:, :n] = M[:, :n] @ T
        return plant.with_matrix(M)


def balance_plant(plant: LFTPlant, g0: float = 1.0, *, balance: bool = True) -> PlantScaling:
    """A diagonal state scaling (scipy's matrix_balance on |[[A, B_all], [C_all, 0]]|'s state part) and
    a scalar parameter-channel scaling equalising ‖B_u‖ and ‖C_u‖; g0 scales the performance output."""
    n = plant.n_x
    if not balance or n == 0:
        return PlantScaling(np.ones(n), 1.0, g0)
    A = np.abs(plant.A)
    b = np.linalg.norm(np.abs(plant.M[:n, n:]), axis=1)
    c = np.linalg.norm(np.abs(plant.M[n:, :n]), axis=0)
    G = np.zeros((n + 1, n + 1))
    G[:n, :n] = A
    G[:n, n] = b
    G[n, :n] = c
    _, (s, _) = sla.matrix_balance(G, permute=False, separate=True)
    T = s[:n] / s[n]
    scaled = PlantScaling(T, 1.0, 1.0).apply(plant)
    bu = np.linalg.norm(scaled.B_u) if plant.n_wu else 0.0
    cu = np.linalg.norm(scaled.C_u) if plant.n_zu else 0.0
    d = math.sqrt(bu / cu) if (bu > 0 and cu > 0) else 1.0
    return PlantScaling(T, d, g0)


# --------------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------------
@dataclass(eq=False)
class SynthesisResult:
    """Solution of Thm 5.15 for the *scaled* plant `plant` (gamma is in the original units).

    X, Y, P, Pt are numpy (complex for complex plants), for `plant` whose performance output is
    divided by ``scaling.g0``; the index there is diag(−γ' I, I/γ') with γ' = gamma / g0.
    """

    feasible: bool
    gamma: float
    X: np.ndarray
    Y: np.ndarray
    P: np.ndarray
    Pt: np.ndarray
    plant: LFTPlant
    params: ParameterSet
    scaling: PlantScaling
    beta: float
    margin: float
    status: str
    solve_time: float
    residuals: dict[str, float] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    @property
    def gamma_scaled(self) -> float:
        return self.gamma / self.scaling.g0


# --------------------------------------------------------------------------------------------------
# the LMIs
# --------------------------------------------------------------------------------------------------
def _lmi_blocks(plant: LFTPlant) -> dict[str, np.ndarray]:
    """Constant data of (5.61)/(5.62): annihilators and the outer factors' rows."""
    p = plant
    n, nwu, nwp, nzu, nzp = p.n_x, p.n_wu, p.n_wp, p.n_zu, p.n_zp
    Psi = null_basis(np.hstack([p.C, p.F_u, p.F_p]))  # Ψ = [C F_u F_p]^⊥
    Phi = null_basis(np.hstack([p.B.conj().T, p.E_u.conj().T, p.E_p.conj().T]))  # Φ = [B^* E_u^* E_p^*]^⊥
    dt = np.result_type(p.M, float)
    I = lambda k: np.eye(k, dtype=dt)  # noqa: E731
    Z = lambda r, c: np.zeros((r, c), dtype=dt)  # noqa: E731
    # X-side rows, columns [x; w_u; w_p]
    x_now = np.hstack([I(n), Z(n, nwu), Z(n, nwp)])
    x_next = np.hstack([p.A, p.B_u, p.B_p])
    w_u = np.hstack([Z(nwu, n), I(nwu), Z(nwu, nwp)])
    z_u = np.hstack([p.C_u, p.D_uu, p.D_up])
    w_p = np.hstack([Z(nwp, n), Z(nwp, nwu), I(nwp)])
    z_p = np.hstack([p.C_p, p.D_pu, p.D_pp])
    # Y-side rows, columns [x; z_u; z_p] (dual)
    y_1 = -np.hstack([p.A.conj().T, p.C_u.conj().T, p.C_p.conj().T])
    y_2 = np.hstack([I(n), Z(n, nzu), Z(n, nzp)])
    wt_u = -np.hstack([p.B_u.conj().T, p.D_uu.conj().T, p.D_pu.conj().T])
    zt_u = np.hstack([Z(nzu, n), I(nzu), Z(nzu, nzp)])
    G = -np.hstack([p.B_p.conj().T, p.D_up.conj().T, p.D_pp.conj().T])
    zt_p = np.hstack([Z(nzp, n), Z(nzp, nzu), I(nzp)])
    return dict(Psi=Psi, Phi=Phi, x_now=x_now, x_next=x_next, w_u=w_u, z_u=z_u, w_p=w_p, z_p=z_p,
                y_1=y_1, y_2=y_2, wt_u=wt_u, zt_u=zt_u, G=G, zt_p=zt_p)  # fmt: skip


def lmi_residuals(
    plant: LFTPlant, params: ParameterSet, X: np.ndarray, Y: np.ndarray, P: np.ndarray, Pt: np.ndarray,
    gamma: float, beta: float = 0.0,
) -> dict[str, float]:
    """Evaluate every LMI of Thm 5.15 in numpy at a given point; returns the signed margins.

    Each value is the largest eigenvalue of the matrix that must be negative definite (so a
    solution has all values < 0); (5.60) is reported as −λ_min([X I; I Y]) (≤ 0 means satisfied).
    `gamma` is the index of `plant` (i.e. the scaled γ' for a scaled plant).
    """
    b = _lmi_blocks(plant)
    rho = 1.0 - beta
    n, nwu, nzu = plant.n_x, plant.n_wu, plant.n_zu
    Psi, Phi = b["Psi"], b["Phi"]
    MX = (-b["x_now"].conj().T @ X @ b["x_now"] + rho**-2 * b["x_next"].conj().T @ X @ b["x_next"]
          + np.vstack([b["w_u"], b["z_u"]]).conj().T @ P @ np.vstack([b["w_u"], b["z_u"]])
          - gamma * b["w_p"].conj().T @ b["w_p"])  # fmt: skip
    LX = np.block([[Psi.conj().T @ MX @ Psi, Psi.conj().T @ b["z_p"].conj().T],
                   [b["z_p"] @ Psi, -gamma * np.eye(plant.n_zp)]])  # fmt: skip
    MY = (-b["y_1"].conj().T @ Y @ b["y_1"] + rho**2 * b["y_2"].conj().T @ Y @ b["y_2"]
          + np.vstack([b["wt_u"], b["zt_u"]]).conj().T @ Pt @ np.vstack([b["wt_u"], b["zt_u"]])
          + gamma * b["zt_p"].conj().T @ b["zt_p"])  # fmt: skip
    LY = np.block([[Phi.conj().T @ MY @ Phi, Phi.conj().T @ b["G"].conj().T],
                   [b["G"] @ Phi, gamma * np.eye(plant.n_wp)]])  # fmt: skip
    out = {
        "(5.60)": -float(np.linalg.eigvalsh(_herm(np.block([[X, np.eye(n)], [np.eye(n), Y]])))[0]),
        "(5.61)": float(np.linalg.eigvalsh(_herm(LX))[-1]),
        "(5.62)": -float(np.linalg.eigvalsh(_herm(LY))[0]),
    }
    if nwu + nzu:
        out["Q<0"] = float(np.linalg.eigvalsh(_herm(P[:nwu, :nwu]))[-1])
        out["Rt>0"] = -float(np.linalg.eigvalsh(_herm(Pt[nwu:, nwu:]))[0])
        worst_p, worst_pt = -np.inf, -np.inf
        for D in params.generators:
            S = np.vstack([D, np.eye(nzu)])
            St = np.vstack([np.eye(nwu), -D.conj().T])
            worst_p = max(worst_p, -float(np.linalg.eigvalsh(_herm(S.conj().T @ P @ S))[0]))
            worst_pt = max(worst_pt, float(np.linalg.eigvalsh(_herm(St.conj().T @ Pt @ St))[-1]))
        out["(5.59) P"] = worst_p
        out["(5.59) Pt"] = worst_pt
    return out


def _diagonal_box(params: ParameterSet) -> bool:
    """True if the generators are exactly the 2^n vertices of a box of real diagonal Δ."""
    g = params.generators
    if not g or g[0].shape[0] != g[0].shape[1] or g[0].shape[0] == 0:
        return False
    if any(np.iscomplexobj(D) and np.any(np.imag(D)) for D in g):
        return False
    if any(np.any(np.abs(D - np.diag(np.diag(D))) > 0) for D in g):
        return False
    diags = np.array([np.real(np.diag(D)) for D in g])
    lo, hi = diags.min(axis=0), diags.max(axis=0)
    want = {tuple(c) for c in itertools.product(*[(a, b) for a, b in zip(lo, hi)])}
    return {tuple(r) for r in diags} == want and len(g) == len(want)


class SynthesisProblem:
    """The LMIs of Thm 5.15 for one plant, compiled once; γ is a cvxpy Parameter (DPP).

    `feasibility(gamma)` maximises the common strictness margin t (feasible iff t > `tol`);
    `minimize()` minimises γ with a fixed margin `eps`. Use `synthesize`/`minimize_gamma`/`bisect_gamma`.

    Hooks (Ch. 7): ``multipliers="diagonal"`` restricts P = diag(Q, R), P̃ = diag(Q̃, R̃) with diagonal
    Q, R, Q̃, R̃ and S = S̃ = 0 (7.2)-(7.6) (real plants, square Δ); `constraints` adds convex constraints
    on P, P̃ (`MultiplierConstraints`); `centering(got)` replaces the objective of `centered` (it gets
    the solver-side expressions ``X_expr, Y_expr, P_expr, Pt_expr``).
    """

    def __init__(
        self,
        plant: LFTPlant,
        params: ParameterSet,
        *,
        beta: float = 0.0,
        g0: float = 1.0,
        balance: bool = True,
        x_bound: float = 1e6,
        mult_bound: float = 1e6,
        eps: float = 1e-7,
        tol: float = 1e-7,
        solver_opts: dict | None = None,
        scaling: PlantScaling | None = None,
        multipliers: str = "full",
        constraints: MultiplierConstraints | None = None,
        centering: Callable[[dict], cp.Expression] | None = None,
    ) -> None:
        if plant.dt is None:
            raise ValueError("Thm 5.15 is for discrete plants; discretise first (synthesis.discretize)")
        if np.any(np.abs(plant.F_3) > 0):
            raise ValueError("F_3 must be 0 (Remark 5.7); use synthesis.lft.remove_feedthrough first")
        if (plant.n_wu, plant.n_zu) != params.shape:
            raise ValueError(f"generators are {params.shape}, plant's Δ must be {plant.n_wu}x{plant.n_zu}")
        if not 0.0 <= beta < 1.0:
            raise ValueError("decay margin beta must lie in [0, 1)")
        if multipliers not in ("full", "diagonal", "multiconvex"):
            raise ValueError(f"multipliers must be 'full', 'diagonal' or 'multiconvex', got {multipliers!r}")
        if multipliers == "multiconvex" and not _diagonal_box(params):
            raise ValueError("multiconvex multipliers need a box of diagonal Δ (generators = its vertices)")
        self.original = plant
        self.params = params
        self.beta = beta
        self.scaling = balance_plant(plant, g0, balance=balance) if scaling is None else scaling
        self.plant = self.scaling.apply(plant)
        self.x_bound, self.mult_bound, self.eps, self.tol = x_bound, mult_bound, eps, tol
        self.solver_opts = {**DEFAULT_SOLVER_OPTS, **(solver_opts or {})}
        self.cplx = _is_complex(self.plant.M) or any(_is_complex(g) for g in params.generators)
        if multipliers == "diagonal" and (self.cplx or plant.n_wu != plant.n_zu):
            raise ValueError("diagonal multipliers (Ch. 7) need a real plant with a square parameter block")
        self.multipliers, self.constraints, self.centering = multipliers, constraints, centering
        self._feas: tuple | None = None
        self._mini: tuple | None = None

    # -- building ---------------------------------------------------------------------------------
    def _build(self, gamma: cp.Expression, margin: cp.Expression) -> tuple[list, dict]:
        p, F = self.plant, _Field(self.cplx)
        b = _lmi_blocks(p)
        n, nwu, nzu, nwp, nzp = p.n_x, p.n_wu, p.n_zu, p.n_wp, p.n_zp
        rho = 1.0 - self.beta
        X, getX = F.herm(n, "X")
        Y, getY = F.herm(n, "Y")
        has_par = nwu + nzu > 0
        if has_par and self.multipliers == "diagonal":
            P, getP = _diag_var(nwu + nzu, "P")  # diag(Q, R), S = 0  (7.2), (7.3), (7.6)
            Pt, getPt = _diag_var(nwu + nzu, "Pt")  # diag(Q̃, R̃), S̃ = 0  (7.4)-(7.6)
        elif has_par:
            P, getP = F.herm(nwu + nzu, "P")
            Pt, getPt = F.herm(nwu + nzu, "Pt")
        cons = []
        # (5.60)
        cons.append(_sym(cp.bmat([[X, F.eye(n)], [F.eye(n), Y]])) >> 0)
        # (5.61) with the γ^{-1} C_r^* C_r term as a Schur complement
        Psi = b["Psi"]
        MX = (_lyap(F, b["x_now"] @ Psi, b["x_next"] @ Psi, X, rho**-2 - 1.0, p.dt)
              - gamma * F.c(Psi.conj().T @ b["w_p"].conj().T @ b["w_p"] @ Psi))  # fmt: skip
        if has_par:
            MX = MX + F.quad(np.vstack([b["w_u"], b["z_u"]]) @ Psi, P)
        CrPsi = F.c(b["z_p"] @ Psi)
        LX = cp.bmat([[MX, CrPsi.T], [CrPsi, -gamma * F.eye(nzp)]])
        cons.append(_sym(LX) + margin * np.eye(LX.shape[0]) << 0)
        # (5.62) with the −γ^{-1} G^* G term as a Schur complement
        Phi = b["Phi"]
        MY = (_lyap(F, b["y_1"] @ Phi, b["y_2"] @ Phi, Y, rho**2 - 1.0, p.dt)
              + gamma * F.c(Phi.conj().T @ b["zt_p"].conj().T @ b["zt_p"] @ Phi))  # fmt: skip
        if has_par:
            MY = MY + F.quad(np.vstack([b["wt_u"], b["zt_u"]]) @ Phi, Pt)
        GPhi = F.c(b["G"] @ Phi)
        LY = cp.bmat([[MY, GPhi.T], [GPhi, gamma * F.eye(nwp)]])
        cons.append(_sym(LY) - margin * np.eye(LY.shape[0]) >> 0)
        # bounds
        cons += [X << self.x_bound * F.eye(n), Y << self.x_bound * F.eye(n)]
        got = {"X": getX, "Y": getY, "X_expr": X, "Y_expr": Y}
        if has_par:
            # (5.59) on the generators + the convex inertia constraints of 5.3.3
            for D in self.params.generators:
                S = np.vstack([D, np.eye(nzu)])
                St = np.vstack([np.eye(nwu), -D.conj().T])
                cons.append(_sym(F.quad(S, P)) - margin * F.eye(nzu) >> 0)
                cons.append(_sym(F.quad(St, Pt)) + margin * F.eye(nwu) << 0)
            Ew = np.vstack([np.eye(nwu), np.zeros((nzu, nwu))])
            Ez = np.vstack([np.zeros((nwu, nzu)), np.eye(nzu)])
            if self.multipliers == "multiconvex":
                # Q_ii < 0, R̃_ii > 0 only: [Δ; I]*P[Δ; I] is then concave (and the P̃ form convex) in each δ_i
                # separately, so (5.59) on the vertices of the box implies it on the box (5.3.3, relaxed)
                for i in range(nwu):
                    cons.append(_sym(F.quad(Ew[:, [i]], P)) + margin * F.eye(1) << 0)
                    cons.append(_sym(F.quad(Ez[:, [i]], Pt)) - margin * F.eye(1) >> 0)
            else:
                cons.append(_sym(F.quad(Ew, P)) + margin * F.eye(nwu) << 0)  # Q < 0
                cons.append(_sym(F.quad(Ez, Pt)) - margin * F.eye(nzu) >> 0)  # R̃ > 0
            mb = self.mult_bound * F.eye(nwu + nzu)
            cons += [P << mb, P >> -mb, Pt << mb, Pt >> -mb]
            if self.constraints is not None:
                cons += self.constraints.build(P, Pt, margin)
            got.update(P=getP, Pt=getPt, P_expr=P, Pt_expr=Pt)
        else:
            z = np.zeros((0, 0))
            got.update(P=lambda: z, Pt=lambda: z)
        return cons, got

    def _solve(self, prob: cp.Problem, opts_override: dict | None = None) -> tuple[str, float]:
        """Solve with Clarabel; on a solver error or a non-optimal status retry with the other settings
        (tight ↔ Clarabel's defaults). Feasibility is decided later by the numpy re-check anyway."""
        t0 = time.perf_counter()
        first = self.solver_opts if opts_override is None else opts_override
        second = {} if first else self.solver_opts
        status = "not solved"
        for opts in (first, second):
            try:
                prob.solve(solver=cp.CLARABEL, **opts)
                status = str(prob.status)
            except cp.SolverError as e:
                status = f"solver_error: {e}"
                continue
            if status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
                break
        if status == cp.OPTIMAL_INACCURATE:
            warnings.warn("LMI solver returned optimal_inaccurate; re-checking eigenvalues", LMIWarning, stacklevel=3)
        return status, time.perf_counter() - t0

    def _result(self, feasible_hint: bool, gamma_s: float, margin: float, status: str, t: float, got: dict,
                mode: str) -> SynthesisResult:
        ok_status = status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
        if ok_status:
            X, Y, P, Pt = (_herm(got[k]()) for k in ("X", "Y", "P", "Pt"))
            res = lmi_residuals(self.plant, self.params, X, Y, P, Pt, gamma_s, self.beta)
            if self.constraints is not None:
                res.update(self.constraints.residuals(P, Pt))
            # numerically re-checked: strict LMIs negative, coupling (non-strict) up to round-off
            strict = [v for k, v in res.items() if k != "(5.60)"]
            feasible = feasible_hint and all(v < 0 for v in strict) and res["(5.60)"] <= 1e-8 * self.x_bound
        else:
            n = self.plant.n_x
            X = Y = np.full((n, n), np.nan)
            P = Pt = np.full((self.plant.n_wu + self.plant.n_zu,) * 2, np.nan)
            res, feasible = {}, False
        return SynthesisResult(
            feasible=bool(feasible), gamma=float(gamma_s * self.scaling.g0), X=X, Y=Y, P=P, Pt=Pt,
            plant=self.plant, params=self.params, scaling=self.scaling, beta=self.beta,
            margin=float(margin), status=status, solve_time=t, residuals=res,
            settings=dict(mode=mode, x_bound=self.x_bound, mult_bound=self.mult_bound, eps=self.eps,
                          tol=self.tol, complex_formed=self.cplx, solver="CLARABEL", cvxpy=cp.__version__,
                          g0=self.scaling.g0, d=self.scaling.d, T=self.scaling.T.tolist(), beta=self.beta,
                          multipliers=self.multipliers),
        )  # fmt: skip

    # -- public -----------------------------------------------------------------------------------
    def feasibility(self, gamma: float) -> SynthesisResult:
        """Maximise the margin t ≤ 1 at fixed γ (original units); feasible iff t > tol and the re-check passes."""
        if self._feas is None:
            g = cp.Parameter(nonneg=True, name="gamma")
            t = cp.Variable(name="t")
            cons, got = self._build(g, t)
            prob = cp.Problem(cp.Maximize(t), cons + [t <= 1.0])
            self._feas = (prob, g, t, got)
        prob, g, t, got = self._feas
        g.value = gamma / self.scaling.g0
        status, el = self._solve(prob)
        ok = status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) and t.value is not None
        tv = float(t.value) if ok else -np.inf
        return self._result(tv > self.tol, g.value, tv, status, el, got, "feasibility")

    def centered(self, gamma: float, margin_frac: float = 0.5, objective: str = "dual") -> SynthesisResult:
        """A solution at fixed γ shaped for the construction (5.3.4).

        First the largest margin t* (`feasibility`); then, with the margin fixed at margin_frac·t*, the
        *dual* variables made small: minimise tr(Y)/n + s with −s I ⪯ P̃ ⪯ s I (``objective="dual"``),
        or (``objective="trace"``) minimise (tr X + tr Y)/n, the usual heuristic that pushes
        [X I; I Y] towards low rank: X − Y^{-1} nearly singular, which allows order reduction (6.2.2),
        and keeps X, Y away from their bounds in nearly singular problems (the current controller).
        A `centering` hook given to the problem replaces the "dual" objective (Ch. 7: tr(R − Q̃)).

        Maximising the margin alone drives X, Y, P, P̃ to their bounds; the extended matrices of (5.30)
        and (5.32) then have condition numbers of about ‖X‖‖Y‖ and ‖P‖‖P̃‖ and the QMI of the
        construction becomes numerically indefinite. Small Y, P̃ keep those products down. (Also
        normalising X and P in the objective was tried: Clarabel then stalls at the starting point.)
        """
        first = self.feasibility(gamma)
        if not first.feasible:
            return first
        if objective not in ("dual", "trace"):
            raise ValueError(f"objective must be 'dual' or 'trace', got {objective!r}")
        cache = getattr(self, "_cent", None) or {}
        self._cent = cache
        if objective not in cache:
            g = cp.Parameter(nonneg=True, name="gamma")
            tm = cp.Parameter(nonneg=True, name="margin")
            cons, got = self._build(g, tm)
            F = _Field(self.cplx)
            obj = cp.trace(got["Y_expr"]) / F.eye(self.plant.n_x).shape[0]
            if objective == "dual" and self.centering is not None:  # the hook replaces the default objective
                obj = self.centering(got)
            elif objective == "trace":
                obj = obj + cp.trace(got["X_expr"]) / F.eye(self.plant.n_x).shape[0]
            elif "Pt_expr" in got:
                s_ = cp.Variable(name="s")
                k = F.eye(self.plant.n_wu + self.plant.n_zu)
                cons += [got["Pt_expr"] << s_ * k, got["Pt_expr"] >> -s_ * k]
                obj = obj + s_
            prob = cp.Problem(cp.Minimize(obj), cons)
            cache[objective] = (prob, g, tm, got)
        prob, g, tm, got = cache[objective]
        g.value = gamma / self.scaling.g0
        tm.value = margin_frac * first.margin
        # Clarabel's own defaults here: the margin is fixed and the problem well posed; the tight
        # settings of the feasibility test make it fail.
        status, el = self._solve(prob, {})
        res = self._result(True, g.value, tm.value, status, el, got,
                           "centered" if objective == "dual" else f"centered ({objective})")
        if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
            return first
        if not res.feasible:  # fall back to the max-margin point
            return first
        res.solve_time += first.solve_time
        return res

    def minimize(self) -> SynthesisResult:
        """Minimise γ subject to the LMIs with the fixed margin eps."""
        if self._mini is None:
            g = cp.Variable(nonneg=True, name="gamma")
            cons, got = self._build(g, self.eps)
            prob = cp.Problem(cp.Minimize(g), cons)
            self._mini = (prob, g, got)
        prob, g, got = self._mini
        status, el = self._solve(prob)
        gv = float(g.value) if g.value is not None else np.inf
        return self._result(True, gv, self.eps, status, el, got, "minimize")


def _auto_g0(plant: LFTPlant, params: ParameterSet, beta: float, balance: bool) -> float:
    """A first γ with unit performance scaling, used as g0 so that the scaled γ' is O(1)."""
    loose = dict(static_regularization_constant=1e-8, tol_feas=1e-8, tol_gap_abs=1e-8, tol_gap_rel=1e-8)
    r = SynthesisProblem(plant, params, beta=beta, balance=balance, g0=1.0, solver_opts=loose).minimize()
    if r.feasible and np.isfinite(r.gamma) and r.gamma > 0:
        return float(r.gamma)
    # fall back: the first decade in which the feasibility test succeeds
    prob = SynthesisProblem(plant, params, beta=beta, balance=balance, g0=1.0, solver_opts=loose)
    for e in range(-8, 7):
        if prob.feasibility(10.0**e).feasible:
            return 10.0**e
    return 1.0


def minimize_gamma(
    plant: LFTPlant, params: ParameterSet, *, beta: float = 0.0, g0: float | None = None, balance: bool = True,
    **kw: float,
) -> SynthesisResult:
    """γ_a by one SDP: minimise γ over (5.59)-(5.62) (two passes when g0 is None: scale, then solve).

    The minimiser lies on the boundary (margin eps only), so its `feasible` flag -- the numpy re-check
    at exactly that γ -- may be False by round-off: use `.gamma` as an estimate of γ_a (it agrees with
    `bisect_gamma` to a fraction of a percent on the test plants) and `synthesize` for a construction.
    """
    if g0 is None:
        g0 = _auto_g0(plant, params, beta, balance)
    return SynthesisProblem(plant, params, beta=beta, g0=g0, balance=balance, **kw).minimize()


def rescale_from_solution(scaling: PlantScaling, X: np.ndarray, Y: np.ndarray) -> PlantScaling:
    """Re-balance the state coordinates from a solution: T ← T·(Y_ii/X_ii)^{1/4} (geometric mean 1).

    This equalises the diagonals of X and Y^{...} in the new coordinates (x' = T^{-1} x gives
    X' = T X T, Y' = T^{-1} Y T^{-1}), the "balancing of the model" that 5.6.2 does before solving.
    """
    xd = np.abs(np.real(np.diag(X)))
    yd = np.abs(np.real(np.diag(Y)))
    if not (np.all(np.isfinite(xd)) and np.all(np.isfinite(yd)) and np.all(xd > 0) and np.all(yd > 0)):
        return scaling
    f = (yd / xd) ** 0.25
    f = f / np.exp(np.mean(np.log(f)))
    T = np.asarray(scaling.T)
    return PlantScaling(T @ np.diag(f) if T.ndim == 2 else T * f, scaling.d, scaling.g0)


def balance_from_solution(scaling: PlantScaling, X: np.ndarray, Y: np.ndarray, P: np.ndarray | None = None,
                          Pt: np.ndarray | None = None) -> PlantScaling:
    """Re-balance state coordinates *and* the parameter channel from a solution (full similarity).

    States: with Y = R R^* and R^* X R = U Σ² U^*, the similarity T_b = R U Σ^{-1/2} gives
    X' = T_b^* X T_b = Σ and Y' = T_b^{-1} Y T_b^{-*} = Σ (a balanced pair, both diagonal and equal).
    Parameter channel: P scales as P/d², P̃ as d² P̃, so d ← d (‖P‖/‖P̃‖)^{1/4} equalises them.
    Measured on the flux observer (5.6.2): the diagonal `rescale_from_solution` leaves X, Y, P at their
    bounds and γ_a at 2.5x the frozen lower bound; this balancing reaches it (`bisect_gamma(rescale="full")`).
    """
    X, Y = _herm(np.asarray(X)), _herm(np.asarray(Y))
    n = X.shape[0]
    if n == 0 or not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
        return scaling
    try:
        R = np.linalg.cholesky(Y)
        w, U = np.linalg.eigh(_herm(R.conj().T @ X @ R))
    except np.linalg.LinAlgError:
        return scaling
    if not np.all(w > 0):
        return scaling
    Tb = R @ U @ np.diag(w**-0.25)
    T = np.asarray(scaling.T)
    T = (T if T.ndim == 2 else np.diag(T)) @ Tb
    d = scaling.d
    if P is not None and Pt is not None and P.size and Pt.size:
        nP, nPt = float(np.max(np.abs(np.linalg.eigvalsh(_herm(P))))), float(np.max(np.abs(np.linalg.eigvalsh(_herm(Pt)))))
        if nP > 0 and nPt > 0 and np.isfinite(nP) and np.isfinite(nPt):
            d = d * (nP / nPt) ** 0.25
    return PlantScaling(T, d, scaling.g0)


def _balance_error(res: SynthesisResult) -> float:
    """How far a solution is from balanced (X = Y, ‖P‖ = ‖P̃‖), relative: 0 at the fixed point of
    `balance_from_solution`."""
    e = float(np.abs(res.X - res.Y).max() / np.abs(res.X).max())
    if res.P.size and res.Pt.size:
        nP, nPt = (float(np.abs(np.linalg.eigvalsh(_herm(M))).max()) for M in (res.P, res.Pt))
        e = max(e, abs(math.log(nP / nPt)))
    return e


def balanced_centre(plant: LFTPlant, params: ParameterSet, gamma: float, scaling: PlantScaling, *,
                    margin_frac: float = 0.5, tol: float = 0.02, max_steps: int = 6, objective: str = "dual",
                    halvings: int = 0, **kw: Any) -> SynthesisResult:  # fmt: skip
    """The centred solution at γ (`SynthesisProblem.centered`) in its own balanced coordinates: a design that is a
    continuous function of the plant.

    `centered`'s solution depends on the coordinates it is solved in (its objective, tr Y + ‖P̃‖, and its margin
    t·I are not invariant under a state similarity or the parameter-channel scalar), and a bisection's scaling
    depends on its path (which γ's it tried). So the centred solution at the bisection's scaling jumps with the
    model: on the flux observer (5.6.2) R_r moved by 10⁻⁶ moved the observer's response by 5 %. Here the scaling is
    re-balanced from each solution (`balance_from_solution`; from the second solve on the performance scaling is
    g0 = γ: at the bisection's g0 the fixed point depends on it, and a first solve at g0 = γ can fail) and the
    centring solved again, until the solution is balanced to ``tol`` (X = Y, ‖P‖ = ‖P̃‖: the fixed point, reached
    in 3 solves on the flux observer): from two different start scalings the responses then agree to 0.04 %, and a
    relative model step ε moves them by about ε (docs/results/fleet-commission.md). ``scaling`` is the start (the
    bisection's). ``objective``: `centered`'s. An infeasible or failed step keeps the last feasible solution; the
    first step's result is returned if none is. With ``halvings`` > 0 a failed step is first tried again that many
    times from half-way between the last feasible scaling and the failed one (`_half_way`): the fixed point is the
    same, only the path to it is shorter (measured on the current controller of 6.2.2, whose trace centring Clarabel
    sometimes cannot solve one full re-balancing step away).
    """
    S, last = scaling, None
    best: SynthesisResult | None = None
    res = None
    step = halved = 0
    while step < max_steps:
        res = SynthesisProblem(plant, params, scaling=S, **kw).centered(gamma, margin_frac=margin_frac,
                                                                        objective=objective)  # fmt: skip
        # (with halvings, `centered`'s fall-back to the max-margin point counts as a failed step)
        if not res.feasible or (halvings and res.settings["mode"] == "feasibility"):
            if last is None or halved >= halvings:
                break
            S, halved = _half_way(last, S, gamma), halved + 1
            continue
        best = res
        best.settings["balance_steps"] = step + 1
        if step > 0 and _balance_error(res) <= tol:  # step 0 ran at the start scaling's g0
            break
        b = balance_from_solution(S, res.X, res.Y, res.P, res.Pt)
        last, S = S, PlantScaling(b.T, b.d, gamma)
        step += 1
    assert res is not None
    return best if best is not None else res


def _half_way(a: PlantScaling, b: PlantScaling, g0: float) -> PlantScaling:
    """The scaling half-way from ``a`` to ``b``: T_a (T_a^{-1} T_b)^{1/2} and the geometric mean of d."""
    Ta, Tb = (np.asarray(s.T) if np.asarray(s.T).ndim == 2 else np.diag(s.T) for s in (a, b))
    return PlantScaling(Ta @ sla.sqrtm(np.linalg.solve(Ta, Tb)), math.sqrt(a.d * b.d), g0)


@dataclass(eq=False)
class BisectionResult:
    """γ_a from `bisect_gamma`: the smallest γ found feasible, the solution there, and the history."""

    gamma_a: float
    result: SynthesisResult
    history: list[tuple[float, bool]]
    scaling: PlantScaling
    iterations: list[float]
    wall_time: float
    n_solves: int


def _bisect_at(prob: SynthesisProblem, top: float, lower_bound: float | None, rtol: float, max_iter: int,
               hist: list[tuple[float, bool]]) -> tuple[float, SynthesisResult, int]:  # fmt: skip
    """One bisection at ``prob``'s scaling: from ``top`` up by 4x until feasible, then down to ``rtol`` (from the
    certified ``lower_bound`` where it is below); each test appended to ``hist``. Returns the feasible γ found,
    its solution and the number of solves."""
    best = prob.feasibility(top)
    n_solves = 1
    hist.append((top, best.feasible))
    grow = 0
    while not best.feasible:
        top *= 4.0
        best = prob.feasibility(top)
        n_solves += 1
        hist.append((top, best.feasible))
        grow += 1
        if grow > 10:
            raise RuntimeError(f"no feasible γ up to {top:g}")
    lo = 0.0 if lower_bound is None or lower_bound >= top else float(lower_bound)
    up = top
    for _ in range(max_iter):
        if up - lo <= rtol * up:
            break
        mid = 0.5 * (lo + up)
        r = prob.feasibility(mid)
        n_solves += 1
        hist.append((mid, r.feasible))
        if r.feasible:
            up, best = mid, r
        else:
            lo = mid
    return up, best, n_solves


#: `bisect_gamma`'s re-balancing stalled above this multiple of the certified lower bound is escaped (`_escape`)
ESCAPE_GAP: float = 1.01
#: escapes per bisection (each of the measured stalls needed one)
MAX_ESCAPES: int = 3
#: factors of the pattern search `_escape` tries on each balanced state, in turn
ESCAPE_FACTORS: tuple[float, ...] = (1e-1, 1e-2, 1e-3, 1e1, 1e2, 1e3)


def _escape(plant: LFTPlant, params: ParameterSet, scaling: PlantScaling, gamma_a: float, lower_bound: float,
            beta: float, kw: dict[str, Any]) -> tuple[PlantScaling | None, float, int]:  # fmt: skip
    """A scaling feasible below ``gamma_a`` from a stalled one: (the scaling or None, the level it is feasible at,
    the number of solves).

    Each state of ``scaling`` is multiplied by each of `ESCAPE_FACTORS` in turn (a pattern search) and the first
    scaling feasible at the target is returned. Targets, the lower first: the geometric mean of γ_a and the bound,
    and 1 % below γ_a (the mean may be below the LMIs' own optimum near the bound: 1.01-1.041x for the thesis' reading
    at 3 kHz).

    The re-balancing (`balance_from_solution`) is a fixed-point iteration on the solution's X, Y; where the optimum
    needs one state scaled far from balance it crawls (measured: two random motors' flux observers at 400 rad/s,
    3 kHz, crawl from 46x to 20x the bound in 8 steps and stop there; which continuation path over ω_r,max escaped
    depended on the BLAS kernel's round-off). Scaling that state's column of T by 1e-2 or 1e-3 is feasible at the
    geometric mean under every kernel tried, and the bisections from there reach 1.002x."""
    T = np.asarray(scaling.T)
    n = T.shape[0]
    solves = 0
    for target in sorted({math.sqrt(lower_bound * gamma_a), gamma_a / 1.01}):
        for i in range(n):
            for f in ESCAPE_FACTORS:
                D = np.ones(n)
                D[i] = f
                trial = PlantScaling(T @ np.diag(D) if T.ndim == 2 else T * D, scaling.d, scaling.g0)
                solves += 1
                if SynthesisProblem(plant, params, beta=beta, scaling=trial, **kw).feasibility(target).feasible:
                    return trial, target, solves
    return None, 0.0, solves


def _rebalanced(prob: SynthesisProblem, best: SynthesisResult, gamma_a: float) -> tuple[PlantScaling, int]:
    """`bisect_gamma`'s full re-balancing: the scaling from a trace-minimising solution at 1.02·γ_a (the max-margin
    point ``best`` where that fails), and the number of solves."""
    src, n = best, 0
    try:
        c = prob.centered(1.02 * gamma_a, objective="trace")
        n = 2
        if c.feasible:
            src = c
    except Exception:  # noqa: BLE001 -- a failed centring keeps the max-margin point
        pass
    return balance_from_solution(prob.scaling, src.X, src.Y, src.P, src.Pt), n


def bisect_gamma(
    plant: LFTPlant,
    params: ParameterSet,
    *,
    hi: float | None = None,
    rtol: float = 2e-3,
    beta: float = 0.0,
    g0: float | None = None,
    balance: bool = True,
    rescale_iters: int = 6,
    rescale_rtol: float = 0.02,
    max_iter: int = 40,
    rescale: str = "diagonal",
    lower_bound: float | None = None,
    scaling: PlantScaling | None = None,
    **kw: float,
) -> BisectionResult:
    """Bisection on γ with feasibility tests (5.6.2), with re-balancing of the model between bisections.

    Each feasibility test maximises the strictness margin (`SynthesisProblem.feasibility`, compiled once per
    scaling). γ_a of these LMIs depends on the model's scaling through the solver's accuracy and the bounds on X, Y
    and the multipliers (the "numerical effect" 5.6.2 reports for Fig. 5.5), so after a bisection the scaling is
    updated from the solution and the bisection repeated, at most ``rescale_iters`` times: ``"diagonal"`` rescales
    the states (`rescale_from_solution`) until γ_a changes by less than ``rescale_rtol``; ``"full"`` re-balances
    with a full state similarity and the parameter-channel scalar (`balance_from_solution`) from a trace-minimising
    solution at 1.02·γ_a (better conditioned than the max-margin point, whose X, Y, P sit at their bounds) until two
    re-balancings gain nothing, and a stall above `ESCAPE_GAP` x ``lower_bound`` is escaped (`_escape`).
    ``lower_bound`` (e.g. `synthesis.lower_bound.lpv_lower_bound`): a certified infeasible level; bisections start
    there, and the re-balancing stops once γ_a ≤ (1 + 2 rtol)·lower_bound. ``scaling``: a starting scaling.
    """
    if rescale not in ("diagonal", "full"):
        raise ValueError(f"rescale must be 'diagonal' or 'full', got {rescale!r}")
    t0 = time.perf_counter()
    if scaling is None:
        if g0 is None:
            g0 = _auto_g0(plant, params, beta, balance)
        scaling = balance_plant(plant, g0, balance=balance)
    hist: list[tuple[float, bool]] = []
    iters: list[float] = []
    n_solves = 0
    best_overall: tuple[float, SynthesisResult, PlantScaling] | None = None
    hi_k = scaling.g0 * 1.5 if hi is None else hi
    budget, escapes, since = rescale_iters + 1, 0, 0  # since: bisections since the last escape
    while len(iters) < budget:
        prob = SynthesisProblem(plant, params, beta=beta, scaling=scaling, **kw)
        up, best, n = _bisect_at(prob, hi_k, lower_bound, rtol, max_iter, hist)
        n_solves += n
        iters.append(up)
        since += 1
        if best_overall is None or up < best_overall[0]:
            best_overall = (up, best, scaling)
        if lower_bound is not None and best_overall[0] <= (1.0 + 2.0 * rtol) * lower_bound:
            break
        if rescale == "diagonal" and len(iters) > 1 and abs(iters[-2] - up) <= rescale_rtol * up:
            break
        stalled = since >= 3 and min(iters[-2:]) >= (1.0 - rescale_rtol) * min(iters[-since:-2])
        if rescale == "full" and (stalled or len(iters) == budget):  # no gain in two rescalings, or out of steps
            if lower_bound is None or best_overall[0] <= ESCAPE_GAP * lower_bound or escapes == MAX_ESCAPES:
                break
            esc, target, n = _escape(plant, params, best_overall[2], best_overall[0], lower_bound, beta, kw)
            n_solves += n
            if esc is None:
                break
            scaling, escapes, since, budget = esc, escapes + 1, 0, len(iters) + rescale_iters + 1
            hi_k = target * (1.0 + rtol)
            continue
        if rescale == "full":
            scaling, n = _rebalanced(prob, best, up)
            n_solves += n
        else:
            scaling = rescale_from_solution(scaling, best.X, best.Y)
        hi_k = 1.05 * best_overall[0]
    assert best_overall is not None
    ga, res, sc = best_overall
    return BisectionResult(ga, res, hist, sc, iters, time.perf_counter() - t0, n_solves)


def synthesize(
    plant: LFTPlant, params: ParameterSet, gamma: float, *, beta: float = 0.0, g0: float | None = None,
    balance: bool = True, scaling: PlantScaling | None = None, **kw: float,
) -> SynthesisResult:
    """Solve Thm 5.15 at a fixed γ for the construction (`SynthesisProblem.centered`)."""
    return SynthesisProblem(plant, params, beta=beta, g0=gamma if g0 is None else g0, balance=balance,
                            scaling=scaling, **kw).centered(gamma)  # fmt: skip
