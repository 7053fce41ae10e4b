"""A synthesised LPV controller run sample by sample (thesis 5.4.4, (5.36), (5.57)): the law's kernels, written once.

`ScheduledLaw` is the per-tick form of `synthesis.construct.LPVRuntime` for a diagonal scheduling
parameter Δ = diag(δ_1, ..., δ_m) (real δ; the matrices may be real or complex):

    Δ_c(Δ) = N_− V_−^* (S^*PS − V_− N_− V_−^*)^{-1} V_+,   S = [Δ; I],  [V_− V_+] = S^* U      (5.36)
    z̃_c = C_c2 x_c + D_c21 y,   w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c,
    u = C_c1 x_c + D_c11 y + D_c12 w_c,   x_c ← A_c x_c + B_c1 y + B_c2 w_c.

Because Δ is diagonal, S^*PS and V are formed entry by entry; the small inversions are closed-form for
2 x 2 and Gaussian elimination otherwise (`solve_into`); `step22` is the whole sample written out for
m_c = k_c = 2, the shape of the shipped current controllers.

These functions are the one definition of the law: the Python engine calls them on the law's lists of Python numbers,
`bench.controllers.lpv_compiled` compiles them with numba onto its buffer (docs/architecture.md, "Kernels written
once"). A law lives in two flat stores: ``e``, its entries (complex or real, the law's kind: the matrices row-major,
the state, the scratch of one evaluation), and ``r``, its reals (the multipliers λ and Δ's diagonal); ``o`` holds
each block's start, indexed by `OF` (`layout`). The kernels index the stores from those starts, write their results
into them and allocate nothing; a sum starts from ``zero`` (0.0 or 0j, the law's kind), as Python's ``sum`` does.
Used by the LPV current controller (`bench.controllers.lpv_current`) and the LPV speed controller
(`bench.controllers.lpv_speed`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bench.controllers.kernel_math import abs_checked

from bench.core.slots import slots

__all__ = ["OF", "ScheduledLaw", "clip", "commit", "dot", "evaluate_into", "layout", "solve_into", "step22"]

HORIZON = 4  # samples per controller state over which a hand-over holds the outgoing part's output
FIRST_WEIGHT = 10.0  # the first sample's weight in it (the jump itself)
#: the law's matrices, the first blocks of its entries
MATRICES = ("Ac", "Bc1", "Bc2", "Cc1", "Dc11", "Dc12", "Cc2", "Dc21", "Dc22", "Q", "S", "R", "Uw", "Uz")
#: the blocks' starts in ``o``: in ``e`` the matrices, the state x, then the scratch (y, u, the next state, V = S^* U,
#: M = S^*PS − V_− N_− V_−^*, M^{-1} V_+, Δ_c, z̃_c, L = I − D_c22 Δ_c, L^{-1} z̃_c, w_c, the elimination's [M B]);
#: in ``r`` the multipliers λ and Δ's diagonal
OF = slots("LPVLawOffsets", AC="i", BC1="i", BC2="i", CC1="i", DC11="i", DC12="i", CC2="i", DC21="i", DC22="i", Q="i",
           S="i", R="i", UW="i", UZ="i", X="i", Y="i", U="i", XN="i", V="i", MM="i", XS="i", DC="i", ZT="i", L="i",
           VV="i", WC="i", A="i", LAM="i", D="i")  # fmt: skip
N_OF = type(OF).size


def layout(dims: tuple) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(o, the blocks' sizes) of a law of ``dims`` = (n_c, n_y, n_u, m_c, k_c, m, n_k)."""
    nc, ny, nu, mc, kc, m, nk = dims
    nb = nk - mc
    sizes = (nc * nc, nc * ny, nc * mc, nu * nc, nu * ny, nu * mc, kc * nc, kc * ny, kc * mc, m * m, m * m, m * m,
             m * nk, m * nk, nc, ny, nu, nc, m * nk, m * m, m * nb, mc * nb, kc, kc * kc, kc, mc,
             max(m * (m + nb), kc * (kc + 1)), nk, m)  # fmt: skip
    o, p = [], 0
    for n in sizes[:OF.LAM]:
        o.append(p)
        p += n
    return (*o, 0, nk), sizes


def clip(v: float, lo: float, hi: float) -> float:
    """min(max(v, lo), hi) as Python's builtins give it (NaN stays NaN)."""
    v = lo if lo > v else v
    return hi if hi < v else v


def dot(a: Any, pa: int, b: Any, pb: int, n: int, zero: Any) -> Any:
    """sum(a[pa + k] * b[pb + k] for k in range(n)), added left to right from ``zero``."""
    s = zero
    for k in range(n):
        s = s + a[pa + k] * b[pb + k]
    return s


def commit(e: Any, o: Any, n: int) -> None:
    """The state x = the next state (the law advanced)."""
    px, pn = o[OF.X], o[OF.XN]
    for k in range(n):
        e[px + k] = e[pn + k]


def solve_into(e: Any, pM: int, pB: int, bs: int, pX: int, pA: int, n: int, nb: int, zero: Any) -> None:
    """X = M^{-1} B for a small square M (n x n) and B (n x nb, its rows ``bs`` entries apart), all in ``e`` (X n x nb
    at pX): closed form for 2 x 2, else Gaussian elimination with partial pivoting (the first of the largest pivots)
    on the scratch at pA (n x (n + nb)). Matrices are row-major."""
    if n == 2:
        a, b, c, d = e[pM], e[pM + 1], e[pM + 2], e[pM + 3]
        det = a * d - b * c
        i00, i01, i10, i11 = d / det, -b / det, -c / det, a / det
        for j in range(nb):
            u, v = e[pB + j], e[pB + bs + j]
            e[pX + j] = i00 * u + i01 * v
            e[pX + nb + j] = i10 * u + i11 * v
        return
    w = n + nb
    for i in range(n):
        for j in range(n):
            e[pA + i * w + j] = e[pM + i * n + j]
        for j in range(nb):
            e[pA + i * w + n + j] = e[pB + i * bs + j]
    for c in range(n):
        p, best = c, abs_checked(e[pA + c * w + c])
        for r in range(c + 1, n):
            v = abs_checked(e[pA + r * w + c])
            if v > best:
                p, best = r, v
        if p != c:
            for j in range(w):
                e[pA + c * w + j], e[pA + p * w + j] = e[pA + p * w + j], e[pA + c * w + j]
        piv = e[pA + c * w + c]
        for r in range(c + 1, n):
            f = e[pA + r * w + c] / piv
            if f != zero:  # (NaN too)
                for j in range(c, w):
                    e[pA + r * w + j] = e[pA + r * w + j] - f * e[pA + c * w + j]
    for r in range(n - 1, -1, -1):
        for j in range(nb):
            s = zero
            for k in range(r + 1, n):
                s = s + e[pA + r * w + k] * e[pX + k * nb + j]
            e[pX + r * nb + j] = (e[pA + r * w + n + j] - s) / e[pA + r * w + r]


def delta_c_into(e: Any, r: Any, o: Any, dims: tuple, zero: Any) -> None:
    """Δ_c(Δ) of (5.36), m_c x (n_k − m_c), into the block DC for Δ = diag(d)."""
    mc, m, nk = dims[3], dims[5], dims[6]
    nb = nk - mc
    pQ, pS, pR, pUw, pUz, pV, pM = o[OF.Q], o[OF.S], o[OF.R], o[OF.UW], o[OF.UZ], o[OF.V], o[OF.MM]
    pXS, pDc, lam, d = o[OF.XS], o[OF.DC], o[OF.LAM], o[OF.D]
    for i in range(m):  # V = S^* U, S = [Δ; I]
        for k in range(nk):
            e[pV + i * nk + k] = r[d + i] * e[pUw + i * nk + k] + e[pUz + i * nk + k]
    for i in range(m):
        for j in range(m):
            s = zero
            for k in range(mc):
                s = s + e[pV + i * nk + k] * r[lam + k] * e[pV + j * nk + k].conjugate()
            e[pM + i * m + j] = (r[d + i] * r[d + j] * e[pQ + i * m + j] + r[d + i] * e[pS + i * m + j]
                                 + r[d + j] * e[pS + j * m + i].conjugate() + e[pR + i * m + j] - s)  # fmt: skip
    solve_into(e, pM, pV + mc, nk, pXS, o[OF.A], m, nb, zero)  # M^{-1} V_+
    for i in range(mc):
        for k in range(nb):
            s = zero
            for j in range(m):
                s = s + e[pV + j * nk + i].conjugate() * e[pXS + j * nb + k]
            e[pDc + i * nb + k] = r[lam + i] * s


def evaluate_into(e: Any, r: Any, o: Any, dims: tuple, zero: Any) -> None:
    """u and the next state (blocks U, XN) for y and Δ = diag(d) (blocks Y, D) at the state x (5.4.4); x is not
    changed."""
    nc, ny, nu, mc, kc = dims[:5]
    px, py, pWC = o[OF.X], o[OF.Y], o[OF.WC]
    if mc:
        delta_c_into(e, r, o, dims, zero)
        pDc, pZT, pL, pVV, pDc22 = o[OF.DC], o[OF.ZT], o[OF.L], o[OF.VV], o[OF.DC22]
        for i in range(kc):
            e[pZT + i] = dot(e, o[OF.CC2] + i * nc, e, px, nc, zero) + dot(e, o[OF.DC21] + i * ny, e, py, ny, zero)
        for i in range(kc):
            for j in range(kc):
                s = zero
                for k in range(mc):
                    s = s + e[pDc22 + i * mc + k] * e[pDc + k * kc + j]
                e[pL + i * kc + j] = (1.0 if i == j else 0.0) - s
        solve_into(e, pL, pZT, 1, pVV, o[OF.A], kc, 1, zero)  # (I − D_c22 Δ_c)^{-1} z̃_c
        for k in range(mc):
            e[pWC + k] = dot(e, pDc + k * kc, e, pVV, kc, zero)
    for i in range(nu):
        e[o[OF.U] + i] = (dot(e, o[OF.CC1] + i * nc, e, px, nc, zero) + dot(e, o[OF.DC11] + i * ny, e, py, ny, zero)
                          + dot(e, o[OF.DC12] + i * mc, e, pWC, mc, zero))  # fmt: skip
    for i in range(nc):
        e[o[OF.XN] + i] = (dot(e, o[OF.AC] + i * nc, e, px, nc, zero) + dot(e, o[OF.BC1] + i * ny, e, py, ny, zero)
                           + dot(e, o[OF.BC2] + i * mc, e, pWC, mc, zero))  # fmt: skip


def step22(e: Any, r: Any, o: Any, nc: int, y: complex, d1: float, d2: float) -> complex:
    """One sample of a complex law with m_c = k_c = 2, n_y = n_u = 1 and four multipliers, written out (both shipped
    current controllers; about half the cost of `evaluate_into`): u for y and Δ = diag(d1, d2); the state advanced."""
    pQ, pS, pR, pUw, pUz = o[OF.Q], o[OF.S], o[OF.R], o[OF.UW], o[OF.UZ]
    q00, q01, q10, q11 = e[pQ], e[pQ + 1], e[pQ + 2], e[pQ + 3]
    s00, s01, s10, s11 = e[pS], e[pS + 1], e[pS + 2], e[pS + 3]
    r00, r01, r10, r11 = e[pR], e[pR + 1], e[pR + 2], e[pR + 3]
    l0, l1 = r[o[OF.LAM]], r[o[OF.LAM] + 1]
    # V = S^* U = Δ U_w + U_z (rows i = 0, 1; columns: two of N_−, two of N_+)
    a0, a1 = d1 * e[pUw] + e[pUz], d1 * e[pUw + 1] + e[pUz + 1]
    a2, a3 = d1 * e[pUw + 2] + e[pUz + 2], d1 * e[pUw + 3] + e[pUz + 3]
    b0, b1 = d2 * e[pUw + 4] + e[pUz + 4], d2 * e[pUw + 5] + e[pUz + 5]
    b2, b3 = d2 * e[pUw + 6] + e[pUz + 6], d2 * e[pUw + 7] + e[pUz + 7]
    # M = S^*PS − V_− N_− V_−^*
    m00 = d1 * d1 * q00 + d1 * (s00 + s00.conjugate()) + r00 - l0 * a0 * a0.conjugate() - l1 * a1 * a1.conjugate()
    m01 = d1 * d2 * q01 + d1 * s01 + d2 * s10.conjugate() + r01 - l0 * a0 * b0.conjugate() - l1 * a1 * b1.conjugate()
    m10 = d2 * d1 * q10 + d2 * s10 + d1 * s01.conjugate() + r10 - l0 * b0 * a0.conjugate() - l1 * b1 * a1.conjugate()
    m11 = d2 * d2 * q11 + d2 * (s11 + s11.conjugate()) + r11 - l0 * b0 * b0.conjugate() - l1 * b1 * b1.conjugate()
    det = m00 * m11 - m01 * m10
    # M^{-1} V_+
    p0 = (m11 * a2 - m01 * b2) / det
    p1 = (m11 * a3 - m01 * b3) / det
    t0 = (m00 * b2 - m10 * a2) / det
    t1 = (m00 * b3 - m10 * a3) / det
    # Δ_c = N_− V_−^* M^{-1} V_+
    c00 = l0 * (a0.conjugate() * p0 + b0.conjugate() * t0)
    c01 = l0 * (a0.conjugate() * p1 + b0.conjugate() * t1)
    c10 = l1 * (a1.conjugate() * p0 + b1.conjugate() * t0)
    c11 = l1 * (a1.conjugate() * p1 + b1.conjugate() * t1)
    px, pCc2, pDc21, pDc22 = o[OF.X], o[OF.CC2], o[OF.DC21], o[OF.DC22]
    zt0 = dot(e, pCc2, e, px, nc, 0j) + e[pDc21] * y
    zt1 = dot(e, pCc2 + nc, e, px, nc, 0j) + e[pDc21 + 1] * y
    e00, e01, e10, e11 = e[pDc22], e[pDc22 + 1], e[pDc22 + 2], e[pDc22 + 3]
    # L = I − D_c22 Δ_c, v = L^{-1} z̃, w_c = Δ_c v
    g00 = 1.0 - (e00 * c00 + e01 * c10)
    g01 = -(e00 * c01 + e01 * c11)
    g10 = -(e10 * c00 + e11 * c10)
    g11 = 1.0 - (e10 * c01 + e11 * c11)
    dg = g00 * g11 - g01 * g10
    v0 = (g11 * zt0 - g01 * zt1) / dg
    v1 = (g00 * zt1 - g10 * zt0) / dg
    wc0 = c00 * v0 + c01 * v1
    wc1 = c10 * v0 + c11 * v1
    pDc12 = o[OF.DC12]
    u = dot(e, o[OF.CC1], e, px, nc, 0j) + e[o[OF.DC11]] * y + e[pDc12] * wc0 + e[pDc12 + 1] * wc1
    pAc, pBc1, pBc2, pXN = o[OF.AC], o[OF.BC1], o[OF.BC2], o[OF.XN]
    for i in range(nc):
        e[pXN + i] = (dot(e, pAc + i * nc, e, px, nc, 0j) + e[pBc1 + i] * y + e[pBc2 + 2 * i] * wc0
                      + e[pBc2 + 2 * i + 1] * wc1)  # fmt: skip
    commit(e, o, nc)
    return u


class ScheduledLaw:
    """The LPV controller (5.57) with scheduling (5.36) of a `ScheduledController`, one sample per `step`.

    ``y`` is a sequence of n_y scalars, ``d`` the m diagonal entries of Δ (normalised); `step` returns
    the n_u outputs as a list and advances the state, `evaluate` returns (u, next state) without. ``complex_entries``
    makes every entry complex (a law whose state is complex by its use, the current controller's) where the
    matrices happen to be real.
    """

    def __init__(self, ctrl: Any, complex_entries: bool = False) -> None:
        K, S = ctrl.K, ctrl.scheduling
        if S.n_wu != S.n_zu:
            raise ValueError(f"diagonal scheduling needs a square Δ, got {S.n_wu}x{S.n_zu}")
        cplx = complex_entries or any(np.iscomplexobj(a) and np.any(np.imag(a)) for a in (K.M, S.P, S.U))

        def flat(M: np.ndarray) -> list[Any]:  # row-major
            return [complex(v) if cplx else float(np.real(v)) for r in np.asarray(M) for v in r]

        self.complex = cplx
        self.zero = 0j if cplx else 0.0
        self.n_c, self.n_y, self.n_u = K.n_c, K.n_y, K.n_u
        self.m_c, self.k_c, self.m = K.n_wc, K.n_zc, S.n_wu
        if (self.m_c, self.k_c) != (S.m_c, S.k_c):
            raise ValueError("scheduling and controller sizes disagree")
        m = self.m
        P = np.asarray(S.P)
        mats = dict(Ac=K.A_c, Bc1=K.B_c1, Bc2=K.B_c2, Cc1=K.C_c1, Dc11=K.D_c11, Dc12=K.D_c12, Cc2=K.C_c2,
                    Dc21=K.D_c21, Dc22=K.D_c22, Q=P[:m, :m], S=P[:m, m:], R=P[m:, m:], Uw=S.U[:m], Uz=S.U[m:])
        lam = [float(v) for v in S.lam]
        nk = len(lam)
        if self.m_c and nk - self.m_c != self.k_c:
            raise ValueError(f"Δ_c is {self.m_c} x {nk - self.m_c}, D_c22 {self.k_c} x {self.m_c}")
        #: n_c, n_y, n_u, m_c, k_c, m, n_k
        self.dims = (self.n_c, self.n_y, self.n_u, self.m_c, self.k_c, m, nk)
        self.o, self.sizes = layout(self.dims)
        #: the stores (the module docstring): the entries (the matrices, row-major, then the state and scratch) and the
        #: reals (λ, then Δ's diagonal)
        self.e = [v for k in MATRICES for v in flat(mats[k])]
        self.e += [self.zero] * (sum(self.sizes[:OF.LAM]) - len(self.e))
        self.r = lam + [0.0] * m
        self.shapes = {k: np.shape(mats[k]) for k in MATRICES}
        self._arrays: dict[str, np.ndarray] | None = None  # the matrices as arrays (`frozen`), made at first use
        self.reset()

    def block(self, name: str) -> list[Any]:
        """A block of ``e`` or ``r`` by its `OF` name, as a list (a copy)."""
        k = OF._fields.index(name)
        store = self.r if k >= OF.LAM else self.e
        return store[self.o[k]:self.o[k] + self.sizes[k]]

    @property
    def x(self) -> list[Any]:
        """The controller's state x_c (a copy)."""
        return self.e[self.o[OF.X]:self.o[OF.X] + self.n_c]

    @x.setter
    def x(self, value: Sequence[Any]) -> None:
        if len(value) != self.n_c:
            raise ValueError(f"the state has {self.n_c} entries, got {len(value)}")
        self.e[self.o[OF.X]:self.o[OF.X] + self.n_c] = value

    @property
    def d(self) -> list[float]:
        """Δ's diagonal of the last evaluation (a copy)."""
        return self.r[self.o[OF.D]:self.o[OF.D] + self.m]

    @d.setter
    def d(self, value: Sequence[float]) -> None:
        self.r[self.o[OF.D]:self.o[OF.D] + self.m] = value

    def reset(self) -> None:
        self.x = [self.zero] * self.n_c

    def delta_c(self, d: Sequence[float]) -> list[list[Any]]:
        """Δ_c(Δ) of (5.36), m_c x k_c, for Δ = diag(d)."""
        self.d = d
        delta_c_into(self.e, self.r, self.o, self.dims, self.zero)
        Dc, nb = self.block("DC"), self.dims[6] - self.m_c
        return [Dc[i * nb:(i + 1) * nb] for i in range(self.m_c)]

    def evaluate(self, y: Sequence[Any], d: Sequence[float]) -> tuple[list[Any], list[Any]]:
        """(u, x_next) for y and Δ = diag(d) at the current state (5.4.4); the state is not changed."""
        self.e[self.o[OF.Y]:self.o[OF.Y] + self.n_y] = y
        self.d = d
        evaluate_into(self.e, self.r, self.o, self.dims, self.zero)
        return self.block("U"), self.block("XN")

    def frozen(self, d: Sequence[float]) -> tuple[np.ndarray, ...]:
        """(A, B, C, D) of the LTI controller frozen at Δ = diag(d): w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c closed
        into (5.57), so x_c+ = A x_c + B y and u = C x_c + D y."""
        if self._arrays is None:  # the law's matrices as arrays, once (a hand-over is between two ticks)
            self._arrays = {k: np.asarray(self.block(k.upper()), dtype=complex).reshape(self.shapes[k])
                            for k in MATRICES[:9]}  # fmt: skip
        a = self._arrays
        A, B1, C1, D11 = a["Ac"], a["Bc1"], a["Cc1"], a["Dc11"]
        if not self.m_c:
            return A, B1, C1, D11
        Dc = np.asarray(self.delta_c(d), dtype=complex).reshape(self.m_c, self.k_c)
        M = Dc @ np.linalg.inv(np.eye(self.k_c) - a["Dc22"] @ Dc)
        B2M, D12M = a["Bc2"] @ M, a["Dc12"] @ M
        return A + B2M @ a["Cc2"], B1 + B2M @ a["Dc21"], C1 + D12M @ a["Cc2"], D11 + D12M @ a["Dc21"]

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
