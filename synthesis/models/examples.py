"""Small test and benchmark problems for the synthesis library (no thesis model).

- `random_diagonal_lpv`: a random real discrete LPV plant (5.55) with a diagonal parameter block
  Δ = diag(δ_1, ..., δ_k), |δ_i| ≤ 1, the setting of Thm 7.1 (robust LPV with uncertain scheduling).
  One control input, one measurement, performance z_p = [C_p x; 0.3 u], disturbances w_p = [process;
  sensor noise]. `gu` sets the strength of the parameter channel (‖B_u‖, ‖C_u‖ scale with it).
"""

from __future__ import annotations

import numpy as np

from synthesis.lft import LFTPlant

__all__ = ["random_diagonal_lpv"]


def random_diagonal_lpv(seed: int, *, n_x: int = 3, k: int = 2, gu: float = 0.4, d_uu: float = 0.1,
                        dt: float = 0.1) -> LFTPlant:
    """A reproducible random plant: A scaled to spectral radius 0.9, Gaussian blocks, F_3 = 0."""
    rng = np.random.default_rng(seed)

    def r(m: int, n: int, s: float = 1.0) -> np.ndarray:
        return s * rng.standard_normal((m, n))

    A = r(n_x, n_x)
    A = 0.9 * A / max(abs(np.linalg.eigvals(A)))
    return LFTPlant.from_blocks(
        A, B_u=r(n_x, k, gu), B_p=np.hstack([r(n_x, 1), np.zeros((n_x, 1))]), B=r(n_x, 1),
        C_u=r(k, n_x, gu), D_uu=r(k, k, d_uu), D_up=np.zeros((k, 2)), E_u=r(k, 1, 0.3),
        C_p=np.vstack([r(1, n_x), np.zeros((1, n_x))]), D_pu=np.zeros((2, k)), D_pp=np.zeros((2, 2)),
        E_p=np.array([[0.0], [0.3]]), C=r(1, n_x), F_u=r(1, k, 0.2), F_p=np.array([[0.0, 1.0]]), dt=dt,
    )  # fmt: skip
