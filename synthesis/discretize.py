"""Bilinear (Tustin) discretisation as a Redheffer star product with D_bl (thesis Sec. 5.4.1).

The continuous system [ẋ; y] = [[A, B], [C, D]] [x; u] is the upper LFT of its system matrix with
the integrator 1/s. The thesis replaces that integrator by the trapezoidal rule, written as the
constant partitioned matrix

    D_bl = [[I, √T_s I], [√T_s I, (T_s/2) I]],      [x_{k+1}; y_k] = (D_bl ⋆ [[A, B], [C, D]]) [x_k; u_k].

For an LPV plant in LFT form, associativity of the star product gives (5.48)

    D_bl ⋆ (M ⋆ Δ) = (D_bl ⋆ M) ⋆ Δ,

so the discrete plant D_bl ⋆ M is computed once and is closed by the SAME parameter block Δ
(frozen over each sample, Δ_k = Δ(k T_s)). For every frozen Δ the result is exactly the Tustin
discretisation of the frozen continuous plant.

Realisation. With ξ_k ≜ √T_s x_k the balanced D_bl gives

    ξ_{k+1} = ξ_k + T_s v_k,   r_k = ξ_k + (T_s/2) v_k = (ξ_k + ξ_{k+1})/2,
    v_k = A r_k + B u_k,       y_k = C r_k + D u_k,

i.e. ξ is the trapezoidal-rule state and the thesis' discrete state is x_k = ξ_k/√T_s (the √T_s
split balances B and C). ``balanced=False`` uses D_bl' = [[I, T_s I], [I, (T_s/2) I]] instead, whose
state is ξ_k itself and whose matrices equal scipy's ``cont2discrete(..., method='bilinear')``.
Both have the same transfer function.

Prewarping (not used in the thesis): Tustin with prewarp frequency ω_p is Tustin with
T' = (2/ω_p) tan(ω_p T_s/2) in place of T_s inside D_bl; the discrete system keeps dt = T_s.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from synthesis.lft import COND_MAX, LFTPlant, Partitioned, StateSpace, star

__all__ = ["d_bl", "bilinear_lti", "bilinear_lft", "tustin_period"]


def tustin_period(Ts: float, prewarp: float | None = None) -> float:
    """The period used inside D_bl: T_s, or (2/ω_p) tan(ω_p T_s/2) with prewarping at ω_p [rad/s]."""
    if not (Ts > 0 and math.isfinite(Ts)):
        raise ValueError(f"sampling period must be positive and finite, got {Ts!r}")
    if prewarp is None:
        return Ts
    if not (0 < prewarp < math.pi / Ts):
        raise ValueError(f"prewarp frequency must lie in (0, π/T_s) = (0, {math.pi / Ts:g}) rad/s, got {prewarp!r}")
    return 2.0 / prewarp * math.tan(prewarp * Ts / 2.0)


def d_bl(n: int, Ts: float, *, balanced: bool = True, prewarp: float | None = None) -> Partitioned:
    """D_bl = [[I, √T I], [√T I, (T/2) I]] of Sec. 5.4.1 (n = number of states), both channels n x n.

    ``balanced=False`` gives [[I, T I], [I, (T/2) I]] (state = trapezoidal state ξ, scipy's realisation).
    """
    T = tustin_period(Ts, prewarp)
    I = np.eye(n)
    g, h = (math.sqrt(T), math.sqrt(T)) if balanced else (T, 1.0)
    return Partitioned.from_blocks(I, g * I, h * I, (T / 2.0) * I)


def bilinear_lti(
    sys: StateSpace,
    Ts: float,
    *,
    balanced: bool = True,
    prewarp: float | None = None,
    cond_max: float = COND_MAX,
) -> StateSpace:
    """Tustin discretisation of an LTI state space: D_bl ⋆ [[A, B], [C, D]] (Sec. 5.4.1).

    Raises IllPosedError if I − (T_s/2) A is singular (A has an eigenvalue at 2/T_s).
    """
    if sys.is_discrete:
        raise ValueError("system is already discrete-time")
    P = star(d_bl(sys.n_states, Ts, balanced=balanced, prewarp=prewarp), sys.to_partitioned(), cond_max=cond_max)
    return StateSpace.from_partitioned(P, Ts)


def bilinear_lft(
    plant: LFTPlant,
    Ts: float,
    *,
    balanced: bool = True,
    prewarp: float | None = None,
    cond_max: float = COND_MAX,
) -> LFTPlant:
    """Discretise an LFT plant (5.11) into (5.55): D_bl ⋆ M with the state as D_bl's channel (5.48).

    All channel sizes are kept, and the discrete plant is closed by the same Δ (frozen over a sample).
    Note that D_uu, D_pp, F_3, ... generally become non-zero in discrete time (e.g. D_uu,d =
    D_uu + (T_s/2) C_u (I − (T_s/2) A)^{-1} B_u), so re-check well-posedness of ⋆ Δ and, if F_3 ≠ 0,
    use `synthesis.lft.remove_feedthrough` before synthesis.
    """
    if not plant.is_continuous:
        raise ValueError("plant is already discrete-time")
    P = star(d_bl(plant.n_x, Ts, balanced=balanced, prewarp=prewarp), plant.state_partition(), cond_max=cond_max)
    return dataclasses.replace(plant, M=P.M, dt=Ts)
