"""Induction-motor current model and the LPV flux-observer problem in LFT form (thesis 3.3, 4.3.1, 5.6.1).

The complex current model (3.41)/(5.77) with state x_sc = [ī_s; ī_m] and the speed ω_r as a
time-varying parameter:

    ẋ_sc = A_sc(ω_r) x_sc + B_sc ū_s,   A_sc(ω_r) = A_0 + ω_r A_wr,   A_wr = A_1 A_2^*.

`flux_observer_plant` builds the LFT (5.79)/(5.80) with Δ = ω_r/ω_r,max (a real scalar in
[-1, 1]) and the observer-as-control setup of Fig. 5.4:

    w_p = [ū_s; w_i; w_u],  z_p = u − ī_m  (E_p = 1, see the errata in INDEX.md),
    y   = [ī_s + σ_i w_i; ū_s + σ_u w_u],   u = î_m (the controller output is the estimate).

`flux_observer_plant_discrete` discretises it with the bilinear D_bl ⋆ M of Sec. 5.4.1, either the
whole plant (default, ``variant="full"``: every output is formed from the trapezoidal state, which
is what `synthesis.discretize.bilinear_lft` does), or -- as the thesis writes after Fig. 5.4 -- only
the part (5.79)/(5.80) (``variant="partial"``), after which C_p, C, F_p are applied to the discrete
state x_k as in continuous time.

The Jansen-Lorenz observer of Sec. 4.3.1 is `jl_observer` (inputs [ī_s; ū_s], output ī_m; the
thesis prints "d/dt ī_m" for the output line, which is an erratum: it is the estimate).

Nothing here imports `bench` or `mock_hw`; motor data are duplicated from (3.57) on purpose.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from synthesis.discretize import bilinear_lft, d_bl
from synthesis.lft import LFTPlant, StateSpace, star, Partitioned
from synthesis.models.referred import ReferredQuantities

__all__ = [
    "MotorData",
    "a_sc",
    "b_sc",
    "flux_observer_plant",
    "flux_observer_plant_discrete",
    "jl_observer",
    "TS_LAB",
]

#: The lab's sampling period, 3 kHz (App. A).
TS_LAB: float = 1.0 / 3000.0


@dataclass(frozen=True)
class MotorData(ReferredQuantities):
    """Electrical motor parameters [H, Ω]; defaults are the lab motor (3.57) at 20 °C."""

    L_s: float = 0.352
    L_r: float = 0.352
    L_m: float = 0.341
    R_s: float = 5.0
    R_r: float = 3.3

    def __post_init__(self) -> None:
        if not self.L_m**2 < self.L_s * self.L_r:
            raise ValueError("need L_m^2 < L_s L_r (positive leakage)")

    # referred parameters of thesis Sec. 4.1 (Ls_p, Lm_p, Rr_p, T_r, sigma): `ReferredQuantities`

    def replace(self, **kw: float) -> "MotorData":
        return dataclasses.replace(self, **kw)

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


def a_sc(omega_r: float, m: MotorData = MotorData()) -> np.ndarray:
    """A_sc(ω_r) of (3.41)/(5.77), complex 2x2, state [ī_s; ī_m]."""
    den = m.L_r * (m.L_m**2 - m.L_s * m.L_r)
    return np.array(
        [
            [(m.L_m**2 * m.R_r + m.R_s * m.L_r**2) / den, m.L_m**2 * (1j * m.L_r * omega_r - m.R_r) / den],
            [m.R_r / m.L_r, 1j * omega_r - m.R_r / m.L_r],
        ],
        dtype=complex,
    )


def b_sc(m: MotorData = MotorData()) -> np.ndarray:
    """B_sc of (3.41)/(5.77), complex 2x1."""
    return np.array([[m.L_r / (m.L_s * m.L_r - m.L_m**2)], [0.0]], dtype=complex)


def _a_factors(m: MotorData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A_0, A_1, A_2^* with A_sc = A_0 + ω_r A_1 A_2^* (5.79): A_wr has rank one (column 2 only)."""
    A0 = a_sc(0.0, m)
    A_wr = a_sc(1.0, m) - A0
    A1 = A_wr[:, [1]]
    A2h = np.array([[0.0, 1.0]], dtype=complex)
    assert np.allclose(A1 @ A2h, A_wr)
    return A0, A1, A2h


def flux_observer_plant(
    omega_r_max: float = 200.0,
    sigma_i: float = 1e-4,
    sigma_u: float = 1e-4,
    m: MotorData = MotorData(),
) -> LFTPlant:
    """Continuous complex LFT plant (5.79)/(5.80) + Fig. 5.4 (E_p = 1); Δ = ω_r/ω_r,max ∈ [−1, 1].

    Channels: x = [ī_s; ī_m], w_u/z_u scalar, w_p = [ū_s; w_i; w_u], z_p = u − ī_m,
    y = [ī_s + σ_i w_i; ū_s + σ_u w_u], u = î_m.
    """
    A0, A1, A2h = _a_factors(m)
    r = math.sqrt(omega_r_max)
    return LFTPlant.from_blocks(
        A0,
        B_u=r * A1,  # (5.79)
        B_p=np.hstack([b_sc(m), np.zeros((2, 2))]),
        B=np.zeros((2, 1)),
        C_u=r * A2h,  # (5.80)
        D_uu=np.zeros((1, 1)),
        D_up=np.zeros((1, 3)),
        E_u=np.zeros((1, 1)),
        C_p=np.array([[0.0, -1.0]]),
        D_pu=np.zeros((1, 1)),
        D_pp=np.zeros((1, 3)),
        E_p=np.ones((1, 1)),  # errata: z_p = u − ī_m needs E_p = 1
        C=np.array([[1.0, 0.0], [0.0, 0.0]]),
        F_u=np.zeros((2, 1)),
        F_p=np.array([[0.0, sigma_i, 0.0], [1.0, 0.0, sigma_u]]),
        F_3=np.zeros((2, 1)),
    )


def flux_observer_plant_discrete(
    omega_r_max: float = 200.0,
    sigma_i: float = 1e-4,
    sigma_u: float = 1e-4,
    Ts: float = TS_LAB,
    m: MotorData = MotorData(),
    *,
    variant: str = "full",
    balanced: bool = True,
) -> LFTPlant:
    """The flux-observer plant discretised by D_bl (Sec. 5.4.1, 5.6.1), closed by the same Δ.

    ``variant="full"``: D_bl ⋆ M of the whole plant (`bilinear_lft`). ``variant="partial"``: only
    [[A, B_u, B_p], [C_u, D_uu, D_up]] goes through D_bl (the thesis' "discretisation was only
    performed on the part of the model specified by (5.79)"), then C_p = [0 −1], C = [[1, 0], [0, 0]],
    F_p, E_p = 1 act on the discrete state x_k (= ξ_k/√T_s with the balanced D_bl).
    """
    Pc = flux_observer_plant(omega_r_max, sigma_i, sigma_u, m)
    if variant == "full":
        return bilinear_lft(Pc, Ts, balanced=balanced)
    if variant != "partial":
        raise ValueError(f"variant must be 'full' or 'partial', got {variant!r}")
    # state part [[A, B_u, B_p], [C_u, D_uu, D_up]] through D_bl
    top = np.block([[Pc.A, Pc.B_u, Pc.B_p], [Pc.C_u, Pc.D_uu, Pc.D_up]])

    S = star(d_bl(Pc.n_x, Ts, balanced=balanced), Partitioned(top, Pc.n_x, Pc.n_x))
    n, nu = Pc.n_x, Pc.n_zu
    Md = S.M
    return LFTPlant.from_blocks(
        Md[:n, :n],
        B_u=Md[:n, n : n + nu],
        B_p=Md[:n, n + nu :],
        B=Pc.B,
        C_u=Md[n:, :n],
        D_uu=Md[n:, n : n + nu],
        D_up=Md[n:, n + nu :],
        E_u=Pc.E_u,
        C_p=Pc.C_p,
        D_pu=Pc.D_pu,
        D_pp=Pc.D_pp,
        E_p=Pc.E_p,
        C=Pc.C,
        F_u=Pc.F_u,
        F_p=Pc.F_p,
        F_3=Pc.F_3,
        dt=Ts,
    )


def jl_observer(omega_r: float, K1: complex, K2: complex, m: MotorData = MotorData()) -> StateSpace:
    """Jansen-Lorenz observer (Sec. 4.3.1): continuous complex, inputs y_m = [ī_s; ū_s], output ī_m estimate.

    State x_jl = [Ψ̂_s; g; Ψ̂_rc]. K1 = 10000, K2 = 0 is practically the current model (4.15) (5.6.2).
    """
    Ls, Lr, Lm, Rs, Rr = m.L_s, m.L_r, m.L_m, m.R_s, m.R_r
    A = np.array(
        [
            [-K1 * Lr / Lm, K2, K1],
            [-Lr / Lm, 0.0, 1.0],
            [0.0, 0.0, -Rr / Lr + 1j * omega_r],
        ],
        dtype=complex,
    )
    B = np.array(
        [
            [K1 * Lr * Ls / Lm - K1 * Lm - Rs, 1.0],
            [Lr * Ls / Lm - Lm, 0.0],
            [Lm * Rr / Lr, 0.0],
        ],
        dtype=complex,
    )
    C = np.array([[Lr / Lm**2, 0.0, 0.0]], dtype=complex)
    D = np.array([[1.0 - Lr * Ls / Lm**2, 0.0]], dtype=complex)
    return StateSpace(A, B, C, D)
