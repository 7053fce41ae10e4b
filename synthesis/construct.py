"""LPV controller construction from a solution of the synthesis LMIs (thesis 5.3.2, 5.3.4, 5.4.3-5.4.4, App. B).

Steps (proof of Thm 5.10, carried over to discrete time by Thm 5.15):

1. multiplier extension (5.27)-(5.31): N = P − P̃^{-1}, U = [U_−, U_+] orthonormal eigenvectors of N's
   non-zero eigenvalues N_− < 0 (m_c of them) and N_+ > 0 (k_c), P_e = [[P, U], [U^*, (U^*NU)^{-1}]];
2. Lyapunov extension (5.32): Z_x an orthonormal basis of im(X − Y^{-1}) (eigenvalues below
   `rank_tol`·max are dropped: order reduction, n_c = rank), 𝒳 = [[X, Z_x], [Z_x^*, (Z_x^*(X − Y^{-1})Z_x)^{-1}]];
3. scheduling function (5.36): Δ_c(Δ) = N_− V_−^* (S^*PS − V_− N_− V_−^*)^{-1} V_+, [V_− V_+] = S(Δ)^* U;
4. the QMI (5.10) (discrete inner factor diag(−𝒳, ρ^{-2}𝒳), 5.4.4) in the controller matrices Θ,
   written as (2.11) and solved by the constructive proof of Lemma 2.9 (App. B) with Lemma 5.12's L;
5. runtime form (5.63)/(5.64): `ScheduledController.frozen(Δ)` and `LPVRuntime.step`.

The result is a `ScheduledController`: an `LFTController` (5.57) plus its scheduling function. All
arithmetic is complex when the plant is (5.5.4: the solution of `synthesis.lmi` is complex-formed, so
this is the construction "in the complex domain" that 5.5.4 recommends).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from synthesis.lft import LFTController, LFTPlant, StateSpace, restore_feedthrough

if TYPE_CHECKING:  # the runtime (artifacts -> construct) must not import cvxpy
    from synthesis.lmi import SynthesisResult

__all__ = [
    "BACKOFFS",
    "MAX_BACKOFF",
    "backoff_ladder",
    "ConstructionError",
    "Scheduling",
    "ScheduledController",
    "LPVRuntime",
    "solve_qmi",
    "qmi_value",
    "extend_multiplier",
    "extend_lyapunov",
    "construct_controller",
    "qmi_data",
]


#: γ/γ_a rungs tried in turn when the construction at the first does not verify (LPVTools and IQClab back off
#: 5-20 %); above MAX_BACKOFF a design says it failed instead of shipping a worse controller
BACKOFFS: tuple[float, ...] = (1.1, 1.25, 1.5)
MAX_BACKOFF: float = BACKOFFS[-1]


def backoff_ladder(first: float) -> list[float]:
    """``first``, then the rungs of BACKOFFS above it (none above MAX_BACKOFF unless ``first`` is)."""
    return [first, *(b for b in BACKOFFS if b > first)]


class ConstructionError(RuntimeError):
    """The controller could not be constructed (an inertia or definiteness condition failed numerically)."""


def _herm(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.conj().T)


# --------------------------------------------------------------------------------------------------
# Lemma 2.9 by its constructive proof (App. B) with Lemma 5.12
# --------------------------------------------------------------------------------------------------
def solve_qmi(A: ArrayLike, B: ArrayLike, C: ArrayLike, P: ArrayLike, *, rank_tol: float = 1e-10,
              diagnostics: dict | None = None) -> np.ndarray:
    """An unstructured X with [I; A^*XB + C]^* P [I; A^*XB + C] < 0 (2.11), by the proof in App. B.

    C is n x m, P is (m + n) x (m + n) Hermitian with in(P) = (m, 0, n) (2.10). K = V_A and
    L = V_B [[I, 0], [0, Q]] with QQ^* = −J_22^{-1} (Lemma 5.12, (5.44)-(5.45)), so S^*ΠS = −I (5.46).
    Raises ConstructionError if (2.12) fails (J_22 not negative definite), if W of (B.15) has an eigenvalue among
    its c_Z smallest that is positive beyond round-off (B.18), or if the chosen directions do not give Z (B.19).
    ``diagnostics``, if given, receives the inertia numbers of W: how many eigenvalues came out negative in
    floating point, how many lie within round-off of zero, and c_Z.
    """
    A, B, C, P = (np.atleast_2d(np.asarray(x)) for x in (A, B, C, P))
    dt = np.result_type(A, B, C, P, float)
    n, m = C.shape
    if P.shape != (m + n, m + n):
        raise ValueError(f"P must be {(m + n, m + n)}, got {P.shape}")
    # K: AK = [A1 0]
    UA, sA, VAh = np.linalg.svd(A)
    rZ = int(np.sum(sA > rank_tol * max(sA.max(initial=0.0), 1e-300)))
    K = VAh.conj().T
    A1 = A @ K[:, :rZ]
    # L (Lemma 5.12): B V_B = [B1 0], then the lower-right block scaled by Q
    UB, sB, VBh = np.linalg.svd(B)
    cZ = int(np.sum(sB > rank_tol * max(sB.max(initial=0.0), 1e-300)))
    VB = VBh.conj().T
    IC = np.vstack([np.eye(m, dtype=dt), C.astype(dt)])
    J = VB.conj().T @ IC.conj().T @ P @ IC @ VB  # (5.44)
    J22 = _herm(J[cZ:, cZ:])
    if J22.size:
        ev, W = np.linalg.eigh(J22)
        if ev[-1] >= 0:
            raise ConstructionError(f"(2.12) fails: B^⊥* [I;C]^* P [I;C] B^⊥ has eigenvalue {ev[-1]:.3g} ≥ 0")
        Qm = W @ np.diag(1.0 / np.sqrt(-ev))  # QQ^* = −J22^{-1}  (5.45)
    else:
        Qm = np.zeros((0, 0), dtype=dt)
    Lm = VB @ _blkdiag(np.eye(cZ, dtype=dt), Qm)
    B1 = B @ Lm[:, :cZ]
    D = K.conj().T @ C @ Lm  # (B.11)
    D11, D12 = D[:rZ, :cZ], D[:rZ, cZ:]
    D21, D22 = D[rZ:, :cZ], D[rZ:, cZ:]
    T = _blkdiag(Lm, np.linalg.inv(K).conj().T)
    Pi = _herm(T.conj().T @ P @ T)
    mc = m - cZ
    Z0 = lambda r, c: np.zeros((r, c), dtype=dt)  # noqa: E731
    R = np.block([[np.eye(cZ, dtype=dt), Z0(cZ, rZ)], [Z0(mc, cZ), Z0(mc, rZ)], [Z0(rZ, cZ), np.eye(rZ, dtype=dt)],
                  [D21, Z0(n - rZ, rZ)]])  # fmt: skip
    S = np.vstack([Z0(cZ, mc), np.eye(mc, dtype=dt), D12, D22])
    SPS = _herm(S.conj().T @ Pi @ S)  # ≈ −I by Lemma 5.12
    RPS = R.conj().T @ Pi @ S
    W = _herm(R.conj().T @ Pi @ R - RPS @ np.linalg.solve(SPS, RPS.conj().T))  # (B.15)
    lam, V = np.linalg.eigh(W)
    # (B.18) says in_-(W) ≥ c_Z. The sign of an eigenvalue within round-off of zero is not a fact about W but
    # about the BLAS kernel that computed it (measured: W spans −3e3 … 2.5e7 for the flux observer at 200 rad/s,
    # four of its five negative eigenvalues lie below eps·‖W‖, and which of them come out negative differs
    # between OpenBLAS kernels). So only an eigenvalue that is positive beyond round-off refutes (B.18); the
    # c_Z most negative directions are taken (B.19) and the QMI residual of the result and the independent
    # verification (synthesis.verify) decide whether the controller is good.
    tol = _roundoff(W, lam)
    if diagnostics is not None:
        diagnostics.update(W_negative=int(np.sum(lam < 0)), W_within_roundoff=int(np.sum(np.abs(lam) <= tol)), c_Z=cZ,
                           W_roundoff=tol)  # fmt: skip
    if cZ and lam[cZ - 1] > tol:
        raise ConstructionError(f"(B.18) fails: in_-(W) = {int(np.sum(lam < tol))} < c_Z = {cZ}: eigenvalue "
                                f"{lam[cZ - 1]:.3g} > round-off {tol:.2g} ((2.13) violated)")  # fmt: skip
    Vn = V[:, :cZ]  # the c_Z most negative directions  (B.19)
    Z1, Z2 = Vn[:cZ], Vn[cZ:]
    if cZ and np.linalg.cond(Z1) > 1e12:
        raise ConstructionError(f"(B.19) fails: the c_Z = {cZ} most negative directions of W have a singular "
                                f"upper block (cond {np.linalg.cond(Z1):.2g})")  # fmt: skip
    Z = Z2 @ np.linalg.inv(Z1)
    X = np.linalg.pinv(A1.conj().T) @ (Z - D11) @ np.linalg.pinv(B1)
    return X


def _roundoff(M: np.ndarray, lam: np.ndarray) -> float:
    """The size below which an eigenvalue of the Hermitian M (eigenvalues lam) has no reliable sign: a backward-
    stable eigensolver returns the eigenvalues of M + E with ‖E‖ ≲ n·eps·‖M‖."""
    return float(M.shape[0] * np.finfo(float).eps * max(np.abs(lam).max(initial=0.0), 1e-300))


def _blkdiag(*Ms: np.ndarray) -> np.ndarray:
    dt = np.result_type(*Ms, float)
    r = sum(M.shape[0] for M in Ms)
    c = sum(M.shape[1] for M in Ms)
    out = np.zeros((r, c), dtype=dt)
    i = j = 0
    for M in Ms:
        out[i : i + M.shape[0], j : j + M.shape[1]] = M
        i, j = i + M.shape[0], j + M.shape[1]
    return out


def qmi_value(A: np.ndarray, B: np.ndarray, C: np.ndarray, P: np.ndarray, X: np.ndarray) -> float:
    """Largest eigenvalue of the left-hand side of (2.11) at X."""
    m = C.shape[1]
    F = np.vstack([np.eye(m), A.conj().T @ X @ B + C])
    return float(np.linalg.eigvalsh(_herm(F.conj().T @ P @ F))[-1])


# --------------------------------------------------------------------------------------------------
# extensions and scheduling
# --------------------------------------------------------------------------------------------------
def extend_multiplier(P: np.ndarray, Pt: np.ndarray, *, rank_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(5.27)-(5.30): returns (U, λ, P_e) with U = [U_−, U_+], λ the eigenvalues of N on them (negatives first).

    For diagonal P, P̃ (Ch. 7) N is diagonal and U is taken as unit vectors, as the proof of Thm 7.1
    requires (U = [T_1 T_2] with one 1 per column); eigh could rotate within a repeated eigenvalue.
    """
    N = _herm(P - np.linalg.inv(Pt))  # (5.27)
    if np.all(N == np.diag(np.diag(N))):
        lam, V = np.real(np.diag(N)).copy(), np.eye(N.shape[0], dtype=N.dtype)
    else:
        lam, V = np.linalg.eigh(N)
    keep = np.abs(lam) > rank_tol * max(np.abs(lam).max(initial=0.0), 1e-300)
    lam, V = lam[keep], V[:, keep]
    order = np.argsort(lam, kind="stable")  # negatives first  (5.28)
    lam, U = lam[order], V[:, order]
    Pe = np.block([[P, U], [U.conj().T, np.diag(1.0 / lam)]])  # (5.30)
    return U, lam, _herm(Pe)


def extend_lyapunov(X: np.ndarray, Y: np.ndarray, *, rank_tol: float = 1e-8, absorb: str = "Y") -> tuple[np.ndarray, int]:
    """(5.32): 𝒳 = [[X, Z_x], [Z_x^*, (Z_x^*(X − Y^{-1})Z_x)^{-1}]]; returns (𝒳, n_c).

    Eigenvalues of X − Y^{-1} below rank_tol·‖X‖ are dropped (order reduction: n_c < n_x); so are the
    slightly negative ones that (5.60), satisfied only up to round-off, can leave. The dropped part μ_d
    perturbs the solution, and `absorb` says where: "Y" keeps X as the upper-left block (𝒳^{-1}'s block
    is then (Y^{-1} + V_d μ_d V_d^*)^{-1}, a change of Y through an inversion); "X" uses X − V_d μ_d V_d^*
    (an absolute change of X by |μ_d|; 𝒳^{-1}'s block is exactly Y). Which one keeps the QMI solvable in
    floating point depends on the problem (measured: a diagonal-multiplier design where "Y" moved Y by
    4e-4 relative and broke (5.62), an LTI design where only "Y" worked), so `construct_controller` tries
    both.
    """
    D = _herm(X - np.linalg.inv(Y))
    mu, V = np.linalg.eigh(D)
    keep = mu > rank_tol * max(np.linalg.norm(X, 2), 1e-300)
    if absorb not in ("X", "Y"):
        raise ValueError("absorb must be 'X' or 'Y'")
    Vd = V[:, ~keep]
    Xu = _herm(X - Vd @ np.diag(mu[~keep]) @ Vd.conj().T) if absorb == "X" else X
    Zx, mu = V[:, keep], mu[keep]
    XX = np.block([[Xu, Zx], [Zx.conj().T, np.diag(1.0 / mu)]])
    return _herm(XX), int(keep.sum())


@dataclass(frozen=True, eq=False)
class Scheduling:
    """The scheduling function Δ_c(Δ) of (5.36) for S(Δ) = [Δ; I]: w_c = Δ_c(Δ) z_c."""

    P: np.ndarray  # (n_wu + n_zu) Hermitian
    U: np.ndarray  # (n_wu + n_zu) x (m_c + k_c), orthonormal, N_− columns first
    lam: np.ndarray  # eigenvalues of N on U: m_c negatives then k_c positives
    n_wu: int
    n_zu: int

    @property
    def m_c(self) -> int:
        return int(np.sum(self.lam < 0))

    @property
    def k_c(self) -> int:
        return int(np.sum(self.lam > 0))

    def __call__(self, Delta: ArrayLike) -> np.ndarray:
        """Δ_c(Δ) (5.36), an m_c x k_c matrix."""
        D = np.atleast_2d(np.asarray(Delta))
        if D.shape != (self.n_wu, self.n_zu):
            raise ValueError(f"Δ must be {self.n_wu}x{self.n_zu}, got {D.shape}")
        S = np.vstack([D, np.eye(self.n_zu)])
        V = S.conj().T @ self.U  # (5.29)
        Vm, Vp = V[:, : self.m_c], V[:, self.m_c :]
        Nm = np.diag(self.lam[: self.m_c])
        M = S.conj().T @ self.P @ S - Vm @ Nm @ Vm.conj().T
        return Nm @ Vm.conj().T @ np.linalg.solve(M, Vp)  # (5.36)


@dataclass(frozen=True, eq=False)
class ScheduledController:
    """LPV controller (5.57) with scheduling w_c = Δ_c(Δ) z_c; `frozen(Δ)` is (5.63)/(5.64) at one Δ."""

    K: LFTController
    scheduling: Scheduling
    gamma: float
    info: dict = field(default_factory=dict)

    @property
    def dt(self) -> float | None:
        return self.K.dt

    def delta_c(self, Delta: ArrayLike) -> np.ndarray:
        return self.scheduling(Delta)

    def frozen(self, Delta: ArrayLike) -> StateSpace:
        """The controller at a frozen parameter, input y, output u (5.63)/(5.64)."""
        if self.K.n_wc == 0 and self.K.n_zc == 0:
            return self.K.at(np.zeros((0, 0)))
        return self.K.at(self.delta_c(Delta))

    def runtime(self) -> "LPVRuntime":
        return LPVRuntime(self)


class LPVRuntime:
    """Sample-by-sample implementation of 5.4.4 ("working with the scheduling vectors").

        z̃_c = C_c2 x_c + D_c21 y;  w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c;
        u = C_c1 x_c + D_c11 y + D_c12 w_c;  x_c ← A_c x_c + B_c1 y + B_c2 w_c.
    """

    def __init__(self, ctrl: ScheduledController) -> None:
        self.c = ctrl
        K = ctrl.K
        self._blocks = [np.array(getattr(K, k)) for k in ("A_c", "B_c1", "B_c2", "C_c1", "D_c11", "D_c12",
                                                          "C_c2", "D_c21", "D_c22")]  # fmt: skip
        self.x = np.zeros(K.n_c, dtype=K.M.dtype)

    def reset(self) -> None:
        self.x[:] = 0

    def step(self, y: ArrayLike, Delta: ArrayLike) -> np.ndarray:
        Ac, Bc1, Bc2, Cc1, Dc11, Dc12, Cc2, Dc21, Dc22 = self._blocks
        y = np.asarray(y).reshape(-1)
        if Bc2.shape[1]:
            Dc = self.c.delta_c(Delta)
            zt = Cc2 @ self.x + Dc21 @ y
            wc = Dc @ np.linalg.solve(np.eye(Dc.shape[1]) - Dc22 @ Dc, zt)
        else:
            wc = np.zeros(0)
        u = Cc1 @ self.x + Dc11 @ y + Dc12 @ wc
        self.x = Ac @ self.x + Bc1 @ y + Bc2 @ wc
        return u


# --------------------------------------------------------------------------------------------------
# the QMI (5.10) for the closed loop (5.15), discrete inner factor
# --------------------------------------------------------------------------------------------------
def qmi_data(plant: LFTPlant, n_c: int, m_c: int, k_c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M_0, 𝓑, 𝓒) with closed loop M_cl = M_0 + 𝓑 Θ 𝓒 (5.15).

    Closed-loop "output" e = [x⁺; x_c⁺; z_u; z_c; z_p], "input" v = [x; x_c; w_u; w_c; w_p];
    Θ = [[A_c, B_c1, B_c2], [C_c1, D_c11, D_c12], [C_c2, D_c21, D_c22]] (rows [x_c⁺; u; z_c],
    columns [x_c; y; w_c]).
    """
    p = plant
    n, nzu, nzp, ny, nwu, nwp, nu = p.n_x, p.n_zu, p.n_zp, p.n_y, p.n_wu, p.n_wp, p.n_u
    dt = np.result_type(p.M, float)
    Z = lambda r, c: np.zeros((r, c), dtype=dt)  # noqa: E731
    I = lambda k: np.eye(k, dtype=dt)  # noqa: E731
    M0 = np.block([
        [p.A, Z(n, n_c), p.B_u, Z(n, m_c), p.B_p],
        [Z(n_c, n), Z(n_c, n_c), Z(n_c, nwu), Z(n_c, m_c), Z(n_c, nwp)],
        [p.C_u, Z(nzu, n_c), p.D_uu, Z(nzu, m_c), p.D_up],
        [Z(k_c, n), Z(k_c, n_c), Z(k_c, nwu), Z(k_c, m_c), Z(k_c, nwp)],
        [p.C_p, Z(nzp, n_c), p.D_pu, Z(nzp, m_c), p.D_pp],
    ])  # fmt: skip
    Bb = np.block([
        [Z(n, n_c), p.B, Z(n, k_c)],
        [I(n_c), Z(n_c, nu), Z(n_c, k_c)],
        [Z(nzu, n_c), p.E_u, Z(nzu, k_c)],
        [Z(k_c, n_c), Z(k_c, nu), I(k_c)],
        [Z(nzp, n_c), p.E_p, Z(nzp, k_c)],
    ])  # fmt: skip
    Cb = np.block([
        [Z(n_c, n), I(n_c), Z(n_c, nwu), Z(n_c, m_c), Z(n_c, nwp)],
        [p.C, Z(ny, n_c), p.F_u, Z(ny, m_c), p.F_p],
        [Z(m_c, n), Z(m_c, n_c), Z(m_c, nwu), I(m_c), Z(m_c, nwp)],
    ])  # fmt: skip
    return M0, Bb, Cb


def _inner(XX: np.ndarray, Pe: np.ndarray, n_wu: int, m_c: int, n_zu: int, n_wp: int, n_zp: int,
           gamma: float, rho: float) -> np.ndarray:
    """Π of (5.10) (discrete: diag(−𝒳, ρ^{-2}𝒳)) reordered to [v; e] with P_p = diag(−γ I, I/γ)."""
    # P_e coordinates [w_u, z_u, w_c, z_c] -> w = (w_u, w_c), z = (z_u, z_c)
    k_c = Pe.shape[0] - n_wu - n_zu - m_c
    iw = np.r_[0:n_wu, n_wu + n_zu : n_wu + n_zu + m_c]
    iz = np.r_[n_wu : n_wu + n_zu, n_wu + n_zu + m_c : n_wu + n_zu + m_c + k_c]
    Qe, Se, Re = Pe[np.ix_(iw, iw)], Pe[np.ix_(iw, iz)], Pe[np.ix_(iz, iz)]
    nxi = XX.shape[0]
    Pvv = _blkdiag(-XX, Qe, -gamma * np.eye(n_wp))
    Pee = _blkdiag(rho**-2 * XX, Re, np.eye(n_zp) / gamma)
    Pve = _blkdiag(np.zeros((nxi, nxi)), Se, np.zeros((n_wp, n_zp)))
    return _herm(np.block([[Pvv, Pve], [Pve.conj().T, Pee]]))


def construct_controller(
    res: SynthesisResult,
    *,
    rank_tol_x: float = 1e-8,
    rank_tol_n: float = 1e-9,
    feedthrough: np.ndarray | None = None,
    qmi_tol: float = 1e-12,
) -> ScheduledController:
    """Build the LPV controller from a feasible `SynthesisResult` (Thm 5.15 construction, steps 1-5).

    The controller is constructed for ``res.plant`` (the scaled plant) and is, unchanged, a controller
    for the original plant (the scalings do not touch y, u). If the original plant had F_3 ≠ 0 and
    was passed through `remove_feedthrough`, give that F_3 as `feedthrough` to apply Γ ⋆ K̃ (2.20).
    """
    if not res.feasible:
        raise ConstructionError("the synthesis LMIs were not feasible")
    p = res.plant
    rho = 1.0 - res.beta
    gam = res.gamma_scaled
    n_wu, n_zu = p.n_wu, p.n_zu
    if n_wu + n_zu:
        U, lam, Pe = extend_multiplier(res.P, res.Pt, rank_tol=rank_tol_n)
    else:
        U, lam, Pe = np.zeros((0, 0)), np.zeros(0), np.zeros((0, 0))
    m_c, k_c = int(np.sum(lam < 0)), int(np.sum(lam > 0))
    first_err: ConstructionError | None = None
    for absorb in ("Y", "X"):  # where the round-off of (5.60) goes (`extend_lyapunov`)
        XX, n_c = extend_lyapunov(res.X, res.Y, rank_tol=rank_tol_x, absorb=absorb)
        M0, Bb, Cb = qmi_data(p, n_c, m_c, k_c)
        Pi = _inner(XX, Pe, n_wu, m_c, n_zu, p.n_wp, p.n_zp, gam, rho)
        # (5.10) as (2.11): [I; M0 + Bb Θ Cb]^* Π [I; ...] < 0 with A^* = Bb, B = Cb, C = M0
        try:
            inertia: dict = {}
            Theta = solve_qmi(Bb.conj().T, Cb, M0, Pi, diagnostics=inertia)
            qv = qmi_value(Bb.conj().T, Cb, M0, Pi, Theta)
            if not qv < qmi_tol * np.linalg.norm(Pi, 2):
                raise ConstructionError(f"the constructed controller violates the QMI (5.10): λ_max = {qv:.3g}")
            break
        except ConstructionError as ex:
            first_err = first_err or ex
    else:
        assert first_err is not None
        raise first_err
    nu, ny = p.n_u, p.n_y
    Kt = LFTController(Theta, n_c, nu, k_c, ny, m_c, p.dt)
    if feedthrough is not None and np.any(feedthrough):
        Kt = restore_feedthrough(Kt, feedthrough)
    sched = Scheduling(res.P, U, lam, n_wu, n_zu)
    info = dict(n_c=n_c, m_c=m_c, k_c=k_c, qmi_max_eig=qv, inertia=inertia, gamma=res.gamma, rank_tol_x=rank_tol_x, lyapunov_absorb=absorb,
                rank_tol_n=rank_tol_n, eig_X_minus_Yinv=np.linalg.eigvalsh(_herm(res.X - np.linalg.inv(res.Y))).tolist())
    return ScheduledController(Kt, sched, res.gamma, info)
