"""Linear fractional transformations, the Redheffer star product and LFT plants (thesis Sec. 2.4, 5.2-5.3).

Conventions (thesis Sec. 2.4, Fig. 2.1/2.2):

- A `Partitioned` matrix M = [[M11, M12], [M21, M22]] maps [w1; w2] -> [e1; e2]. The *first* (upper)
  channel is (w1 -> e1), the *second* (lower) channel is (w2 -> e2).
- ``A ⋆ B`` (`star`) closes A's second channel with B's first channel; the result keeps A's first and
  B's second channel. ``F_l(M, Δ)`` closes M's second channel with Δ, ``F_u(M, Δ)`` its first channel.
- Every interconnection checks well-posedness (Def. 2.19, 2.20): each loop matrix I − X that must be
  inverted is tested by (1 + ‖X‖)/σ_min(I − X) <= cond_max (default `COND_MAX`), and an
  `IllPosedError` (a `ValueError`) is raised when it is singular or too badly conditioned.

State-space LFT plants follow the thesis' LPV form (5.11)/(5.55), with its names:

    [ ẋ  ]   [ A    B_u   B_p   B   ] [ x   ]
    [ z_u] = [ C_u  D_uu  D_up  E_u ] [ w_u ]      w_u = Δ z_u   (or [w_u; z_u] ∈ im [S1(Δ); S2(Δ)], (5.12))
    [ z_p]   [ C_p  D_pu  D_pp  E_p ] [ w_p ]
    [ y  ]   [ C    F_u   F_p   F_3 ] [ u   ]

i.e. subscript ``u`` is the *parameter* (uncertainty) channel w_u/z_u, ``p`` is the *performance*
channel w_p/z_p, and B/E/C/F belong to the control input u and measurement y. F_3 is the u -> y
feedthrough; synthesis needs F_3 = 0, which `remove_feedthrough` achieves by the Γ transformation of
Example 2.22. Controllers follow (5.13)/(5.57):

    [ẋ_c]   [ A_c   B_c1   B_c2  ] [x_c]
    [ u  ] = [ C_c1  D_c11  D_c12 ] [ y ]      w_c = Δ_c z_c  (or the subspace form (5.14))
    [z_c]   [ C_c2  D_c21  D_c22 ] [w_c]

Everything works for real or complex matrices (the thesis' complex-formed motor models are complex).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "COND_MAX",
    "IllPosedError",
    "Partitioned",
    "lft_lower",
    "lft_upper",
    "lft_lower_subspace",
    "star",
    "star_identity",
    "StateSpace",
    "LFTPlant",
    "LFTController",
    "closed_loop",
    "gamma",
    "gamma_inverse",
    "remove_feedthrough",
    "restore_feedthrough",
]

#: Default threshold: a loop matrix I − X that must be inverted for an interconnection is treated as
#: singular (the interconnection as ill-posed) when (1 + ‖X‖₂) / σ_min(I − X) exceeds this.
COND_MAX: float = 1e10


class IllPosedError(ValueError):
    """An LFT / star product / parameter closure is not well-posed (Def. 2.19, 2.20)."""


# --------------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------------
def _as_matrix(x: ArrayLike, name: str = "matrix") -> np.ndarray:
    """A 2-D float or complex array (integers and booleans become float)."""
    a = np.asarray(x)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    if a.ndim != 2:
        raise ValueError(f"{name} must be 2-D, got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.complexfloating):
        a = a.astype(float)
    return a


def _loop_matrix(X: np.ndarray, what: str, cond_max: float) -> np.ndarray:
    """Return L = I − X after checking that it is safely invertible, else raise IllPosedError.

    The measure is (1 + ‖X‖) / σ_min(I − X): for a small loop gain it is cond(I − X); it also
    catches I − X ≈ 0 from cancellation (cond(I − X) alone is scale-invariant and would not).
    """
    n = X.shape[0]
    L = np.eye(n) - X
    if n == 0:
        return L
    if not np.all(np.isfinite(L)):
        raise IllPosedError(f"not well-posed: {what} contains non-finite entries")
    sv = np.linalg.svd(L, compute_uv=False)
    kappa = np.inf if sv[-1] == 0.0 else (1.0 + np.linalg.norm(X, 2)) / sv[-1]
    if not kappa <= cond_max:
        raise IllPosedError(
            f"not well-posed: {what} is singular or ill-conditioned "
            f"((1 + |X|)/sigma_min = {kappa:.3g} > {cond_max:.3g})"
        )
    return L


def _check_full_row_rank(G: np.ndarray, scale: float, what: str, cond_max: float) -> None:
    """Raise IllPosedError unless G (wide or square) has numerically full row rank relative to scale."""
    if G.shape[0] == 0:
        return
    if G.shape[1] < G.shape[0]:
        raise IllPosedError(f"not well-posed: {what} has fewer columns than rows ({G.shape})")
    sv = np.linalg.svd(G, compute_uv=False)
    scale = max(scale, sv[0])
    if not np.isfinite(scale) or scale == 0.0 or sv[-1] < scale / cond_max:
        raise IllPosedError(
            f"not well-posed: {what} is (numerically) row-rank deficient "
            f"(singular values {sv[-1]:.3g} ... {sv[0]:.3g})"
        )


def _assemble(rows: Sequence[Sequence[np.ndarray]]) -> np.ndarray:
    """np.block that also copes with zero-sized blocks (all blocks must have consistent shapes)."""
    dtype = np.result_type(*[b for r in rows for b in r])
    n_rows = [r[0].shape[0] for r in rows]
    n_cols = [b.shape[1] for b in rows[0]]
    out = np.zeros((sum(n_rows), sum(n_cols)), dtype=dtype)
    r0 = 0
    for i, r in enumerate(rows):
        c0 = 0
        for j, b in enumerate(r):
            if b.shape != (n_rows[i], n_cols[j]):
                raise ValueError(f"block ({i},{j}) has shape {b.shape}, expected {(n_rows[i], n_cols[j])}")
            out[r0 : r0 + n_rows[i], c0 : c0 + n_cols[j]] = b
            c0 += n_cols[j]
        r0 += n_rows[i]
    return out


def _offsets(sizes: Sequence[int]) -> list[slice]:
    out, k = [], 0
    for s in sizes:
        out.append(slice(k, k + s))
        k += s
    return out


# --------------------------------------------------------------------------------------------------
# partitioned constant matrices
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Partitioned:
    """M = [[M11, M12], [M21, M22]] mapping [w1; w2] -> [e1; e2]; M11 is ``n_out1 x n_in1``.

    Any block may be of zero size (Remark 2.21).
    """

    M: np.ndarray
    n_out1: int
    n_in1: int

    def __post_init__(self) -> None:
        M = _as_matrix(self.M, "M")
        object.__setattr__(self, "M", M)
        if not (0 <= self.n_out1 <= M.shape[0] and 0 <= self.n_in1 <= M.shape[1]):
            raise ValueError(f"partition ({self.n_out1}, {self.n_in1}) does not fit a {M.shape} matrix")

    @classmethod
    def from_blocks(cls, M11: ArrayLike, M12: ArrayLike, M21: ArrayLike, M22: ArrayLike) -> "Partitioned":
        b = [_as_matrix(x, n) for x, n in zip((M11, M12, M21, M22), ("M11", "M12", "M21", "M22"))]
        return cls(_assemble([[b[0], b[1]], [b[2], b[3]]]), b[0].shape[0], b[0].shape[1])

    @classmethod
    def single(cls, K: ArrayLike) -> "Partitioned":
        """K as a partitioned matrix whose second channel is empty (e.g. a Δ block to star with)."""
        K = _as_matrix(K, "K")
        return cls(K, K.shape[0], K.shape[1])

    @property
    def n_out2(self) -> int:
        return self.M.shape[0] - self.n_out1

    @property
    def n_in2(self) -> int:
        return self.M.shape[1] - self.n_in1

    @property
    def M11(self) -> np.ndarray:
        return self.M[: self.n_out1, : self.n_in1]

    @property
    def M12(self) -> np.ndarray:
        return self.M[: self.n_out1, self.n_in1 :]

    @property
    def M21(self) -> np.ndarray:
        return self.M[self.n_out1 :, : self.n_in1]

    @property
    def M22(self) -> np.ndarray:
        return self.M[self.n_out1 :, self.n_in1 :]

    def __repr__(self) -> str:
        return (
            f"Partitioned(shape={self.M.shape}, first=({self.n_out1}x{self.n_in1}), "
            f"second=({self.n_out2}x{self.n_in2}), dtype={self.M.dtype})"
        )


def _as_partitioned(M: Partitioned | ArrayLike, n_out2: int, n_in2: int, role: str) -> Partitioned:
    """M as Partitioned whose *second* channel is (n_in2 -> n_out2); checks a given partition."""
    if isinstance(M, Partitioned):
        if (M.n_out2, M.n_in2) != (n_out2, n_in2):
            raise ValueError(
                f"{role}: M's second channel is {M.n_out2}x{M.n_in2}, expected {n_out2}x{n_in2}"
            )
        return M
    Ma = _as_matrix(M, "M")
    if Ma.shape[0] < n_out2 or Ma.shape[1] < n_in2:
        raise ValueError(f"{role}: M of shape {Ma.shape} is too small for a {n_out2}x{n_in2} block")
    return Partitioned(Ma, Ma.shape[0] - n_out2, Ma.shape[1] - n_in2)


def lft_lower(M: Partitioned | ArrayLike, Delta: ArrayLike, *, cond_max: float = COND_MAX) -> np.ndarray:
    """Lower LFT F_l(M, Δ) = M11 + M12 Δ (I − M22 Δ)^{-1} M21 (Sec. 2.4, Def. 2.19).

    If M is a plain array its partition follows from Δ's shape: Δ is p x q, so M22 is q x p.
    Raises IllPosedError if I − M22 Δ is singular (cond > cond_max).
    """
    D = _as_matrix(Delta, "Delta")
    P = _as_partitioned(M, D.shape[1], D.shape[0], "lft_lower")
    L = _loop_matrix(P.M22 @ D, "I - M22 Δ", cond_max)
    return P.M11 + P.M12 @ D @ np.linalg.solve(L, P.M21)


def lft_upper(M: Partitioned | ArrayLike, Delta: ArrayLike, *, cond_max: float = COND_MAX) -> np.ndarray:
    """Upper LFT F_u(M, Δ) = M22 + M21 Δ (I − M11 Δ)^{-1} M12 (Sec. 2.4, Def. 2.19).

    If M is a plain array its partition follows from Δ's shape: Δ is p x q, so M11 is q x p.
    Raises IllPosedError if I − M11 Δ is singular (cond > cond_max).
    """
    D = _as_matrix(Delta, "Delta")
    if isinstance(M, Partitioned):
        P = M
        if (P.n_out1, P.n_in1) != (D.shape[1], D.shape[0]):
            raise ValueError(f"lft_upper: M11 is {P.n_out1}x{P.n_in1}, Δ is {D.shape}")
    else:
        P = Partitioned(_as_matrix(M, "M"), D.shape[1], D.shape[0])
    L = _loop_matrix(P.M11 @ D, "I - M11 Δ", cond_max)
    return P.M22 + P.M21 @ D @ np.linalg.solve(L, P.M12)


def lft_lower_subspace(
    M: Partitioned | ArrayLike, S1: ArrayLike, S2: ArrayLike, *, cond_max: float = COND_MAX
) -> np.ndarray:
    """Close M's second channel with [w2; e2] ∈ im [S1; S2] (5.12): the general form of Lemma 5.5 / (5.8), (5.64).

    Returns M11 + M12 S1 [S2 − M22 S1]^† M21. With S1 = Δ, S2 = I this is F_l(M, Δ); S1 = Δ T,
    S2 = T (T invertible) describes the same subspace and gives the same result.
    Well-posedness (Sec. 5.2.2): im S has dimension n_out2 and S2 − M22 S1 has full row rank.
    """
    S1a, S2a = _as_matrix(S1, "S1"), _as_matrix(S2, "S2")
    if S1a.shape[1] != S2a.shape[1]:
        raise ValueError(f"S1 {S1a.shape} and S2 {S2a.shape} must have the same number of columns")
    P = _as_partitioned(M, S2a.shape[0], S1a.shape[0], "lft_lower_subspace")
    S = np.vstack([S1a, S2a])
    if S.size:
        rank = np.linalg.matrix_rank(S)
        if rank != P.n_out2:
            raise IllPosedError(f"not well-posed: dim im S = {rank}, must equal dim z = {P.n_out2}")
    M22S1 = P.M22 @ S1a
    G = S2a - M22S1
    scale = max(np.linalg.norm(S2a, 2), np.linalg.norm(M22S1, 2)) if G.size else 0.0
    _check_full_row_rank(G, scale, "S2 - M22 S1", cond_max)
    return P.M11 + P.M12 @ S1a @ np.linalg.pinv(G) @ P.M21


def star(A: Partitioned, B: Partitioned, *, cond_max: float = COND_MAX) -> Partitioned:
    """Redheffer star product A ⋆ B (Sec. 2.4, Fig. 2.2).

        A ⋆ B = [[F_l(A, B11),                     A12 (I − B11 A22)^{-1} B12],
                 [B21 (I − A22 B11)^{-1} A21,     F_u(B, A22)               ]]

    A's second channel is closed with B's first channel: B11 must be A.n_in2 x A.n_out2.
    The result has A's first channel and B's second channel. Raises IllPosedError unless
    I − B11 A22 and I − A22 B11 are invertible (Def. 2.20).
    """
    if (B.n_out1, B.n_in1) != (A.n_in2, A.n_out2):
        raise ValueError(
            f"star: B11 is {B.n_out1}x{B.n_in1} but A22 is {A.n_out2}x{A.n_in2}; "
            f"B11 must be {A.n_in2}x{A.n_out2}"
        )
    A11, A12, A21, A22 = A.M11, A.M12, A.M21, A.M22
    B11, B12, B21, B22 = B.M11, B.M12, B.M21, B.M22
    L = _loop_matrix(A22 @ B11, "I - A22 B11", cond_max)
    R = _loop_matrix(B11 @ A22, "I - B11 A22", cond_max)
    LA21 = np.linalg.solve(L, A21)
    RB12 = np.linalg.solve(R, B12)
    M = _assemble(
        [
            [A11 + A12 @ B11 @ LA21, A12 @ RB12],
            [B21 @ LA21, B22 + B21 @ A22 @ RB12],
        ]
    )
    return Partitioned(M, A.n_out1, A.n_in1)


def star_identity(n_out1: int, n_in1: int, dtype: type = float) -> Partitioned:
    """The star-product unit [[0, I], [I, 0]] (Sec. 2.4) with first channel n_in1 -> n_out1.

    e1 = w2 and e2 = w1, so the block is [[0_{n_out1 x n_in1}, I_{n_out1}], [I_{n_in1}, 0]].
    ``A ⋆ star_identity(A.n_in2, A.n_out2)`` is A; ``star_identity(B.n_out1, B.n_in1) ⋆ B`` is B.
    """
    M = np.zeros((n_out1 + n_in1, n_in1 + n_out1), dtype=dtype)
    M[:n_out1, n_in1:] = np.eye(n_out1)
    M[n_out1:, :n_in1] = np.eye(n_in1)
    return Partitioned(M, n_out1, n_in1)


# --------------------------------------------------------------------------------------------------
# LTI state space
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StateSpace:
    """ẋ = A x + B u, y = C x + D u (dt is None), or x_{k+1} = A x_k + B u_k, y_k = C x_k + D u_k (dt = T_s)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float | None = None

    def __post_init__(self) -> None:
        A, B, C, D = (_as_matrix(x, n) for x, n in zip((self.A, self.B, self.C, self.D), "ABCD"))
        n = A.shape[0]
        if A.shape != (n, n) or B.shape[0] != n or C.shape[1] != n or D.shape != (C.shape[0], B.shape[1]):
            raise ValueError(f"inconsistent shapes A{A.shape} B{B.shape} C{C.shape} D{D.shape}")
        for k, v in zip("ABCD", (A, B, C, D)):
            object.__setattr__(self, k, v)

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[0]

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    def evaluate(self, s: complex) -> np.ndarray:
        """Transfer matrix at the complex point s (or z): C (sI − A)^{-1} B + D."""
        n = self.n_states
        return self.D + self.C @ np.linalg.solve(s * np.eye(n) - self.A, self.B.astype(complex))

    def freqresp(self, omega: ArrayLike) -> np.ndarray:
        """Frequency response, shape (len(omega), p, m), at s = jω or z = exp(jω T_s)."""
        w = np.atleast_1d(np.asarray(omega, dtype=float))
        pts = np.exp(1j * w * self.dt) if self.is_discrete else 1j * w
        return np.stack([self.evaluate(p) for p in pts])

    def poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.A)

    def transform(self, T: ArrayLike) -> "StateSpace":
        """The same system in the state x_new = T x (3.38): (T A T^{-1}, T B, C T^{-1}, D)."""
        T = _as_matrix(T, "T")
        Ti = np.linalg.inv(T)
        return StateSpace(T @ self.A @ Ti, T @ self.B, self.C @ Ti, self.D, self.dt)

    def to_partitioned(self) -> Partitioned:
        """[[A, B], [C, D]] with the state as first channel, ready for D_bl ⋆ · or F_u(·, I/s)."""
        return Partitioned(_assemble([[self.A, self.B], [self.C, self.D]]), self.n_states, self.n_states)

    @classmethod
    def from_partitioned(cls, P: Partitioned, dt: float | None = None) -> "StateSpace":
        if P.n_out1 != P.n_in1:
            raise ValueError("the first (state) channel of a state-space matrix must be square")
        return cls(P.M11, P.M12, P.M21, P.M22, dt)


# --------------------------------------------------------------------------------------------------
# LPV plants in LFT form (5.11)
# --------------------------------------------------------------------------------------------------
_PLANT_NAMES = (
    ("A", "B_u", "B_p", "B"),
    ("C_u", "D_uu", "D_up", "E_u"),
    ("C_p", "D_pu", "D_pp", "E_p"),
    ("C", "F_u", "F_p", "F_3"),
)
_PLANT_INDEX = {name: (i, j) for i, row in enumerate(_PLANT_NAMES) for j, name in enumerate(row)}


def _grid_from_blocks(
    names: Sequence[Sequence[str]], given: dict[str, ArrayLike | None], fixed: dict[int, int] | None = None
) -> tuple[np.ndarray, list[int], list[int]]:
    """Assemble a block grid from named blocks; missing blocks are zero, sizes inferred and checked."""
    nr, nc = len(names), len(names[0])
    rows: list[int | None] = [None] * nr
    cols: list[int | None] = [None] * nc
    blocks: dict[tuple[int, int], np.ndarray] = {}
    for i in range(nr):
        for j in range(nc):
            v = given.get(names[i][j])
            if v is None:
                continue
            b = _as_matrix(v, names[i][j])
            blocks[(i, j)] = b
            for sizes, k, n, what in ((rows, i, b.shape[0], "rows"), (cols, j, b.shape[1], "columns")):
                if sizes[k] is None:
                    sizes[k] = n
                elif sizes[k] != n:
                    raise ValueError(f"{names[i][j]} has {n} {what}, other blocks in its {what[:-1]} say {sizes[k]}")
    r = [0 if s is None else s for s in rows]
    c = [0 if s is None else s for s in cols]
    dtype = np.result_type(float, *blocks.values())
    grid = [[blocks.get((i, j), np.zeros((r[i], c[j]), dtype=dtype)) for j in range(nc)] for i in range(nr)]
    return _assemble(grid), r, c


def _plant_block(i: int, j: int, doc: str) -> property:
    def get(self: "LFTPlant") -> np.ndarray:
        return self.M[self._rows[i], self._cols[j]]

    return property(get, doc=doc)


@dataclass(frozen=True, eq=False)
class LFTPlant:
    """LPV plant in LFT form (5.11) (continuous, dt None) or (5.55) (discrete, dt = T_s).

    M is the whole system matrix, rows [ẋ; z_u; z_p; y], columns [x; w_u; w_p; u]. The parameter
    block closes w_u = Δ z_u with Δ of shape n_wu x n_zu (`at`), or more generally (5.12) (`at_subspace`).
    Build one with `LFTPlant.from_blocks(A=..., B_u=..., ...)`.
    """

    M: np.ndarray
    n_x: int
    n_zu: int
    n_zp: int
    n_y: int
    n_wu: int
    n_wp: int
    n_u: int
    dt: float | None = None

    def __post_init__(self) -> None:
        M = _as_matrix(self.M, "M")
        object.__setattr__(self, "M", M)
        exp = (self.n_x + self.n_zu + self.n_zp + self.n_y, self.n_x + self.n_wu + self.n_wp + self.n_u)
        if M.shape != exp:
            raise ValueError(f"M has shape {M.shape}, the channel sizes need {exp}")

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def from_blocks(
        cls,
        A: ArrayLike,
        *,
        B_u: ArrayLike | None = None,
        B_p: ArrayLike | None = None,
        B: ArrayLike | None = None,
        C_u: ArrayLike | None = None,
        D_uu: ArrayLike | None = None,
        D_up: ArrayLike | None = None,
        E_u: ArrayLike | None = None,
        C_p: ArrayLike | None = None,
        D_pu: ArrayLike | None = None,
        D_pp: ArrayLike | None = None,
        E_p: ArrayLike | None = None,
        C: ArrayLike | None = None,
        F_u: ArrayLike | None = None,
        F_p: ArrayLike | None = None,
        F_3: ArrayLike | None = None,
        dt: float | None = None,
    ) -> "LFTPlant":
        """Plant (5.11) from named blocks; omitted blocks are zero, channel sizes are inferred.

        A channel whose size cannot be inferred from any given block is empty.
        """
        given = dict(
            A=A, B_u=B_u, B_p=B_p, B=B, C_u=C_u, D_uu=D_uu, D_up=D_up, E_u=E_u,
            C_p=C_p, D_pu=D_pu, D_pp=D_pp, E_p=E_p, C=C, F_u=F_u, F_p=F_p, F_3=F_3,
        )  # fmt: skip
        M, r, c = _grid_from_blocks(_PLANT_NAMES, given)
        if r[0] != c[0]:
            raise ValueError(f"A must be square, got {r[0]}x{c[0]}")
        return cls(M, r[0], r[1], r[2], r[3], c[1], c[2], c[3], dt)

    # -- block access ------------------------------------------------------------------------------
    @property
    def _rows(self) -> list[slice]:
        return _offsets((self.n_x, self.n_zu, self.n_zp, self.n_y))

    @property
    def _cols(self) -> list[slice]:
        return _offsets((self.n_x, self.n_wu, self.n_wp, self.n_u))

    A = _plant_block(0, 0, "state matrix")
    B_u = _plant_block(0, 1, "parameter input w_u -> ẋ")
    B_p = _plant_block(0, 2, "performance input w_p -> ẋ")
    B = _plant_block(0, 3, "control input u -> ẋ")
    C_u = _plant_block(1, 0, "x -> parameter output z_u")
    D_uu = _plant_block(1, 1, "w_u -> z_u")
    D_up = _plant_block(1, 2, "w_p -> z_u")
    E_u = _plant_block(1, 3, "u -> z_u")
    C_p = _plant_block(2, 0, "x -> performance output z_p")
    D_pu = _plant_block(2, 1, "w_u -> z_p")
    D_pp = _plant_block(2, 2, "w_p -> z_p")
    E_p = _plant_block(2, 3, "u -> z_p")
    C = _plant_block(3, 0, "x -> measurement y")
    F_u = _plant_block(3, 1, "w_u -> y")
    F_p = _plant_block(3, 2, "w_p -> y")
    F_3 = _plant_block(3, 3, "u -> y feedthrough (must be 0 for synthesis, Remark 5.7)")

    def block(self, name: str) -> np.ndarray:
        """A block by its thesis name, e.g. ``plant.block('D_uu')``."""
        i, j = _PLANT_INDEX[name]
        return self.M[self._rows[i], self._cols[j]]

    @property
    def is_continuous(self) -> bool:
        return self.dt is None

    def with_matrix(self, M: ArrayLike) -> "LFTPlant":
        """A plant with the same channel sizes and dt and a new system matrix."""
        return dataclasses.replace(self, M=M)

    # -- partitions used by the star products ----------------------------------------------------
    def state_partition(self) -> Partitioned:
        """First channel x -> ẋ (the integrator / D_bl side), second [w_u; w_p; u] -> [z_u; z_p; y]."""
        return Partitioned(self.M, self.n_x, self.n_x)

    def _param_perm(self) -> tuple[np.ndarray, np.ndarray]:
        r, c = self._rows, self._cols
        ar, ac = np.arange(self.M.shape[0]), np.arange(self.M.shape[1])
        rp = np.concatenate([ar[r[0]], ar[r[2]], ar[r[3]], ar[r[1]]])
        cp = np.concatenate([ac[c[0]], ac[c[2]], ac[c[3]], ac[c[1]]])
        return rp, cp

    def parameter_partition(self) -> Partitioned:
        """Rows [ẋ; z_p; y | z_u], columns [x; w_p; u | w_u]: the form (5.48) that is closed by ⋆ Δ."""
        rp, cp = self._param_perm()
        return Partitioned(self.M[np.ix_(rp, cp)], self.n_x + self.n_zp + self.n_y, self.n_x + self.n_wp + self.n_u)

    def control_partition(self) -> Partitioned:
        """Rows [ẋ; z_u; z_p | y], columns [x; w_u; w_p | u]: the form M_s of Example 2.22, closed by ⋆ K."""
        return Partitioned(self.M, self.n_x + self.n_zu + self.n_zp, self.n_x + self.n_wu + self.n_wp)

    # -- closing the parameter block ---------------------------------------------------------------
    def _frozen(self, F: np.ndarray) -> "LFTPlant":
        return LFTPlant(F, self.n_x, 0, self.n_zp, self.n_y, 0, self.n_wp, self.n_u, self.dt)

    def at(self, Delta: ArrayLike, *, cond_max: float = COND_MAX) -> "LFTPlant":
        """The LTI plant for the frozen parameter block: (5.48) ``M ⋆ Δ`` with w_u = Δ z_u.

        Δ is n_wu x n_zu (a scalar is accepted for 1x1). The result has no parameter channel.
        Raises IllPosedError if I − D_uu Δ is singular.
        """
        D = _as_matrix(Delta, "Delta")
        if D.shape != (self.n_wu, self.n_zu):
            raise ValueError(f"Δ must be {self.n_wu}x{self.n_zu}, got {D.shape}")
        return self._frozen(lft_lower(self.parameter_partition(), D, cond_max=cond_max))

    def at_subspace(self, S1: ArrayLike, S2: ArrayLike, *, cond_max: float = COND_MAX) -> "LFTPlant":
        """The LTI plant for [w_u; z_u] ∈ im [S1; S2] (5.12), by the formula of Lemma 5.5 (5.8)."""
        return self._frozen(lft_lower_subspace(self.parameter_partition(), S1, S2, cond_max=cond_max))

    def to_state_space(self) -> StateSpace:
        """Inputs [w_p; u], outputs [z_p; y]; only for a plant without parameter channel (see `at`)."""
        if self.n_zu or self.n_wu:
            raise ValueError("plant still has a parameter channel; close it first with .at(Delta)")
        return StateSpace.from_partitioned(self.state_partition(), self.dt)

    def frozen(self, Delta: ArrayLike, *, cond_max: float = COND_MAX) -> StateSpace:
        """Shorthand for ``self.at(Delta).to_state_space()``."""
        return self.at(Delta, cond_max=cond_max).to_state_space()

    def __repr__(self) -> str:
        t = "continuous" if self.dt is None else f"discrete dt={self.dt:g}"
        return (
            f"LFTPlant(n_x={self.n_x}, z_u/w_u={self.n_zu}/{self.n_wu}, z_p/w_p={self.n_zp}/{self.n_wp}, "
            f"y/u={self.n_y}/{self.n_u}, {t}, dtype={self.M.dtype})"
        )


# --------------------------------------------------------------------------------------------------
# LPV controllers in LFT form (5.13)
# --------------------------------------------------------------------------------------------------
_CTRL_NAMES = (
    ("A_c", "B_c1", "B_c2"),
    ("C_c1", "D_c11", "D_c12"),
    ("C_c2", "D_c21", "D_c22"),
)


def _ctrl_block(i: int, j: int) -> property:
    def get(self: "LFTController") -> np.ndarray:
        return self.M[self._rows[i], self._cols[j]]

    return property(get, doc=_CTRL_NAMES[i][j])


@dataclass(frozen=True, eq=False)
class LFTController:
    """LPV controller (5.13)/(5.57): rows [ẋ_c; u; z_c], columns [x_c; y; w_c]; w_c = Δ_c z_c."""

    M: np.ndarray
    n_c: int
    n_u: int
    n_zc: int
    n_y: int
    n_wc: int
    dt: float | None = None

    def __post_init__(self) -> None:
        M = _as_matrix(self.M, "M")
        object.__setattr__(self, "M", M)
        exp = (self.n_c + self.n_u + self.n_zc, self.n_c + self.n_y + self.n_wc)
        if M.shape != exp:
            raise ValueError(f"M has shape {M.shape}, the channel sizes need {exp}")

    @classmethod
    def from_blocks(
        cls,
        A_c: ArrayLike | None = None,
        *,
        B_c1: ArrayLike | None = None,
        B_c2: ArrayLike | None = None,
        C_c1: ArrayLike | None = None,
        D_c11: ArrayLike | None = None,
        D_c12: ArrayLike | None = None,
        C_c2: ArrayLike | None = None,
        D_c21: ArrayLike | None = None,
        D_c22: ArrayLike | None = None,
        dt: float | None = None,
    ) -> "LFTController":
        """Controller (5.13) from named blocks; omitted blocks are zero (A_c may be omitted for a static gain)."""
        given = dict(A_c=A_c, B_c1=B_c1, B_c2=B_c2, C_c1=C_c1, D_c11=D_c11, D_c12=D_c12,
                     C_c2=C_c2, D_c21=D_c21, D_c22=D_c22)  # fmt: skip
        M, r, c = _grid_from_blocks(_CTRL_NAMES, given)
        if r[0] != c[0]:
            raise ValueError(f"A_c must be square, got {r[0]}x{c[0]}")
        return cls(M, r[0], r[1], r[2], c[1], c[2], dt)

    @property
    def _rows(self) -> list[slice]:
        return _offsets((self.n_c, self.n_u, self.n_zc))

    @property
    def _cols(self) -> list[slice]:
        return _offsets((self.n_c, self.n_y, self.n_wc))

    A_c = _ctrl_block(0, 0)
    B_c1 = _ctrl_block(0, 1)
    B_c2 = _ctrl_block(0, 2)
    C_c1 = _ctrl_block(1, 0)
    D_c11 = _ctrl_block(1, 1)
    D_c12 = _ctrl_block(1, 2)
    C_c2 = _ctrl_block(2, 0)
    D_c21 = _ctrl_block(2, 1)
    D_c22 = _ctrl_block(2, 2)

    def _perm(self) -> tuple[np.ndarray, np.ndarray]:
        r, c = self._rows, self._cols
        ar, ac = np.arange(self.M.shape[0]), np.arange(self.M.shape[1])
        return (
            np.concatenate([ar[r[1]], ar[r[0]], ar[r[2]]]),
            np.concatenate([ac[c[1]], ac[c[0]], ac[c[2]]]),
        )

    def plant_partition(self) -> Partitioned:
        """K̃_c of Example 2.22: rows [u | ẋ_c; z_c], columns [y | x_c; w_c]; first channel y -> u."""
        rp, cp = self._perm()
        return Partitioned(self.M[np.ix_(rp, cp)], self.n_u, self.n_y)

    @classmethod
    def from_plant_partition(
        cls, K: Partitioned, n_c: int, n_zc: int, n_wc: int, dt: float | None = None
    ) -> "LFTController":
        """Inverse of `plant_partition`: back from rows [u; ẋ_c; z_c] x columns [y; x_c; w_c] to (5.13)."""
        n_u, n_y = K.n_out1, K.n_in1
        if K.M.shape != (n_u + n_c + n_zc, n_y + n_c + n_wc):
            raise ValueError(f"K has shape {K.M.shape}, inconsistent with n_c={n_c}, n_zc={n_zc}, n_wc={n_wc}")
        rp = np.r_[n_u : n_u + n_c, 0:n_u, n_u + n_c : n_u + n_c + n_zc]
        cp = np.r_[n_y : n_y + n_c, 0:n_y, n_y + n_c : n_y + n_c + n_wc]
        return cls(K.M[np.ix_(rp, cp)], n_c, n_u, n_zc, n_y, n_wc, dt)

    def at(self, Delta_c: ArrayLike, *, cond_max: float = COND_MAX) -> StateSpace:
        """Frozen controller (5.63) for w_c = Δ_c z_c: states x_c, input y, output u."""
        D = _as_matrix(Delta_c, "Delta_c")
        if D.shape != (self.n_wc, self.n_zc):
            raise ValueError(f"Δ_c must be {self.n_wc}x{self.n_zc}, got {D.shape}")
        P = Partitioned(self.M, self.n_c + self.n_u, self.n_c + self.n_y)
        return StateSpace.from_partitioned(Partitioned(lft_lower(P, D, cond_max=cond_max), self.n_c, self.n_c), self.dt)

    def at_subspace(self, S_c1: ArrayLike, S_c2: ArrayLike, *, cond_max: float = COND_MAX) -> StateSpace:
        """Frozen controller (5.63)-(5.64) for [w_c; z_c] ∈ im [S_c1; S_c2] (5.14)."""
        P = Partitioned(self.M, self.n_c + self.n_u, self.n_c + self.n_y)
        F = lft_lower_subspace(P, S_c1, S_c2, cond_max=cond_max)
        return StateSpace.from_partitioned(Partitioned(F, self.n_c, self.n_c), self.dt)


def closed_loop(plant: LFTPlant, controller: LFTController, *, cond_max: float = COND_MAX) -> LFTPlant:
    """Closed loop M_c = M_s ⋆ K_c (Example 2.22, Sec. 5.3.1) as an LFT plant of the form (5.6).

    The result has state ξ = [x; x_c], parameter channel [z_u; z_c] / [w_u; w_c] (close it with
    blockdiag(Δ, Δ_c)), performance channel z_p / w_p, and no control channel. Well-posed iff
    I − F_3 D_c11 is invertible.
    """
    if plant.dt != controller.dt:
        raise ValueError(f"plant dt={plant.dt} and controller dt={controller.dt} differ")
    if (controller.n_y, controller.n_u) != (plant.n_y, plant.n_u):
        raise ValueError(
            f"controller maps {controller.n_y} measurements to {controller.n_u} inputs; "
            f"plant has n_y={plant.n_y}, n_u={plant.n_u}"
        )
    Mc = star(plant.control_partition(), controller.plant_partition(), cond_max=cond_max).M
    # Mc rows [ẋ; z_u; z_p; ẋ_c; z_c], columns [x; w_u; w_p; x_c; w_c]  ->  (5.6) order
    nx, nzu, nzp, nc, nzc = plant.n_x, plant.n_zu, plant.n_zp, controller.n_c, controller.n_zc
    nwu, nwp, nwc = plant.n_wu, plant.n_wp, controller.n_wc
    r = _offsets((nx, nzu, nzp, nc, nzc))
    c = _offsets((nx, nwu, nwp, nc, nwc))
    ar, ac = np.arange(Mc.shape[0]), np.arange(Mc.shape[1])
    rp = np.concatenate([ar[r[0]], ar[r[3]], ar[r[1]], ar[r[4]], ar[r[2]]])
    cp = np.concatenate([ac[c[0]], ac[c[3]], ac[c[1]], ac[c[4]], ac[c[2]]])
    return LFTPlant(Mc[np.ix_(rp, cp)], nx + nc, nzu + nzc, nzp, 0, nwu + nwc, nwp, 0, plant.dt)


# --------------------------------------------------------------------------------------------------
# The Γ transformation (Example 2.22, Remark 5.28)
# --------------------------------------------------------------------------------------------------
def gamma(F_3: ArrayLike) -> Partitioned:
    """Γ = [[0, I], [I, −F_3]] (Example 2.22): first channel y -> u, second u' -> y' = y − F_3 u'."""
    F = _as_matrix(F_3, "F_3")
    n_y, n_u = F.shape
    return Partitioned.from_blocks(np.zeros((n_u, n_y)), np.eye(n_u), np.eye(n_y), -F)


def gamma_inverse(F_3: ArrayLike) -> Partitioned:
    """Γ^{-⋆} = [[0, I], [I, F_3]] (Example 2.22); Γ ⋆ Γ^{-⋆} = Γ^{-⋆} ⋆ Γ = star identity."""
    F = _as_matrix(F_3, "F_3")
    n_y, n_u = F.shape
    return Partitioned.from_blocks(np.zeros((n_u, n_y)), np.eye(n_u), np.eye(n_y), F)


def remove_feedthrough(plant: LFTPlant, *, cond_max: float = COND_MAX) -> tuple[LFTPlant, np.ndarray]:
    """M_p = M_s ⋆ Γ (Example 2.22): the same plant with F_3 = 0, and the removed F_3.

    Design a controller K̃ for the returned plant, then use ``restore_feedthrough(K̃, F_3)``.
    """
    F3 = plant.F_3.copy()
    Mp = star(plant.control_partition(), gamma(F3), cond_max=cond_max)
    return plant.with_matrix(Mp.M), F3


def restore_feedthrough(K_tilde: LFTController, F_3: ArrayLike, *, cond_max: float = COND_MAX) -> LFTController:
    """K_c = Γ ⋆ K̃_c (2.20): a controller for the plant with feedthrough F_3.

    M_s ⋆ K_c = M_p ⋆ K̃_c. Requires I + D̃_c11 F_3 invertible (the thesis writes I + F_3 K̃_c),
    else IllPosedError. Also implements Remark 5.28 / (5.72) with F_3 = M22.
    """
    Kc = star(gamma(F_3), K_tilde.plant_partition(), cond_max=cond_max)
    return LFTController.from_plant_partition(Kc, K_tilde.n_c, K_tilde.n_zc, K_tilde.n_wc, K_tilde.dt)
