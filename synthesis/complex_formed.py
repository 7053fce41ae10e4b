"""Complex-formed matrices and systems: complex n <-> real 2n forms, T_C and the projection (thesis 3.3.2, 5.5).

A matrix is *complex-formed* (Def. 5.16) if it is  [[M_r, −M_i], [M_i, M_r]]  with M_r, M_i of
equal size (they may themselves be complex). The real form of a complex matrix (3.45) is the
complex-formed matrix with M_r = Re M, M_i = Im M, and a complex signal vector x becomes
[Re x; Im x] (3.46) -- real parts of *all* entries first, then all imaginary parts, as in the
motor's real state x_sr = [i_sD, i_mD, i_sQ, i_mQ] of (3.47).

Reading of the definitions (the text extraction lost some symbols; reconstructed from context):

- T_C (5.65) maps C_M^{2m x 2n} -> C^{m x n}:  T_C([[M_r, −M_i], [M_i, M_r]]) = M_r + j M_i. On real
  complex-formed matrices it inverts (3.45); on complex ones it is not injective (Remark 5.19). It
  is additive and multiplicative and commutes with inversion (Lemma 5.20).
- J_k = [[0, −I_k], [I_k, 0]] (Lemma 5.29); T_C(J_k) = j I_k, and A J_n = J_m A for complex-formed A.
- Q = [[0, I], [I, 0]] (5.67).
- The projection (5.74) of X ∈ C^{2m x 2l} is X_c = ½ (X + J_m^* X J_l)
  = ½ [[X1 + X4, −(X3 − X2)], [X3 − X2, X1 + X4]]. It is the orthogonal (Frobenius) projection onto
  the complex-formed matrices, and X − X_c = Q X_c̄ with X_c̄ complex-formed (proof of Thm 5.30).
- For a partitioned matrix whose sub-blocks are each complex-formed (the multipliers of Example 5.32),
  projecting each sub-block separately equals the thesis' ½ (P X_0 P^* + P J^* X_0 J P^*) with the
  permutation P; `project_blocks` does that.
- A *system* is complex-formed (Def. 5.21) if its transfer matrix is complex-formed at every s. That
  is a property of the transfer function; `is_complex_formed_tf` tests it independently of the
  realisation, `is_complex_formed_ss` tests the sufficient realisation condition of Cor. 5.22.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from synthesis.lft import LFTController, LFTPlant, StateSpace, _as_matrix, _offsets

__all__ = [
    "complex_formed",
    "real_form",
    "t_c",
    "is_complex_formed",
    "j_matrix",
    "q_matrix",
    "project",
    "decompose",
    "project_blocks",
    "vec_real",
    "vec_complex",
    "interleaved_to_blocked",
    "ss_real_form",
    "ss_t_c",
    "is_complex_formed_ss",
    "is_complex_formed_tf",
    "lft_real_form",
    "lft_t_c",
    "controller_real_form",
    "controller_t_c",
]

_RTOL = 1e-9
_ATOL = 1e-12


# --------------------------------------------------------------------------------------------------
# matrices
# --------------------------------------------------------------------------------------------------
def complex_formed(M_r: ArrayLike, M_i: ArrayLike) -> np.ndarray:
    """[[M_r, −M_i], [M_i, M_r]] (Def. 5.16); M_r and M_i may be complex."""
    R, I = _as_matrix(M_r, "M_r"), _as_matrix(M_i, "M_i")
    if R.shape != I.shape:
        raise ValueError(f"M_r {R.shape} and M_i {I.shape} must have the same shape")
    return np.block([[R, -I], [I, R]]) if R.size else np.zeros((2 * R.shape[0], 2 * R.shape[1]), np.result_type(R, I))


def real_form(M: ArrayLike) -> np.ndarray:
    """A_r + j A_i -> [[A_r, −A_i], [A_i, A_r]] (3.45): the real 2m x 2n form of a complex m x n matrix."""
    Mc = np.asarray(_as_matrix(M, "M"), dtype=complex)
    return complex_formed(Mc.real, Mc.imag)


def _halves(M: np.ndarray) -> tuple[int, int]:
    if M.shape[0] % 2 or M.shape[1] % 2:
        raise ValueError(f"a complex-formed matrix has even dimensions, got {M.shape}")
    return M.shape[0] // 2, M.shape[1] // 2


def is_complex_formed(M: ArrayLike, *, rtol: float = _RTOL, atol: float = _ATOL) -> bool:
    """True if M = [[M_r, −M_i], [M_i, M_r]] up to atol + rtol·max|M| (Def. 5.16)."""
    Ma = _as_matrix(M, "M")
    if Ma.shape[0] % 2 or Ma.shape[1] % 2:
        return False
    m, n = _halves(Ma)
    if Ma.size == 0:
        return True
    tol = atol + rtol * np.max(np.abs(Ma))
    d1 = np.max(np.abs(Ma[:m, :n] - Ma[m:, n:]))
    d2 = np.max(np.abs(Ma[:m, n:] + Ma[m:, :n]))
    return bool(max(d1, d2) <= tol)


def t_c(M: ArrayLike, *, check: bool = True, rtol: float = _RTOL, atol: float = _ATOL) -> np.ndarray:
    """T_C([[M_r, −M_i], [M_i, M_r]]) = M_r + j M_i (5.65).

    With ``check`` (default) a ValueError is raised unless M is complex-formed to the tolerance;
    the result is computed from the averaged blocks, i.e. it is T_C of `project(M)`.
    """
    Ma = _as_matrix(M, "M")
    m, n = _halves(Ma)
    if check and not is_complex_formed(Ma, rtol=rtol, atol=atol):
        raise ValueError("matrix is not complex-formed; use project() first or check=False")
    Mr = 0.5 * (Ma[:m, :n] + Ma[m:, n:])
    Mi = 0.5 * (Ma[m:, :n] - Ma[:m, n:])
    return Mr + 1j * Mi


def j_matrix(k: int) -> np.ndarray:
    """J_k = [[0, −I_k], [I_k, 0]] (Lemma 5.29)."""
    return complex_formed(np.zeros((k, k)), np.eye(k))


def q_matrix(k: int) -> np.ndarray:
    """Q = [[0, I_k], [I_k, 0]] (5.67)."""
    Z, I = np.zeros((k, k)), np.eye(k)
    return np.block([[Z, I], [I, Z]])


def project(X: ArrayLike) -> np.ndarray:
    """X_c = ½ (X + J_m^* X J_l) = ½ [[X1 + X4, −(X3 − X2)], [X3 − X2, X1 + X4]] (5.74).

    Idempotent, lands in the complex-formed matrices, and is the orthogonal (Frobenius) projection
    onto them. Preserves Hermitian symmetry and any block structure common to X1..X4.
    """
    Xa = _as_matrix(X, "X")
    m, n = _halves(Xa)
    X1, X2, X3, X4 = Xa[:m, :n], Xa[:m, n:], Xa[m:, :n], Xa[m:, n:]
    return complex_formed(0.5 * (X1 + X4), 0.5 * (X3 - X2))


def decompose(X: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """X = X_c + Q X_c̄ with X_c, X_c̄ both complex-formed (proof of Thm 5.30); returns (X_c, X_c̄)."""
    Xa = _as_matrix(X, "X")
    Xc = project(Xa)
    m, _ = _halves(Xa)
    return Xc, q_matrix(m) @ (Xa - Xc)


def project_blocks(X: ArrayLike, row_sizes: Sequence[int], col_sizes: Sequence[int] | None = None) -> np.ndarray:
    """Apply (5.74) to every sub-block of a partitioned matrix (Example 5.32).

    ``row_sizes``/``col_sizes`` are the (even) full sizes of the sub-blocks, e.g. [2n, 2p] for the
    multiplier [[Q, S], [S^*, R]]. Hermitian symmetry of X and of its diagonal blocks is preserved.
    """
    Xa = _as_matrix(X, "X")
    cs = list(row_sizes) if col_sizes is None else list(col_sizes)
    if sum(row_sizes) != Xa.shape[0] or sum(cs) != Xa.shape[1]:
        raise ValueError(f"block sizes {list(row_sizes)} x {cs} do not fit a {Xa.shape} matrix")
    out = np.empty_like(Xa)
    for rs in _offsets(row_sizes):
        for cl in _offsets(cs):
            out[rs, cl] = project(Xa[rs, cl])
    return out


# --------------------------------------------------------------------------------------------------
# signals
# --------------------------------------------------------------------------------------------------
def vec_real(x: ArrayLike) -> np.ndarray:
    """x_r + j x_i -> [x_r; x_i] (3.46); works along the first axis (vectors or stacks of columns)."""
    xc = np.asarray(x, dtype=complex)
    return np.concatenate([xc.real, xc.imag], axis=0)


def vec_complex(x: ArrayLike) -> np.ndarray:
    """[x_r; x_i] -> x_r + j x_i, the inverse of (3.46)."""
    xa = np.asarray(x)
    if xa.shape[0] % 2:
        raise ValueError(f"length {xa.shape[0]} is odd")
    n = xa.shape[0] // 2
    return xa[:n] + 1j * xa[n:]


def interleaved_to_blocked(n: int) -> np.ndarray:
    """Index array p with x_blocked = x_interleaved[p] for [re_1, im_1, ..., re_n, im_n] -> [re; im] (3.46).

    Use it to bring a real model written in interleaved order (e.g. [i_sD, i_sQ, i_mD, i_mQ]) into
    the order in which its matrices are complex-formed: A_blocked = A[np.ix_(p, p)].
    """
    return np.concatenate([np.arange(0, 2 * n, 2), np.arange(1, 2 * n, 2)])


# --------------------------------------------------------------------------------------------------
# state-space systems
# --------------------------------------------------------------------------------------------------
def ss_real_form(sys: StateSpace) -> StateSpace:
    """Real 2n-state form of a complex n-state system by (3.45)/(3.46) on A, B, C, D."""
    return StateSpace(real_form(sys.A), real_form(sys.B), real_form(sys.C), real_form(sys.D), sys.dt)


def ss_t_c(sys: StateSpace, *, check: bool = True) -> StateSpace:
    """T_C on every matrix (Cor. 5.22): T_C(G(s)) = T_C(C) (sI − T_C(A))^{-1} T_C(B) + T_C(D)."""
    return StateSpace(t_c(sys.A, check=check), t_c(sys.B, check=check), t_c(sys.C, check=check),
                      t_c(sys.D, check=check), sys.dt)  # fmt: skip


def is_complex_formed_ss(sys: StateSpace, *, rtol: float = 1e-9) -> bool:
    """All of A, B, C, D complex-formed in the given realisation (the hypothesis of Cor. 5.22)."""
    return all(is_complex_formed(X, rtol=rtol) for X in (sys.A, sys.B, sys.C, sys.D))


def is_complex_formed_tf(sys: StateSpace, *, rtol: float = 1e-8) -> bool:
    """Def. 5.21: is G(s) complex-formed for all s? Realisation independent.

    G is complex-formed iff H(s) = G(s) J_m − J_p G(s) ≡ 0 (Lemma 5.29). H is rational with
    denominator det(sI − A) of degree n, so it vanishes identically iff it vanishes at n + 1
    distinct non-poles. D is checked exactly; the strictly proper part is evaluated at 2n + 2
    points spread over the magnitudes of A's eigenvalues, each relative to its own size.
    """
    if sys.n_inputs % 2 or sys.n_outputs % 2:
        return False
    if not is_complex_formed(sys.D, rtol=rtol):
        return False
    n = sys.n_states
    if n == 0:
        return True
    Jm, Jp = j_matrix(sys.n_inputs // 2), j_matrix(sys.n_outputs // 2)
    lam = np.abs(np.linalg.eigvals(sys.A))
    big = max(float(lam.max()), 1.0)
    small = max(float(lam[lam > 0].min()) if np.any(lam > 0) else big, big * 1e-6)
    radii = np.geomspace(0.5 * small, 2.0 * big, 2 * n + 2)
    angles = 0.3 + np.arange(2 * n + 2) * 2.399963229728653  # golden angle: distinct, off the real axis
    for r, a in zip(radii, angles):
        s = r * np.exp(1j * a)
        G = sys.C @ np.linalg.solve(s * np.eye(n) - sys.A, sys.B.astype(complex))
        scale = np.max(np.abs(G)) if G.size else 0.0
        if G.size and np.max(np.abs(G @ Jm - Jp @ G)) > rtol * scale + _ATOL:
            return False
    return True


# --------------------------------------------------------------------------------------------------
# LFT plants and controllers: block-wise forms (every channel doubles, each as [Re; Im])
# --------------------------------------------------------------------------------------------------
def _map_grid(
    M: np.ndarray, rows: Sequence[int], cols: Sequence[int], f: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Apply f to every block of the grid given by rows x cols and reassemble."""
    blocks = [[f(M[r, c]) for c in _offsets(cols)] for r in _offsets(rows)]
    dtype = np.result_type(*[b for row in blocks for b in row])
    nr = [row[0].shape[0] for row in blocks]
    nc = [b.shape[1] for b in blocks[0]]
    out = np.zeros((sum(nr), sum(nc)), dtype=dtype)
    for rs, row in zip(_offsets(nr), blocks):
        for cs, b in zip(_offsets(nc), row):
            out[rs, cs] = b
    return out


def _plant_sizes(p: LFTPlant) -> tuple[list[int], list[int]]:
    return [p.n_x, p.n_zu, p.n_zp, p.n_y], [p.n_x, p.n_wu, p.n_wp, p.n_u]


def lft_real_form(plant: LFTPlant) -> LFTPlant:
    """Real form of a complex LFT plant: (3.45) on every block, every channel becomes [Re; Im] (3.46).

    A real parameter block Δ of the complex plant corresponds to real_form(Δ) (= blockdiag(Δ, Δ))
    for the real plant; a complex Δ to its real form as well.
    """
    rows, cols = _plant_sizes(plant)
    M = _map_grid(plant.M, rows, cols, real_form)
    return LFTPlant(M, *(2 * k for k in rows), *(2 * k for k in cols[1:]), dt=plant.dt)


def lft_t_c(plant: LFTPlant, *, check: bool = True) -> LFTPlant:
    """T_C on every block of a plant whose blocks are all complex-formed (Sec. 5.5.4)."""
    rows, cols = _plant_sizes(plant)
    if any(k % 2 for k in rows + cols):
        raise ValueError(f"every channel of a complex-formed plant has even size, got {rows} / {cols}")
    M = _map_grid(plant.M, rows, cols, lambda b: t_c(b, check=check))
    return LFTPlant(M, *(k // 2 for k in rows), *(k // 2 for k in cols[1:]), dt=plant.dt)


def _ctrl_sizes(k: LFTController) -> tuple[list[int], list[int]]:
    return [k.n_c, k.n_u, k.n_zc], [k.n_c, k.n_y, k.n_wc]


def controller_real_form(K: LFTController) -> LFTController:
    """Real form of a complex controller, e.g. A_c -> [[Re A_c, −Im A_c], [Im A_c, Re A_c]] (Sec. 5.5.4)."""
    rows, cols = _ctrl_sizes(K)
    M = _map_grid(K.M, rows, cols, real_form)
    d = {k: 2 * getattr(K, k) for k in ("n_c", "n_u", "n_zc", "n_y", "n_wc")}
    return dataclasses.replace(K, M=M, **d)


def controller_t_c(K: LFTController, *, check: bool = True) -> LFTController:
    """T_C on every block of a controller whose blocks are all complex-formed (Sec. 5.5.4)."""
    rows, cols = _ctrl_sizes(K)
    if any(k % 2 for k in rows + cols):
        raise ValueError(f"every channel of a complex-formed controller has even size, got {rows} / {cols}")
    M = _map_grid(K.M, rows, cols, lambda b: t_c(b, check=check))
    h = {k: getattr(K, k) // 2 for k in ("n_c", "n_u", "n_zc", "n_y", "n_wc")}
    return dataclasses.replace(K, M=M, **h)
