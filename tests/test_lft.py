"""Tests for synthesis.lft: LFTs, the Redheffer star product, LFT plants/controllers and Γ (thesis 2.4, 5.3)."""

from __future__ import annotations

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import block_diag

from synthesis.lft import (
    IllPosedError,
    LFTController,
    LFTPlant,
    Partitioned,
    StateSpace,
    closed_loop,
    gamma,
    gamma_inverse,
    lft_lower,
    lft_lower_subspace,
    lft_upper,
    remove_feedthrough,
    restore_feedthrough,
    star,
    star_identity,
)
from synthesis.models.motor import flux_observer_plant

# Motor data (3.57)
L_s, L_r, L_m, R_s, R_r = 0.352, 0.352, 0.341, 5.0, 3.3
W_MAX = 200.0  # ω_r,max used to scale Δ = ω_r/ω_r,max (5.6.1)


def rand(rng: np.random.Generator, m: int, n: int, cplx: bool = False, scale: float = 1.0) -> np.ndarray:
    X = rng.standard_normal((m, n))
    if cplx:
        X = X + 1j * rng.standard_normal((m, n))
    return scale * X


def rand_part(rng, o1, i1, o2, i2, cplx=False, scale=1.0) -> Partitioned:
    return Partitioned(rand(rng, o1 + o2, i1 + i2, cplx, scale), o1, i1)


def small(rng, m, n, cplx=False):
    """A random matrix of 2-norm 0.7 (so products of two are contractions: always well-posed)."""
    X = rand(rng, m, n, cplx)
    nrm = np.linalg.norm(X, 2) if X.size else 1.0
    return 0.7 * X / max(nrm, 1e-12)


# -------------------------------------------------------------------------------------------------
# motor current model (3.41)/(5.77), hand-built from the thesis formulas
# -------------------------------------------------------------------------------------------------
def A_sc(w_r: float) -> np.ndarray:
    """(3.41)/(5.77), typed from the thesis."""
    den = L_r * (L_m**2 - L_s * L_r)
    return np.array(
        [
            [(L_m**2 * R_r + R_s * L_r**2) / den, L_m**2 * (1j * L_r * w_r - R_r) / den],
            [R_r / L_r, 1j * w_r - R_r / L_r],
        ]
    )


B_SC = np.array([[L_r / (L_s * L_r - L_m**2)], [0.0]])


def motor_lft(sigma_i: float = 1e-4, sigma_u: float = 1e-4) -> LFTPlant:
    """The flux-observer LFT (5.79)-(5.80) with E_p = 1 (INDEX errata); complex, Δ = ω_r/ω_r,max.

    Built by `synthesis.models.motor.flux_observer_plant` (moved there from this file); the test below
    compares it with the hand-typed A_sc / B_SC above.
    """
    return flux_observer_plant(W_MAX, sigma_i, sigma_u)


# -------------------------------------------------------------------------------------------------
# star product algebra
# -------------------------------------------------------------------------------------------------
dims = st.integers(min_value=0, max_value=3)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), o1=dims, i1=dims, o2=dims, i2=dims, cplx=st.booleans())
def test_star_identity_is_unit(seed, o1, i1, o2, i2, cplx):
    rng = np.random.default_rng(seed)
    A = rand_part(rng, o1, i1, o2, i2, cplx)
    right = star(A, star_identity(A.n_in2, A.n_out2))
    left = star(star_identity(A.n_out1, A.n_in1), A)
    for R in (right, left):
        assert (R.n_out1, R.n_in1) == (A.n_out1, A.n_in1)
        np.testing.assert_array_equal(R.M, A.M)


def test_star_identity_square_is_thesis_matrix():
    J = star_identity(2, 2)
    np.testing.assert_array_equal(J.M, np.block([[np.zeros((2, 2)), np.eye(2)], [np.eye(2), np.zeros((2, 2))]]))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), d=st.lists(st.integers(0, 3), min_size=6, max_size=6), cplx=st.booleans())
def test_star_associative(seed, d, cplx):
    rng = np.random.default_rng(seed)
    a1o, a1i, ab_o, ab_i, bc_o, bc_i = d  # ab_o: A's e2 = B's w1, ab_i: B's e1 = A's w2, ...
    c2o, c2i = rng.integers(0, 3, size=2)

    # A22 and C11 are contractions (norm 0.7)
    A = Partitioned.from_blocks(
        rand(rng, a1o, a1i, cplx), rand(rng, a1o, ab_i, cplx), rand(rng, ab_o, a1i, cplx), small(rng, ab_o, ab_i, cplx)
    )
    # B entirely small: then F_u(B, A22) and F_l(B, C11) have norm < 1.37 and every loop gain < 0.96
    B = Partitioned.from_blocks(
        small(rng, ab_i, ab_o, cplx),
        small(rng, ab_i, bc_i, cplx),
        small(rng, bc_o, ab_o, cplx),
        small(rng, bc_o, bc_i, cplx),
    )
    C = Partitioned.from_blocks(
        small(rng, bc_i, bc_o, cplx), rand(rng, bc_i, c2i, cplx), rand(rng, c2o, bc_o, cplx), rand(rng, c2o, c2i, cplx)
    )
    lhs = star(star(A, B), C)
    rhs = star(A, star(B, C))
    assert (lhs.n_out1, lhs.n_in1) == (rhs.n_out1, rhs.n_in1) == (A.n_out1, A.n_in1)
    np.testing.assert_allclose(lhs.M, rhs.M, rtol=1e-9, atol=1e-9)


def test_star_matches_signal_level_interconnection():
    """Solve the loop of Fig. 2.2 as one linear system and compare with the closed formula."""
    rng = np.random.default_rng(1)
    A = rand_part(rng, 2, 3, 2, 4, cplx=True)
    B = rand_part(rng, 4, 2, 3, 1, cplx=True)
    w1, w2 = rand(rng, 3, 1, True), rand(rng, 1, 1, True)
    # unknowns: a (A's e2, 2), b (B's e1, 4):  a = A21 w1 + A22 b,  b = B11 a + B12 w2
    K = np.block([[np.eye(2), -A.M22], [-B.M11, np.eye(4)]])
    ab = np.linalg.solve(K, np.vstack([A.M21 @ w1, B.M12 @ w2]))
    a, b = ab[:2], ab[2:]
    e1 = A.M11 @ w1 + A.M12 @ b
    e2 = B.M21 @ a + B.M22 @ w2
    S = star(A, B)
    np.testing.assert_allclose(S.M @ np.vstack([w1, w2]), np.vstack([e1, e2]), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("cplx", [False, True])
def test_lft_lower_and_upper_match_definitions_and_star(cplx):
    rng = np.random.default_rng(2)
    M = rand(rng, 5, 6, cplx)  # M22 is 2x3 for a 3x2 Δ
    D = rand(rng, 3, 2, cplx, 0.3)
    M11, M12, M21, M22 = M[:3, :3], M[:3, 3:], M[3:, :3], M[3:, 3:]
    direct = M11 + M12 @ D @ np.linalg.inv(np.eye(2) - M22 @ D) @ M21
    np.testing.assert_allclose(lft_lower(M, D), direct, rtol=1e-12)
    # F_l via the star product with a Δ whose second channel is empty
    via_star = star(Partitioned(M, 3, 3), Partitioned.single(D))
    assert via_star.M.shape == direct.shape
    np.testing.assert_allclose(via_star.M, direct, rtol=1e-12)
    # F_u(M, Δu) = M22 + M21 Δu (I - M11 Δu)^{-1} M12 with M11 3x2 for a 2x3 Δu
    Du = rand(rng, 2, 3, cplx, 0.3)
    N11, N12, N21, N22 = M[:3, :2], M[:3, 2:], M[3:, :2], M[3:, 2:]
    direct_u = N22 + N21 @ Du @ np.linalg.inv(np.eye(3) - N11 @ Du) @ N12
    np.testing.assert_allclose(lft_upper(M, Du), direct_u, rtol=1e-12)
    # Remark 2.21: with e1, w1 empty, A ⋆ B = F_u(B, A22)
    via_star_u = star(Partitioned(Du, 0, 0), Partitioned(M, 3, 2))
    np.testing.assert_allclose(via_star_u.M, direct_u, rtol=1e-12)


def test_partition_mismatch_raises():
    rng = np.random.default_rng(3)
    A = rand_part(rng, 1, 1, 2, 3)
    with pytest.raises(ValueError, match="B11 must be 3x2"):
        star(A, rand_part(rng, 2, 2, 1, 1))
    with pytest.raises(ValueError, match="second channel"):
        lft_lower(A, np.zeros((2, 3)))  # Δ 2x3 needs M22 3x2, A22 is 2x3


def test_lft_lower_ill_posed_raises():
    rng = np.random.default_rng(4)
    D = rand(rng, 2, 2) + 2 * np.eye(2)
    M = rand(rng, 4, 4)
    M[2:, 2:] = np.linalg.inv(D)  # I - M22 Δ = 0
    with pytest.raises(IllPosedError, match="not well-posed"):
        lft_lower(M, D)
    with pytest.raises(ValueError):  # IllPosedError is a ValueError
        lft_lower(M, D)
    # nearly singular: beyond the condition threshold
    M[2:, 2:] = np.linalg.inv(D) * (1 - 1e-13)
    with pytest.raises(IllPosedError):
        lft_lower(M, D)
    # ... but accepted with a looser threshold, and a well-conditioned perturbation is fine
    lft_lower(M, D, cond_max=1e16)
    M[2:, 2:] = 0.5 * np.linalg.inv(D)
    np.testing.assert_allclose(
        lft_lower(M, D), M[:2, :2] + M[:2, 2:] @ D @ np.linalg.inv(np.eye(2) - M[2:, 2:] @ D) @ M[2:, :2]
    )
    # upper LFT likewise
    N = rand(rng, 4, 4)
    N[:2, :2] = np.linalg.inv(D)
    with pytest.raises(IllPosedError):
        lft_upper(N, D)


def test_star_ill_posed_raises():
    rng = np.random.default_rng(5)
    A = rand_part(rng, 2, 2, 2, 2)
    Bm = rand(rng, 4, 4)
    Bm[:2, :2] = np.linalg.inv(A.M22)  # B11 A22 = I
    with pytest.raises(IllPosedError, match="I - A22 B11|I - B11 A22"):
        star(A, Partitioned(Bm, 2, 2))


def test_lft_lower_subspace():
    rng = np.random.default_rng(6)
    M = rand(rng, 5, 5, cplx=True)  # M22 2x2
    D = rand(rng, 2, 2, cplx=True, scale=0.3)
    T = rand(rng, 2, 2) + 3 * np.eye(2)
    ref = lft_lower(M, D)
    # same subspace in another basis: im [Δ T; T] = im [Δ; I]
    np.testing.assert_allclose(lft_lower_subspace(M, D @ T, T), ref, rtol=1e-10)
    # and im [I; Δ^{-1}]
    np.testing.assert_allclose(lft_lower_subspace(M, np.eye(2), np.linalg.inv(D)), ref, rtol=1e-9)
    # the limit Δ -> ∞ (S2 = 0): M11 − M12 M22^{-1} M21, approached by lft_lower with a huge Δ
    lim = M[:3, :3] - M[:3, 3:] @ np.linalg.inv(M[3:, 3:]) @ M[3:, :3]
    np.testing.assert_allclose(lft_lower_subspace(M, np.eye(2), np.zeros((2, 2))), lim, rtol=1e-10)
    np.testing.assert_allclose(lft_lower(M, 1e7 * np.eye(2)), lim, rtol=1e-5)
    # ill-posed: S2 − M22 S1 singular
    M2 = M.copy()
    M2[3:, 3:] = np.linalg.inv(D)
    with pytest.raises(IllPosedError):
        lft_lower_subspace(M2, D, np.eye(2))
    # dim im S must equal dim z
    with pytest.raises(IllPosedError, match="dim im S"):
        lft_lower_subspace(M, np.zeros((2, 1)), np.ones((2, 1)))


# -------------------------------------------------------------------------------------------------
# LFT plants
# -------------------------------------------------------------------------------------------------
def test_plant_from_blocks_roundtrip_and_validation():
    rng = np.random.default_rng(7)
    blocks = dict(
        A=rand(rng, 3, 3), B_u=rand(rng, 3, 2), B_p=rand(rng, 3, 1), B=rand(rng, 3, 2),
        C_u=rand(rng, 1, 3), D_uu=rand(rng, 1, 2), D_up=rand(rng, 1, 1), E_u=rand(rng, 1, 2),
        C_p=rand(rng, 2, 3), D_pu=rand(rng, 2, 2), D_pp=rand(rng, 2, 1), E_p=rand(rng, 2, 2),
        C=rand(rng, 4, 3), F_u=rand(rng, 4, 2), F_p=rand(rng, 4, 1), F_3=rand(rng, 4, 2),
    )  # fmt: skip
    P = LFTPlant.from_blocks(**blocks)
    assert (P.n_x, P.n_zu, P.n_zp, P.n_y, P.n_wu, P.n_wp, P.n_u) == (3, 1, 2, 4, 2, 1, 2)
    for name, val in blocks.items():
        np.testing.assert_array_equal(getattr(P, name), val)
        np.testing.assert_array_equal(P.block(name), val)
    # omitted blocks are zero, sizes inferred from the others
    Q = LFTPlant.from_blocks(blocks["A"], B_u=blocks["B_u"], C=blocks["C"])
    assert (Q.n_zu, Q.n_wu, Q.n_y, Q.n_u) == (0, 2, 4, 0)
    assert Q.F_u.shape == (4, 2) and not Q.F_u.any()
    with pytest.raises(ValueError, match="B_u"):
        LFTPlant.from_blocks(blocks["A"], B_u=rand(rng, 2, 2))
    with pytest.raises(ValueError, match="square"):
        LFTPlant.from_blocks(rand(rng, 3, 2))


@pytest.mark.parametrize("w_r", [-200.0, -37.5, 0.0, 120.0, 297.4])
def test_motor_lft_frozen_equals_hand_built(w_r):
    """Closing Δ = ω_r/ω_r,max on the LFT (5.79)-(5.80) gives A_sc(ω_r) of (5.77) and the setup of 5.6.1."""
    P = motor_lft(sigma_i=1e-4, sigma_u=2e-4)
    G = P.frozen(np.array([[w_r / W_MAX]]))
    np.testing.assert_allclose(G.A, A_sc(w_r), rtol=1e-12, atol=1e-9)
    # inputs [u_s, w_i, w_u | u], outputs [z_p | y1, y2]
    B_ref = np.hstack([B_SC, np.zeros((2, 3))])
    C_ref = np.array([[0, -1], [1, 0], [0, 0]])
    D_ref = np.array([[0, 0, 0, 1], [0, 1e-4, 0, 0], [1, 0, 2e-4, 0]])
    np.testing.assert_allclose(G.B, B_ref, atol=1e-12)
    np.testing.assert_allclose(G.C, C_ref, atol=1e-12)
    np.testing.assert_allclose(G.D, D_ref, atol=1e-12)
    # the parameter actually matters: ω_r enters A
    if w_r != 0:
        assert not np.allclose(G.A, P.frozen(np.zeros((1, 1))).A)


def test_plant_at_validates_delta_and_well_posedness():
    rng = np.random.default_rng(8)
    P = LFTPlant.from_blocks(rand(rng, 2, 2), B_u=rand(rng, 2, 1), C_u=rand(rng, 1, 2), D_uu=[[0.5]])
    with pytest.raises(ValueError, match="1x1"):
        P.at(np.eye(2))
    with pytest.raises(IllPosedError):
        P.at([[2.0]])  # 1 - D_uu Δ = 0
    with pytest.raises(ValueError, match="parameter channel"):
        P.to_state_space()
    # hand-built frozen A: A + B_u Δ (1 - D_uu Δ)^{-1} C_u
    d = 0.7
    np.testing.assert_allclose(P.frozen([[d]]).A, P.A + P.B_u * d / (1 - 0.5 * d) @ P.C_u, rtol=1e-12)
    # the subspace form (5.12) with S = [Δ; 1] gives the same
    np.testing.assert_allclose(P.at_subspace([[d]], [[1.0]]).M, P.at([[d]]).M, rtol=1e-12)


# -------------------------------------------------------------------------------------------------
# controllers, closed loop, Γ transformation (Example 2.22)
# -------------------------------------------------------------------------------------------------
def random_plant(rng, F3: bool = True, dt=None) -> LFTPlant:
    n_x, n_zu, n_wu, n_zp, n_wp, n_y, n_u = 3, 2, 2, 2, 2, 2, 1
    P = LFTPlant.from_blocks(
        rand(rng, n_x, n_x) - 2 * np.eye(n_x),
        B_u=rand(rng, n_x, n_wu), B_p=rand(rng, n_x, n_wp), B=rand(rng, n_x, n_u),
        C_u=rand(rng, n_zu, n_x), D_uu=0.3 * rand(rng, n_zu, n_wu),
        D_up=rand(rng, n_zu, n_wp), E_u=rand(rng, n_zu, n_u),
        C_p=rand(rng, n_zp, n_x), D_pu=rand(rng, n_zp, n_wu), D_pp=rand(rng, n_zp, n_wp), E_p=rand(rng, n_zp, n_u),
        C=rand(rng, n_y, n_x), F_u=rand(rng, n_y, n_wu), F_p=rand(rng, n_y, n_wp),
        F_3=0.5 * rand(rng, n_y, n_u) if F3 else np.zeros((n_y, n_u)), dt=dt,
    )  # fmt: skip
    return P


def random_controller(rng, dt=None) -> LFTController:
    return LFTController.from_blocks(
        rand(rng, 2, 2) - 2 * np.eye(2), B_c1=rand(rng, 2, 2), B_c2=rand(rng, 2, 1),
        C_c1=rand(rng, 1, 2), D_c11=0.3 * rand(rng, 1, 2), D_c12=rand(rng, 1, 1),
        C_c2=rand(rng, 1, 2), D_c21=rand(rng, 1, 2), D_c22=[[0.2]], dt=dt,
    )  # fmt: skip


def test_controller_partition_roundtrip_and_frozen():
    rng = np.random.default_rng(9)
    K = random_controller(rng)
    Kp = K.plant_partition()
    assert (Kp.n_out1, Kp.n_in1) == (1, 2)
    np.testing.assert_array_equal(Kp.M11, K.D_c11)
    back = LFTController.from_plant_partition(Kp, K.n_c, K.n_zc, K.n_wc)
    np.testing.assert_array_equal(back.M, K.M)
    # (5.63)/(5.64) by hand
    d = 0.8
    g = d / (1 - 0.2 * d)
    F = K.at([[d]])
    np.testing.assert_allclose(F.A, K.A_c + K.B_c2 * g @ K.C_c2, rtol=1e-12)
    np.testing.assert_allclose(F.B, K.B_c1 + K.B_c2 * g @ K.D_c21, rtol=1e-12)
    np.testing.assert_allclose(F.C, K.C_c1 + K.D_c12 * g @ K.C_c2, rtol=1e-12)
    np.testing.assert_allclose(F.D, K.D_c11 + K.D_c12 * g @ K.D_c21, rtol=1e-12)
    np.testing.assert_allclose(K.at_subspace([[2 * d]], [[2.0]]).A, F.A, rtol=1e-12)


def _ctrl_ss(S: StateSpace) -> control.StateSpace:
    return control.ss(S.A, S.B, S.C, S.D)


def test_closed_loop_matches_python_control_lft():
    """Frozen closed loop from closed_loop(...).at(blockdiag(Δ, Δc)) vs python-control's StateSpace.lft."""
    rng = np.random.default_rng(10)
    P, K = random_plant(rng), random_controller(rng)
    Delta, Delta_c = 0.4 * rand(rng, 2, 2), np.array([[0.6]])
    CL = closed_loop(P, K)
    assert (CL.n_x, CL.n_zu, CL.n_wu, CL.n_y, CL.n_u) == (5, 3, 3, 0, 0)
    ours = CL.frozen(block_diag(Delta, Delta_c))
    ref = _ctrl_ss(P.frozen(Delta)).lft(_ctrl_ss(K.at(Delta_c)), nu=1, ny=2)
    for s in (0.3j, 2.0 + 1.0j, -0.5 + 7j, 40j):
        np.testing.assert_allclose(ours.evaluate(s), ref(s), rtol=1e-9, atol=1e-12)


def test_gamma_inverse_and_remove_feedthrough():
    rng = np.random.default_rng(11)
    F3 = rand(rng, 2, 1)
    I_star = star_identity(1, 2)
    for X in (star(gamma(F3), gamma_inverse(F3)), star(gamma_inverse(F3), gamma(F3))):
        np.testing.assert_allclose(X.M, I_star.M, atol=1e-14)
    P = random_plant(rng)
    Pp, F3_removed = remove_feedthrough(P)
    np.testing.assert_array_equal(F3_removed, P.F_3)
    assert not np.any(Pp.F_3)
    # M_p differs from M_s only in F_3 (Example 2.22)
    mask = np.ones_like(P.M, dtype=bool)
    mask[P.n_x + P.n_zu + P.n_zp :, P.n_x + P.n_wu + P.n_wp :] = False
    np.testing.assert_allclose(Pp.M[mask], P.M[mask], rtol=1e-14)


def test_restore_feedthrough_gives_same_closed_loop():
    """M_s ⋆ (Γ ⋆ K̃) = M_p ⋆ K̃ (2.20), checked via star products and via python-control."""
    rng = np.random.default_rng(12)
    P = random_plant(rng)
    Pp, F3 = remove_feedthrough(P)
    Kt = random_controller(rng)
    K = restore_feedthrough(Kt, F3)
    assert (K.n_c, K.n_u, K.n_y, K.n_zc, K.n_wc) == (Kt.n_c, Kt.n_u, Kt.n_y, Kt.n_zc, Kt.n_wc)
    np.testing.assert_allclose(closed_loop(P, K).M, closed_loop(Pp, Kt).M, rtol=1e-9, atol=1e-12)
    # independent: frozen plants and controllers interconnected by python-control
    Delta, Delta_c = 0.3 * rand(rng, 2, 2), np.array([[-0.5]])
    ref_p = _ctrl_ss(Pp.frozen(Delta)).lft(_ctrl_ss(Kt.at(Delta_c)), nu=1, ny=2)
    ref_s = _ctrl_ss(P.frozen(Delta)).lft(_ctrl_ss(K.at(Delta_c)), nu=1, ny=2)
    wrong = _ctrl_ss(P.frozen(Delta)).lft(_ctrl_ss(Kt.at(Delta_c)), nu=1, ny=2)  # K̃ on M_s: not the same
    for s in (0.5j, 3 + 2j, 25j):
        np.testing.assert_allclose(ref_s(s), ref_p(s), rtol=1e-9, atol=1e-12)
        assert not np.allclose(wrong(s), ref_p(s), rtol=1e-6)
    # the frozen K really has D_c = (I + D̃ F3)^{-1} D̃ at Δ_c (u = D̃ (y − F3 u))
    Dt = Kt.at(Delta_c).D
    np.testing.assert_allclose(K.at(Delta_c).D, np.linalg.solve(np.eye(1) + Dt @ F3, Dt), rtol=1e-10)


def test_restore_feedthrough_ill_posed():
    F3 = np.array([[2.0], [0.0]])
    Kt = LFTController.from_blocks(D_c11=[[-0.5, 0.3]])  # I + D̃11 F3 = 1 − 1 = 0
    assert Kt.n_c == 0
    with pytest.raises(IllPosedError):
        restore_feedthrough(Kt, F3)
