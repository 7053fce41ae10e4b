"""A synthesised LPV controller run sample by sample with Python scalars (thesis 5.4.4, (5.36), (5.57)).

`ScheduledLaw` is the per-tick form of `synthesis.construct.LPVRuntime` for a diagonal scheduling
parameter Δ = diag(δ_1, ..., δ_m) (real δ; the matrices may be real or complex):

    Δ_c(Δ) = N_− V_−^* (S^*PS − V_− N_− V_−^*)^{-1} V_+,   S = [Δ; I],  [V_− V_+] = S^* U      (5.36)
    z̃_c = C_c2 x_c + D_c21 y,   w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c,
    u = C_c1 x_c + D_c11 y + D_c12 w_c,   x_c ← A_c x_c + B_c1 y + B_c2 w_c.

Because Δ is diagonal, S^*PS and V are formed entry by entry; the small inversions are closed-form for
2 x 2 and Gaussian elimination otherwise. No numpy per tick. Used by the LPV current controller
(`bench.controllers.lpv_current`, which adds an unrolled fast path) and the LPV speed controller
(`bench.controllers.lpv_speed`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["ScheduledLaw", "solve_small"]

HORIZON = 4  # samples per controller state over which a hand-over holds the outgoing part's output
FIRST_WEIGHT = 10.0  # the first sample's weight in it (the jump itself)


def _inv2(a: Any, b: Any, c: Any, d: Any) -> tuple[Any, Any, Any, Any]:
    det = a * d - b * c
    return d / det, -b / det, -c / det, a / det


def solve_small(M: list[list[Any]], B: list[list[Any]]) -> list[list[Any]]:
    """M^{-1} B for a small square M (closed form for 2 x 2, else Gaussian elimination with partial pivoting)."""
    n = len(M)
    if n == 2:
        a, b, c, d = _inv2(M[0][0], M[0][1], M[1][0], M[1][1])
        return [[a * x + b * y for x, y in zip(B[0], B[1])], [c * x + d * y for x, y in zip(B[0], B[1])]]
    A = [M[i][:] + B[i][:] for i in range(n)]
    w = len(A[0])
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(A[r][c]))
        A[c], A[p] = A[p], A[c]
        piv = A[c][c]
        for r in range(c + 1, n):
            f = A[r][c] / piv
            if f:
                Ar, Ac = A[r], A[c]
                for j in range(c, w):
                    Ar[j] -= f * Ac[j]
    X = [[0.0 * A[0][0]] * (w - n) for _ in range(n)]
    for r in range(n - 1, -1, -1):
        for j in range(w - n):
            s = A[r][n + j] - sum(A[r][k] * X[k][j] for k in range(r + 1, n))
            X[r][j] = s / A[r][r]
    return X


class ScheduledLaw:
    """The LPV controller (5.57) with scheduling (5.36) of a `ScheduledController`, one sample per `step`.

    ``y`` is a sequence of n_y scalars, ``d`` the m diagonal entries of Δ (normalised); `step` returns
    the n_u outputs as a list and advances the state, `evaluate` returns (u, next state) without.
    """

    def __init__(self, ctrl: Any) -> None:
        K, S = ctrl.K, ctrl.scheduling
        if S.n_wu != S.n_zu:
            raise ValueError(f"diagonal scheduling needs a square Δ, got {S.n_wu}x{S.n_zu}")
        cplx = any(np.iscomplexobj(a) and np.any(np.imag(a)) for a in (K.M, S.P, S.U))
        conv = complex if cplx else float

        def rows(M: np.ndarray) -> list[list[Any]]:
            return [[conv(v) if cplx else float(np.real(v)) for v in r] for r in np.asarray(M)]

        self.complex = cplx
        self.n_c, self.n_y, self.n_u = K.n_c, K.n_y, K.n_u
        self.m_c, self.k_c, self.m = K.n_wc, K.n_zc, S.n_wu
        if (self.m_c, self.k_c) != (S.m_c, S.k_c):
            raise ValueError("scheduling and controller sizes disagree")
        self._Ac, self._Bc1, self._Bc2 = rows(K.A_c), rows(K.B_c1), rows(K.B_c2)
        self._Cc1, self._Dc11, self._Dc12 = rows(K.C_c1), rows(K.D_c11), rows(K.D_c12)
        self._Cc2, self._Dc21, self._Dc22 = rows(K.C_c2), rows(K.D_c21), rows(K.D_c22)
        m = self.m
        P = np.asarray(S.P)
        self._Q, self._S, self._R = rows(P[:m, :m]), rows(P[:m, m:]), rows(P[m:, m:])
        self._Uw, self._Uz = rows(S.U[:m]), rows(S.U[m:])
        self._lam = [float(v) for v in S.lam]
        self._arrays: dict[str, np.ndarray] | None = None  # the matrices as arrays (`frozen`), made at first use
        self.reset()

    def reset(self) -> None:
        self.x = [0.0 * (1j if self.complex else 1.0)] * self.n_c

    def delta_c(self, d: Sequence[float]) -> list[list[Any]]:
        """Δ_c(Δ) of (5.36), m_c x k_c, for Δ = diag(d)."""
        Q, S, R, Uw, Uz, lam, mc, m = self._Q, self._S, self._R, self._Uw, self._Uz, self._lam, self.m_c, self.m
        nk = len(lam)
        V = [[d[i] * Uw[i][k] + Uz[i][k] for k in range(nk)] for i in range(m)]  # S^* U, S = [Δ; I]
        M = [[d[i] * d[j] * Q[i][j] + d[i] * S[i][j] + d[j] * S[j][i].conjugate() + R[i][j]
              - sum(V[i][k] * lam[k] * V[j][k].conjugate() for k in range(mc)) for j in range(m)]
             for i in range(m)]  # fmt: skip
        X = solve_small(M, [row[mc:] for row in V])  # M^{-1} V_+
        return [[lam[r] * sum(V[i][r].conjugate() * X[i][k] for i in range(m)) for k in range(nk - mc)]
                for r in range(mc)]  # fmt: skip

    def evaluate(self, y: Sequence[Any], d: Sequence[float]) -> tuple[list[Any], list[Any]]:
        """(u, x_next) for y and Δ = diag(d) at the current state (5.4.4); the state is not changed."""
        x = self.x
        nc, kc, mc = self.n_c, self.k_c, self.m_c
        if mc:
            Dc = self.delta_c(d)
            Cc2, Dc21, Dc22 = self._Cc2, self._Dc21, self._Dc22
            zt = [[sum(a * b for a, b in zip(Cc2[i], x)) + sum(a * b for a, b in zip(Dc21[i], y))] for i in range(kc)]
            L = [[(1.0 if i == j else 0.0) - sum(Dc22[i][r] * Dc[r][j] for r in range(mc)) for j in range(kc)]
                 for i in range(kc)]  # fmt: skip
            v = [row[0] for row in solve_small(L, zt)]  # (I − D_c22 Δ_c)^{-1} z̃_c
            wc = [sum(Dc[r][k] * v[k] for k in range(kc)) for r in range(mc)]
        else:
            wc = []
        u = [sum(a * b for a, b in zip(self._Cc1[i], x)) + sum(a * b for a, b in zip(self._Dc11[i], y))
             + sum(a * b for a, b in zip(self._Dc12[i], wc)) for i in range(self.n_u)]  # fmt: skip
        xn = [sum(a * b for a, b in zip(self._Ac[i], x)) + sum(a * b for a, b in zip(self._Bc1[i], y))
              + sum(a * b for a, b in zip(self._Bc2[i], wc)) for i in range(nc)]  # fmt: skip
        return u, xn

    def frozen(self, d: Sequence[float]) -> tuple[np.ndarray, ...]:
        """(A, B, C, D) of the LTI controller frozen at Δ = diag(d): w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c closed
        into (5.57), so x_c+ = A x_c + B y and u = C x_c + D y."""
        if self._arrays is None:  # the law's matrices as arrays, once (a hand-over is between two ticks)
            nc, ny, nu, mc, kc = self.n_c, self.n_y, self.n_u, self.m_c, self.k_c
            shapes = {"_Ac": (nc, nc), "_Bc1": (nc, ny), "_Cc1": (nu, nc), "_Dc11": (nu, ny), "_Bc2": (nc, mc),
                      "_Dc12": (nu, mc), "_Cc2": (kc, nc), "_Dc21": (kc, ny), "_Dc22": (kc, mc)}  # fmt: skip
            self._arrays = {k: np.asarray(getattr(self, k), dtype=complex).reshape(r) for k, r in shapes.items()}
        a = self._arrays
        A, B1, C1, D11 = a["_Ac"], a["_Bc1"], a["_Cc1"], a["_Dc11"]
        if not self.m_c:
            return A, B1, C1, D11
        Dc = np.asarray(self.delta_c(d), dtype=complex).reshape(self.m_c, self.k_c)
        M = Dc @ np.linalg.inv(np.eye(self.k_c) - a["_Dc22"] @ Dc)
        B2M, D12M = a["_Bc2"] @ M, a["_Dc12"] @ M
        return A + B2M @ a["_Cc2"], B1 + B2M @ a["_Dc21"], C1 + D12M @ a["_Cc2"], D11 + D12M @ a["_Dc21"]

    def take_over(self, y: Sequence[Any], d: Sequence[float], u: Sequence[Any], outputs: Sequence[int]) -> None:
        """Bumpless start (a switch from another part): the state whose output (the indices ``outputs``) stays
        nearest ``u`` over the next `HORIZON` x n_c samples at constant input ``y`` and scheduling ``d``, the
        first sample weighted `FIRST_WEIGHT` times (least squares, the frozen law `frozen`). Matching the first output alone would leave the rest of the state free, and
        a minimum-norm choice of it excites the law's fast modes (the LPV speed law alternates then: measured,
        docs/switching.md); holding the output over a horizon puts the state where the law itself would hold
        it. The law's own steady state (it may have no integrator) is where it then drifts, at its own pace."""
        A, B, C, D = self.frozen(d)
        n, idx = self.n_c, list(outputs)
        yv = np.asarray(y, dtype=complex)
        C, Dy = C[idx], D[idx] @ yv
        N, k = HORIZON * n, len(idx)
        O = np.empty((N * k, n), dtype=complex)  # rows C A^j
        F = np.empty((N * k,), dtype=complex)  # C sum_{i<j} A^i B y: the outputs' response to the held input
        CA, f, By = C, np.zeros(k, dtype=complex), B @ yv
        for j in range(N):
            O[j * k:(j + 1) * k], F[j * k:(j + 1) * k] = CA, f
            f = f + CA @ By
            CA = CA @ A
        rhs = np.tile(np.asarray(u, dtype=complex) - Dy, N) - F
        O[:k] *= FIRST_WEIGHT
        rhs[:k] *= FIRST_WEIGHT
        x = np.linalg.lstsq(O, rhs, rcond=None)[0]
        self.x = [complex(v) for v in x] if self.complex else [float(v.real) for v in x]

    def step(self, y: Sequence[Any], d: Sequence[float]) -> list[Any]:
        u, self.x = self.evaluate(y, d)
        return u
