"""Independent lower bounds on the LPV performance γ: the optimal LTI H∞ level of each frozen plant.

For an LPV plant M ⋆ Δ (5.55) and *any* controller scheduled on Δ (LPV or gain-scheduled), freezing
Δ(t) ≡ Δ_0 turns the closed loop into an LTI loop of the frozen plant with the frozen controller, so
the LPV induced l2 gain -- and every γ certified by Thm 5.15 -- is at least

    γ_opt(Δ_0) = inf_{K stabilising} ‖F_l(M ⋆ Δ_0, K)‖_∞ ,

and at least the worst of these over any set of frozen points Δ_0 ∈ Δ̄. `lpv_lower_bound` evaluates
that worst over a grid of Δ̄.

γ_opt is computed here by γ-bisection on the two-Riccati (Hamiltonian) conditions of Glover & Doyle
(1988) -- nothing from `synthesis.lmi` is used, so the bound is independent of the synthesis LMIs and
their numerics. A discrete plant is first mapped to continuous time by the Cayley transform
z = (1 + s)/(1 − s), which maps the unit circle onto the imaginary axis, preserves every H∞ norm and
commutes with feedback interconnection (it is a change of the frequency variable), so the discrete
optimum equals the continuous optimum of the transformed plant. Complex (complex-formed, Sec. 5.5)
plants are handled directly in complex arithmetic.

γ-test (Glover-Doyle, general D_11; D_22 does not change the optimum and is ignored; D_12 must have
full column rank and D_21 full row rank): γ > γ_opt iff
  (a) R = D_1•^* D_1• − diag(γ² I, 0) and R̃ = D_•1 D_•1^* − diag(γ² I, 0) have the inertia of
      diag(−I, I) (this is γ > max(σ̄[(I − D_12 D_12^+) D_11], σ̄[D_11 (I − D_21^+ D_21)]));
  (b) X = Ric(H_X) ⪰ 0 exists (stabilising),  H_X = [[A, 0], [−C_1^*C_1, −A^*]] − [[B], [−C_1^* D_1•]] R^{-1} [D_1•^* C_1, B^*];
  (c) Y = Ric(H_Y) ⪰ 0 exists (dual);
  (d) ρ(X Y) < γ².
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np
import scipy.linalg as sla

from synthesis.lft import LFTPlant, StateSpace
from synthesis.models.motor import flux_observer_plant_discrete

__all__ = [
    "cayley_to_continuous",
    "frozen_plant",
    "hinf_gamma_test",
    "hinf_optimal_gamma",
    "hinf_norm",
    "lpv_lower_bound",
    "LowerBound",
    "certificate",
    "switching_filter_lower_bound",
]


# --------------------------------------------------------------------------------------------------
# plants
# --------------------------------------------------------------------------------------------------
def frozen_plant(plant: LFTPlant, delta: np.ndarray) -> StateSpace:
    """M ⋆ Δ_0 (5.55) as an LTI state space with inputs [w_p; u] and outputs [z_p; y] (same dt)."""
    p = plant
    n, nwu, nzu = p.n_x, p.n_wu, p.n_zu
    D = np.atleast_2d(np.asarray(delta))
    if nwu + nzu == 0:
        M = p.M
    else:
        # parameter channel last: rows/cols [x, p, y] / [x, p, u] then [u-channel]
        idx_r = list(range(n)) + list(range(n + nzu, p.M.shape[0])) + list(range(n, n + nzu))
        idx_c = list(range(n)) + list(range(n + nwu, p.M.shape[1])) + list(range(n, n + nwu))
        Mr = p.M[np.ix_(idx_r, idx_c)]
        M = _close(Mr, nzu, nwu, D)
    return StateSpace(M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:], p.dt)


def _close(M: np.ndarray, nzu: int, nwu: int, D: np.ndarray) -> np.ndarray:
    """Close the last nzu outputs / nwu inputs of M with w_u = D z_u."""
    r, c = M.shape[0] - nzu, M.shape[1] - nwu
    M11, M12, M21, M22 = M[:r, :c], M[:r, c:], M[r:, :c], M[r:, c:]
    L = np.eye(nzu, dtype=np.result_type(M, D)) - M22 @ D
    return M11 + M12 @ D @ np.linalg.solve(L, M21)


def cayley_to_continuous(sys: StateSpace) -> StateSpace:
    """z = (1 + s)/(1 − s): a discrete (A, B, C, D) to a continuous system with the same frequency response
    on the image frequencies, H_c(jν) = H_d(e^{jθ}), ν = tan(θ/2); needs A + I invertible."""
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    n = A.shape[0]
    Ai = np.linalg.inv(A + np.eye(n))
    Ac = (A - np.eye(n)) @ Ai
    Bc = math.sqrt(2.0) * Ai @ B
    Cc = math.sqrt(2.0) * C @ Ai
    Dc = D - C @ Ai @ B
    return StateSpace(Ac, Bc, Cc, Dc)


def hinf_norm(sys: StateSpace, n_freq: int = 2000) -> float:
    """‖G‖_∞ by a dense frequency sweep refined near the peak (a check, not a certificate)."""
    if sys.is_discrete:
        th = np.linspace(0.0, 2 * np.pi, n_freq, endpoint=False)
        zs = np.exp(1j * th)
    else:
        zs = 1j * np.concatenate([[0.0], np.logspace(-6, 8, n_freq), -np.logspace(-6, 8, n_freq)])
    vals = [np.linalg.norm(sys.evaluate(z), 2) for z in zs]
    k = int(np.argmax(vals))
    best = vals[k]
    # refine around the peak
    z0 = zs[k]
    for scale in (1e-2, 1e-4, 1e-6):
        if sys.is_discrete:
            th0 = np.angle(z0)
            cand = np.exp(1j * (th0 + scale * np.linspace(-1, 1, 201) * 2 * np.pi / n_freq * 100))
        else:
            w0 = z0.imag
            cand = 1j * (w0 + scale * max(1.0, abs(w0)) * np.linspace(-100, 100, 201))
        v = [np.linalg.norm(sys.evaluate(z), 2) for z in cand]
        j = int(np.argmax(v))
        if v[j] > best:
            best, z0 = v[j], cand[j]
    return float(best)


# --------------------------------------------------------------------------------------------------
# Riccati
# --------------------------------------------------------------------------------------------------
def _ric(H: np.ndarray, n: int, imag_tol: float) -> np.ndarray | None:
    """Stabilising solution X of the Riccati equation with Hamiltonian H (X = U_21 U_11^{-1} of the stable
    invariant subspace), or None if H has eigenvalues on (within the tolerance of) the imaginary axis or
    U_11 is singular.

    H is balanced by a diagonal similarity first (eigenvalues and the subspace, mapped back, unchanged);
    an eigenvalue counts as imaginary when |Re λ| ≤ max(imag_tol·max|λ|, 1e3·eps·‖H_bal‖), the second
    term being the backward error of the Schur form.
    """
    Hc = H.astype(complex)
    Hb, (sc, _) = sla.matrix_balance(Hc, permute=False, separate=True)
    T, U, sdim = sla.schur(Hb, output="complex", sort=lambda z: z.real < 0)
    ev = np.diag(T)
    tol = max(imag_tol * float(np.max(np.abs(ev))), 1e3 * np.finfo(float).eps * float(np.linalg.norm(Hb, 1)))
    if sdim != n or np.min(np.abs(ev.real)) <= tol:
        return None
    V = sc[:, None] * U[:, :n]  # the stable subspace of H
    U11, U21 = V[:n], V[n:]
    if np.linalg.cond(U11) > 1e12:
        return None
    X = np.linalg.solve(U11.conj().T, U21.conj().T).conj().T
    return 0.5 * (X + X.conj().T)


@dataclass
class _Split:
    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    D11: np.ndarray
    D12: np.ndarray
    D21: np.ndarray


def _inv_sqrt(M: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(0.5 * (M + M.conj().T))
    return (V / np.sqrt(w)) @ V.conj().T


def _split(sys: StateSpace, n_z: int, n_w: int) -> _Split:
    """Partition a continuous generalised plant with inputs [w; u] and outputs [z; y], and normalise
    D_12^* D_12 = I, D_21 D_21^* = I by u = (D_12^*D_12)^{-1/2} u', y' = (D_21 D_21^*)^{-1/2} y (invertible
    changes of the controller's input and output: the optimum is unchanged)."""
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    s = _Split(A, B[:, :n_w], B[:, n_w:], C[:n_z], C[n_z:], D[:n_z, :n_w], D[:n_z, n_w:], D[n_z:, :n_w])
    for name, M, full in (("D_12", s.D12, "column"), ("D_21", s.D21, "row")):
        r = np.linalg.matrix_rank(M, tol=1e-13 * max(1e-300, float(np.linalg.norm(M, 2)))) if M.size else 0
        need = M.shape[1] if full == "column" else M.shape[0]
        if r < need:
            raise ValueError(f"{name} must have full {full} rank (regular problem); rank {r} < {need}")
    Su = _inv_sqrt(s.D12.conj().T @ s.D12)
    Sy = _inv_sqrt(s.D21 @ s.D21.conj().T)
    s.B2, s.D12 = s.B2 @ Su, s.D12 @ Su
    s.C2, s.D21 = Sy @ s.C2, Sy @ s.D21
    return s


def hinf_gamma_test(s: _Split, gamma: float, *, imag_tol: float = 1e-9, psd_tol: float = 1e-8) -> tuple[bool, str]:
    """Glover-Doyle conditions (a)-(d) at γ for a continuous split plant (see the module docstring)."""
    A, B1, B2, C1, C2, D11, D12, D21 = s.A, s.B1, s.B2, s.C1, s.C2, s.D11, s.D12, s.D21
    n = A.shape[0]
    nz, nw, nu, ny = C1.shape[0], B1.shape[1], B2.shape[1], C2.shape[0]
    dt = np.result_type(A, B1, C1, D11, complex)
    g2 = gamma * gamma
    # X side. (a): with D_12^*D_12 = I, R has the inertia of diag(−I, I) iff σ̄((I − D_12 D_12^*) D_11) < γ
    D1d = np.hstack([D11, D12]).astype(dt)
    R = D1d.conj().T @ D1d - np.diag(np.r_[np.full(nw, g2), np.zeros(nu)])
    if nw and np.linalg.norm(D11 - D12 @ (D12.conj().T @ D11), 2) >= gamma:
        return False, "(a) R"
    Bb = np.hstack([B1, B2]).astype(dt)
    Ri = np.linalg.inv(R)
    HX = (np.block([[A, np.zeros((n, n))], [-C1.conj().T @ C1, -A.conj().T]])
          - np.vstack([Bb, -C1.conj().T @ D1d]) @ Ri @ np.hstack([D1d.conj().T @ C1, Bb.conj().T]))  # fmt: skip
    # Y side (dual)
    Dd1 = np.vstack([D11, D21]).astype(dt)
    Rt = Dd1 @ Dd1.conj().T - np.diag(np.r_[np.full(nz, g2), np.zeros(ny)])
    if nz and np.linalg.norm(D11 - (D11 @ D21.conj().T) @ D21, 2) >= gamma:
        return False, "(a) R~"
    Cc = np.vstack([C1, C2]).astype(dt)
    Rti = np.linalg.inv(Rt)
    HY = (np.block([[A.conj().T, np.zeros((n, n))], [-B1 @ B1.conj().T, -A]])
          - np.vstack([Cc.conj().T, -B1 @ Dd1.conj().T]) @ Rti @ np.hstack([Dd1 @ B1.conj().T, Cc]))  # fmt: skip
    if n == 0:
        return True, "ok"
    X = _ric(HX, n, imag_tol)
    if X is None:
        return False, "(b) no stabilising X"
    Y = _ric(HY, n, imag_tol)
    if Y is None:
        return False, "(c) no stabilising Y"
    xs = max(1.0, float(np.linalg.norm(X, 2)))
    ys = max(1.0, float(np.linalg.norm(Y, 2)))
    if np.linalg.eigvalsh(X)[0] < -psd_tol * xs:
        return False, "(b) X not ⪰ 0"
    if np.linalg.eigvalsh(Y)[0] < -psd_tol * ys:
        return False, "(c) Y not ⪰ 0"
    rho = float(np.max(np.abs(np.linalg.eigvals(X @ Y))))
    if rho >= g2:
        return False, "(d) ρ(XY) ≥ γ²"
    return True, "ok"


def hinf_optimal_gamma(
    sys: StateSpace, n_z: int, n_w: int, *, rtol: float = 1e-4, hi: float | None = None, max_iter: int = 200
) -> float:
    """inf ‖F_l(P, K)‖_∞ over stabilising K for the LTI generalised plant ``sys`` (inputs [w; u], outputs
    [z; y], the first n_w inputs and n_z outputs are the performance channels), by bisection on
    `hinf_gamma_test` to relative accuracy rtol. Discrete plants go through `cayley_to_continuous`.

    Needs (A, B_2) stabilisable, (C_2, A) detectable, full-rank D_12/D_21 and no zeros of P_12, P_21 on
    the stability boundary; otherwise no γ passes and a RuntimeError is raised.
    """
    c = cayley_to_continuous(sys) if sys.is_discrete else sys
    s = _split(c, n_z, n_w)
    ok = lambda g: hinf_gamma_test(s, g)[0]  # noqa: E731
    up = float(hi) if hi is not None else max(1.0, float(np.linalg.norm(c.D, 2)))
    k = 0
    while not ok(up):  # grow to a feasible level
        up *= 10.0
        k += 1
        if k > 40:
            raise RuntimeError("no finite γ passes the H∞ test (stabilisability/detectability or boundary zeros)")
    lo = 0.0
    while lo == 0.0 and up > 1e-300:  # decades down to an infeasible level
        if ok(up / 10.0):
            up /= 10.0
        else:
            lo = up / 10.0
    return float(_bisect(ok, lo, up, rtol, max_iter)[1])


def _bisect(ok: Callable[[float], bool], lo: float, up: float, rtol: float, max_iter: int = 200) -> tuple[float, float]:
    """Shrink [lo, up] (ok(up) true, ok(lo) false) to relative width rtol; returns the final (lo, up)."""
    for _ in range(max_iter):
        if up - lo <= rtol * up:
            break
        mid = 0.5 * (lo + up)
        if ok(mid):
            up = mid
        else:
            lo = mid
    return lo, up


# --------------------------------------------------------------------------------------------------
# LPV lower bound
# --------------------------------------------------------------------------------------------------
@dataclass
class LowerBound:
    """max over frozen Δ_0 of γ_opt(Δ_0): `value`, the argmax `delta_worst` and every point's γ_opt."""

    value: float
    delta_worst: np.ndarray
    points: list[tuple[np.ndarray, float]] = field(default_factory=list)
    rtol: float = 1e-4

    def as_dict(self) -> dict:
        def _d(D: np.ndarray) -> list:
            D = np.asarray(D)
            return np.real(D).tolist() if not np.iscomplexobj(D) or not np.any(np.imag(D)) else D.tolist()

        return dict(gamma_lower_bound=self.value, delta_worst=_d(self.delta_worst), rtol=self.rtol,
                    method="max over frozen Δ of the Glover-Doyle Riccati optimum (Cayley transform for discrete)",
                    points=[dict(delta=_d(D), gamma_opt=g) for D, g in self.points])  # fmt: skip


def lpv_lower_bound(plant: LFTPlant, deltas: Iterable[np.ndarray], *, rtol: float = 1e-4) -> LowerBound:
    """The worst optimal LTI H∞ level over frozen parameter values: a lower bound on any LPV γ (see module doc).

    The bound is exact up to rtol (bisection) at each point; between grid points the LPV optimum can only
    be higher, so a finer grid gives a larger (still valid) bound.
    """
    pts: list[tuple[np.ndarray, float]] = []
    for D in deltas:
        ss = frozen_plant(plant, D)
        g = hinf_optimal_gamma(ss, plant.n_zp, plant.n_wp, rtol=rtol)
        pts.append((np.asarray(D), g))
    if not pts:
        raise ValueError("no frozen parameter values given")
    k = int(np.argmax([g for _, g in pts]))
    # the bisection returns an upper end of the bracket; report the lower end (a certified lower bound)
    return LowerBound(float(pts[k][1] * (1.0 - rtol)), pts[k][0], pts, rtol)


def lower_bound_grid(values: Sequence[float], n: int = 1) -> list[np.ndarray]:
    """δ·I_n for each δ (a convenience for scalar-scheduled plants)."""
    return [v * np.eye(n) for v in values]


def certificate(lb: LowerBound | None, gamma_a: float, gamma: float | None = None) -> dict:
    """The `[lower bound, γ_a, γ]` record every synthesis report and artifact JSON carries (issue 12).

    ``gap`` = γ_a / bound (1 means the LMI reached the optimum over frozen parameters; above 1 it is the
    numerics or the LMIs' own optimum -- `synthesis.lmi_dual.lmi_optimum_evidence` decides which);
    ``gap_constructed`` = γ / bound.
    """
    if lb is None:
        return dict(gamma_lower_bound=None, gap=None, gammas=[None, gamma_a, gamma])
    out = dict(gamma_lower_bound=lb.value, gap=gamma_a / lb.value, gammas=[lb.value, gamma_a, gamma],
               lower_bound=lb.as_dict())  # fmt: skip
    if gamma is not None:
        out["gap_constructed"] = gamma / lb.value
    return out


# --------------------------------------------------------------------------------------------------
# time-varying (switching) lower bound for estimation problems
# --------------------------------------------------------------------------------------------------
def _estimation_form(sys: StateSpace, n_z: int, n_w: int) -> tuple[np.ndarray, ...]:
    """(Ã, G̃, H̃, L) of a frozen filtering plant z = u + L x, y = C x + F w (u reaches neither x nor y): the
    noise w split into v = (FF*)^{-1/2} F w and ζ = N* w (N a basis of ker F), ‖w‖² = ‖v‖² + ‖ζ‖², so that
    x⁺ = Ã x + G̃ ζ + (known y term), y' = H̃ x + v (Hassibi-Sayed-Kailath's uncorrelated form)."""
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    Bw, Bu = B[:, :n_w], B[:, n_w:]
    Cz, Cy = C[:n_z], C[n_z:]
    Dzw, Dzu, Dyw, Dyu = D[:n_z, :n_w], D[:n_z, n_w:], D[n_z:, :n_w], D[n_z:, n_w:]
    if np.any(Bu) or np.any(Dyu) or np.any(Dzw) or not np.allclose(Dzu, np.eye(n_z)):
        raise ValueError("not a filtering problem z = u + L x, y = C x + F w (u must reach neither x nor y)")
    FF = Dyw @ Dyw.conj().T
    Fp = Dyw.conj().T @ np.linalg.inv(FF)
    N = sla.null_space(Dyw)
    W = _inv_sqrt(FF)
    return A - Bw @ Fp @ Cy, Bw @ N, W @ Cy, Cz


def switching_filter_lower_bound(
    plant: LFTPlant, period: Sequence[np.ndarray], *, repeats: int = 50, rtol: float = 1e-4, hi: float | None = None
) -> float:
    """A lower bound on the γ of *any* causal observer, scheduled or not, for the filtering plant M ⋆ Δ_k when the
    parameter follows the periodic sequence ``period`` (repeated ``repeats`` times from x_0 = 0).

    For a fixed parameter sequence the LPV plant is linear time-varying; the best causal estimator of L x_k from
    y_0 ... y_k (a posteriori) over a finite horizon reaches γ iff the Krein-space Riccati recursion
    P_{k+1} = Ã P Ã* + G̃ G̃* − K R_e K*,  R_e = diag(I, −γ² I) + [H̃; L] P [H̃; L]*,  P_0 = 0,
    keeps R_e with the inertia of diag(I, −γ² I) at every step (Hassibi, Sayed & Kailath 1999, the H∞ a posteriori
    filter), i.e. L (P − P H̃*(I + H̃PH̃*)^{-1}H̃P) L* ≺ γ² I. Any LPV observer is such an estimator on this
    trajectory, so every γ that fails is a lower bound on its induced l2 gain (arbitrarily fast parameters, 5.6.1).
    Returns the largest failing γ found by bisection (relative accuracy rtol). Constant sequences reproduce the
    frozen LTI optimum of `hinf_optimal_gamma` (checked in the tests); sequences that switch can exceed it.
    """
    n_z, n_w = plant.n_zp, plant.n_wp
    forms = [_estimation_form(frozen_plant(plant, D), n_z, n_w) for D in period]
    n = plant.n_x
    seq = forms * repeats

    def passes(g: float) -> bool:
        P = np.zeros((n, n), dtype=complex)
        g2 = g * g
        for At, Gt, Ht, L in seq:
            HL = np.vstack([Ht, L])
            S = HL @ P @ HL.conj().T
            ny = Ht.shape[0]
            R11 = np.eye(ny) + S[:ny, :ny]
            M = S[ny:, ny:] - S[ny:, :ny] @ np.linalg.solve(R11, S[:ny, ny:])
            if np.linalg.eigvalsh(0.5 * (M + M.conj().T))[-1] >= g2:
                return False
            Re = S + np.diag(np.r_[np.ones(ny), -g2 * np.ones(L.shape[0])])
            K = At @ P @ HL.conj().T
            P = At @ P @ At.conj().T + Gt @ Gt.conj().T - K @ np.linalg.solve(Re, K.conj().T)
            P = 0.5 * (P + P.conj().T)
        return True

    up = hi if hi is not None else 1.0
    while not passes(up):
        up *= 10.0
    lo = up / 10.0
    while passes(lo):
        lo, up = lo / 10.0, lo
    return float(_bisect(passes, lo, up, rtol, max_iter=10_000)[0])


def _switching_cases(seed: int = 0) -> dict[str, list[float]]:
    """The periodic δ sequences of `python -m synthesis.lower_bound` (one period each)."""
    rng = np.random.default_rng(seed)
    out: dict[str, list[float]] = {"constant 0": [0.0], "constant 1": [1.0], "+1,-1": [1.0, -1.0]}
    for N in (2, 5, 20, 100):
        out[f"square +1 x{N}, -1 x{N}"] = [1.0] * N + [-1.0] * N
    out["0,1"] = [0.0, 1.0]
    out["0,0,1,-1"] = [0.0, 0.0, 1.0, -1.0]
    out["random +-1 (600)"] = [float(x) for x in rng.choice([-1.0, 1.0], 600)]
    for e in (0.02, 0.05, 0.1, 0.2):
        out[f"+{e},-{e}"] = [e, -e]
    for e in (0.05, 0.2):
        for N in (3, 30):
            out[f"square +{e} x{N}, -{e} x{N}"] = [e] * N + [-e] * N
    return out


def _main(argv: list[str] | None = None) -> None:
    """CLI: the flux observer's frozen bound next to `switching_filter_lower_bound` for periodic ω_r sequences."""
    import argparse
    import json
    import time

    ap = argparse.ArgumentParser(prog="python -m synthesis.lower_bound", description=_main.__doc__)
    ap.add_argument("--omega-max", type=float, default=400.0)
    ap.add_argument("--discretisation", choices=("full", "thesis"), default="thesis")
    ap.add_argument("--horizon", type=int, default=6000, help="samples (from x_0 = 0)")
    a = ap.parse_args(argv)

    P = flux_observer_plant_discrete(a.omega_max, variant="partial" if a.discretisation == "thesis" else "full")
    frozen = lpv_lower_bound(P, [np.zeros((1, 1))], rtol=1e-6).value
    rows = []
    for name, per in _switching_cases().items():
        t0 = time.perf_counter()
        g = switching_filter_lower_bound(P, [np.array([[d]]) for d in per], repeats=max(1, a.horizon // len(per)),
                                         hi=frozen, rtol=3e-4)  # fmt: skip
        rows.append(dict(sequence=name, bound=g, ratio_to_frozen=g / frozen, seconds=time.perf_counter() - t0))
    print(json.dumps(dict(omega_r_max=a.omega_max, discretisation=a.discretisation, horizon=a.horizon,
                          frozen_bound=frozen, switching=rows), indent=1))  # fmt: skip


if __name__ == "__main__":
    _main()
