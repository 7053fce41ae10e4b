"""Tests for synthesis.complex_formed: (3.45)/(3.46), T_C (5.65), the projection (5.74), Sec. 5.5."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synthesis.complex_formed import (
    complex_formed,
    controller_real_form,
    controller_t_c,
    decompose,
    interleaved_to_blocked,
    is_complex_formed,
    is_complex_formed_ss,
    is_complex_formed_tf,
    j_matrix,
    lft_real_form,
    lft_t_c,
    project,
    project_blocks,
    q_matrix,
    real_form,
    ss_real_form,
    ss_t_c,
    t_c,
    vec_complex,
    vec_real,
)
from synthesis.discretize import bilinear_lft
from synthesis.lft import LFTController, LFTPlant, StateSpace

L_s, L_r, L_m, R_s, R_r = 0.352, 0.352, 0.341, 5.0, 3.3  # (3.57)
W_MAX = 200.0


def crand(rng, m, n):
    return rng.standard_normal((m, n)) + 1j * rng.standard_normal((m, n))


def rrand(rng, m, n):
    return rng.standard_normal((m, n))


# -------------------------------------------------------------------------------------------------
# the motor, typed from the thesis: complex (3.41)/(5.77) and real (3.47)
# -------------------------------------------------------------------------------------------------
def A_sc(w_r):
    den = L_r * (L_m**2 - L_s * L_r)
    return np.array(
        [
            [(L_m**2 * R_r + R_s * L_r**2) / den, L_m**2 * (1j * L_r * w_r - R_r) / den],
            [R_r / L_r, 1j * w_r - R_r / L_r],
        ]
    )


B_SC = np.array([[L_r / (L_s * L_r - L_m**2)], [0.0]])


def A_sr(w_r):
    d = L_m**2 - L_s * L_r
    a11 = (L_m**2 * R_r + R_s * L_r**2) / (L_r * d)
    a12 = -(L_m**2) * R_r / (L_r * d)
    return np.array(
        [
            [a11, a12, 0, -(L_m**2) * w_r / d],
            [R_r / L_r, -R_r / L_r, 0, -w_r],
            [0, L_m**2 * w_r / d, a11, a12],
            [0, w_r, R_r / L_r, -R_r / L_r],
        ]
    )


B_SR = np.array([[L_r / (L_s * L_r - L_m**2), 0], [0, 0], [0, L_r / (L_s * L_r - L_m**2)], [0, 0]])


def motor_complex_lft() -> LFTPlant:
    d = L_m**2 - L_s * L_r
    A0 = A_sc(0.0)
    A1 = np.array([[1j * L_m**2 / d], [1j]])
    return LFTPlant.from_blocks(
        A0, B_u=np.sqrt(W_MAX) * A1, C_u=np.sqrt(W_MAX) * np.array([[0.0, 1.0]]), B_p=B_SC, C_p=np.eye(2)
    )


# -------------------------------------------------------------------------------------------------
# matrices
# -------------------------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 4), n=st.integers(1, 4))
def test_real_form_roundtrip_and_signal_consistency(seed, m, n):
    rng = np.random.default_rng(seed)
    M = crand(rng, m, n)
    R = real_form(M)
    assert R.shape == (2 * m, 2 * n) and np.isrealobj(R)
    np.testing.assert_array_equal(R, np.block([[M.real, -M.imag], [M.imag, M.real]]))  # (3.45)
    assert is_complex_formed(R)
    np.testing.assert_allclose(t_c(R), M, rtol=1e-15)
    np.testing.assert_allclose(real_form(t_c(R)), R, rtol=1e-15)
    # (3.45) and (3.46) are consistent: real_form(M) [Re x; Im x] = [Re Mx; Im Mx]
    x = crand(rng, n, 1)
    np.testing.assert_allclose(R @ vec_real(x), vec_real(M @ x), rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(vec_complex(vec_real(x)), x)


def test_is_complex_formed_rejects_and_t_c_checks():
    rng = np.random.default_rng(0)
    X = rrand(rng, 4, 6)
    assert not is_complex_formed(X)
    assert not is_complex_formed(rrand(rng, 3, 4))  # odd size
    with pytest.raises(ValueError, match="not complex-formed"):
        t_c(X)
    R = real_form(crand(rng, 2, 3))
    R[0, 0] += 1e-6
    assert not is_complex_formed(R)
    assert is_complex_formed(R, rtol=1e-5)


def test_t_c_is_a_homomorphism_including_complex_blocks():
    """T_C additive, multiplicative, and T_C(M^{-1}) = T_C(M)^{-1} (Lemmas 5.17, 5.20) for complex M_r, M_i."""
    rng = np.random.default_rng(1)
    M1 = complex_formed(crand(rng, 3, 2), crand(rng, 3, 2))
    M2 = complex_formed(crand(rng, 3, 2), crand(rng, 3, 2))
    M3 = complex_formed(crand(rng, 2, 4), crand(rng, 2, 4))
    M4 = complex_formed(crand(rng, 3, 3), crand(rng, 3, 3))
    np.testing.assert_allclose(t_c(M1 + M2), t_c(M1) + t_c(M2), rtol=1e-13)
    assert is_complex_formed(M1 @ M3)
    np.testing.assert_allclose(t_c(M1 @ M3), t_c(M1) @ t_c(M3), rtol=1e-12)
    Mi = np.linalg.inv(M4)
    assert is_complex_formed(Mi)  # Lemma 5.17
    np.testing.assert_allclose(t_c(Mi), np.linalg.inv(t_c(M4)), rtol=1e-9)  # (5.66)
    # Remark 5.19: T_C is not injective on complex blocks: M_r + j M_i = (M_r + j Z) + j (M_i − Z)
    Mr, Mi_ = crand(rng, 2, 2), crand(rng, 2, 2)
    Z = crand(rng, 2, 2)
    A, B = complex_formed(Mr, Mi_), complex_formed(Mr + 1j * Z, Mi_ - Z)
    assert not np.allclose(A, B)
    np.testing.assert_allclose(t_c(A), t_c(B), rtol=1e-13)


def test_j_and_q_matrices():
    rng = np.random.default_rng(2)
    J3 = j_matrix(3)
    np.testing.assert_array_equal(J3, np.block([[np.zeros((3, 3)), -np.eye(3)], [np.eye(3), np.zeros((3, 3))]]))
    np.testing.assert_allclose(t_c(J3), 1j * np.eye(3))
    np.testing.assert_array_equal(J3 @ J3, -np.eye(6))
    np.testing.assert_array_equal(q_matrix(2) @ q_matrix(2), np.eye(4))
    A = complex_formed(crand(rng, 2, 3), crand(rng, 2, 3))  # Lemma 5.29: J_m A = A J_n
    np.testing.assert_allclose(j_matrix(2) @ A, A @ j_matrix(3), rtol=1e-13)
    assert not np.allclose(j_matrix(2) @ rrand(rng, 4, 6), rrand(rng, 4, 6) @ j_matrix(3))


def test_remark_5_23_eigenvalues():
    rng = np.random.default_rng(3)
    Mc = crand(rng, 3, 3)
    ev_real = np.linalg.eigvals(real_form(Mc))
    ev_c = np.linalg.eigvals(Mc)
    both = np.concatenate([ev_c, ev_c.conj()])
    np.testing.assert_allclose(np.sort_complex(ev_real), np.sort_complex(both), rtol=1e-10)


# -------------------------------------------------------------------------------------------------
# projection (5.74)
# -------------------------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 3), l=st.integers(1, 3), cplx=st.booleans())
def test_projection(seed, m, l, cplx):
    rng = np.random.default_rng(seed)
    X = crand(rng, 2 * m, 2 * l) if cplx else rrand(rng, 2 * m, 2 * l)
    Xc = project(X)
    # literally ½ (X + J_m^* X J_l)
    np.testing.assert_allclose(Xc, 0.5 * (X + j_matrix(m).conj().T @ X @ j_matrix(l)), rtol=1e-13, atol=1e-15)
    assert is_complex_formed(Xc)
    np.testing.assert_allclose(project(Xc), Xc, rtol=1e-14)  # idempotent
    # orthogonal: X − X_c ⟂ every complex-formed Y (Frobenius inner product)
    Y = complex_formed(crand(rng, m, l), crand(rng, m, l))
    assert abs(np.vdot(Y, X - Xc)) < 1e-10 * np.linalg.norm(X) * np.linalg.norm(Y)
    # the thesis' decomposition X = X_c + Q X_c̄ with X_c̄ complex-formed
    Xc2, Xcb = decompose(X)
    np.testing.assert_allclose(Xc2, Xc)
    assert is_complex_formed(Xcb)
    np.testing.assert_allclose(Xc + q_matrix(m) @ Xcb, X, rtol=1e-13, atol=1e-14)
    # a complex-formed matrix is left alone; a real one stays real
    np.testing.assert_allclose(project(Y), Y, rtol=1e-14)
    assert np.isrealobj(Xc) == np.isrealobj(X)


def test_projection_preserves_hermitian_and_lmi_feasibility():
    """Thm 5.30: L(X_c) = ½ (L(X) + J^* L(X) J), so L(X) > 0 implies L(X_c) > 0."""
    rng = np.random.default_rng(4)
    n, m, l = 3, 2, 2
    A = complex_formed(crand(rng, n, m), crand(rng, n, m))  # 2n x 2m
    B = complex_formed(crand(rng, l, n), crand(rng, l, n))  # 2l x 2n
    X = crand(rng, 2 * m, 2 * l)  # an unstructured "solution"

    def L(X, C):
        T = A @ X @ B
        return T + T.conj().T + C

    T = A @ X @ B
    lam_min = np.linalg.eigvalsh(T + T.conj().T).min()
    C = (-lam_min + 0.05) * np.eye(2 * n)  # complex-formed Hermitian, L(X) > 0 just barely
    assert np.linalg.eigvalsh(L(X, C)).min() > 0
    assert not is_complex_formed(L(X, C))
    Xc = project(X)
    LXc = L(Xc, C)
    Jn = j_matrix(n)
    np.testing.assert_allclose(LXc, 0.5 * (L(X, C) + Jn.conj().T @ L(X, C) @ Jn), rtol=1e-10, atol=1e-10)
    assert np.linalg.eigvalsh(LXc).min() > 0
    assert is_complex_formed(LXc, rtol=1e-9)
    # Hermitian in, Hermitian out
    H = crand(rng, 4, 4)
    H = H + H.conj().T
    Hc = project(H)
    np.testing.assert_allclose(Hc, Hc.conj().T, rtol=1e-14)


def test_project_blocks_matches_example_5_32():
    """Block-wise projection = ½ (P X0 P^* + P J^* X0 J P^*), X0 = P^* [[Q, S], [S^*, R]] P."""
    rng = np.random.default_rng(5)
    n, p = 2, 3
    W = crand(rng, 2 * (n + p), 2 * (n + p))
    X = W + W.conj().T  # Hermitian multiplier [[Q, S], [S^*, R]], Q 2n x 2n, R 2p x 2p
    I_n, I_p = np.eye(n), np.eye(p)
    Z = lambda a, b: np.zeros((a, b))  # noqa: E731
    P = np.block(
        [
            [I_n, Z(n, p), Z(n, n), Z(n, p)],
            [Z(n, n), Z(n, p), I_n, Z(n, p)],
            [Z(p, n), I_p, Z(p, n), Z(p, p)],
            [Z(p, n), Z(p, p), Z(p, n), I_p],
        ]
    )
    assert np.allclose(P @ P.T, np.eye(2 * (n + p)))
    X0 = P.T @ X @ P
    J = j_matrix(n + p)
    thesis = 0.5 * (P @ X0 @ P.T + P @ J.conj().T @ X0 @ J @ P.T)
    ours = project_blocks(X, [2 * n, 2 * p])
    np.testing.assert_allclose(ours, thesis, rtol=1e-12, atol=1e-13)
    for blk in (ours[: 2 * n, : 2 * n], ours[: 2 * n, 2 * n :], ours[2 * n :, 2 * n :]):
        assert is_complex_formed(blk)
    np.testing.assert_allclose(ours, ours.conj().T, rtol=1e-13)  # Q, R stay Hermitian
    # and it differs from projecting the whole matrix at once (different structure)
    assert not np.allclose(ours, project(X))


# -------------------------------------------------------------------------------------------------
# systems
# -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("w_r", [-200.0, 0.0, 137.0, 297.4])
def test_motor_real_form_is_thesis_3_47(w_r):
    G = StateSpace(A_sc(w_r), B_SC, np.eye(2), np.zeros((2, 1)))
    R = ss_real_form(G)
    np.testing.assert_allclose(R.A, A_sr(w_r), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(R.B, B_SR, rtol=1e-12)
    assert is_complex_formed_ss(R) and is_complex_formed_tf(R)
    back = ss_t_c(R)
    np.testing.assert_allclose(back.A, G.A, rtol=1e-14)


@pytest.mark.parametrize("w_r", [-150.0, 60.0])
def test_real_form_has_same_frequency_response(w_r):
    """Cor. 5.22 on the motor: G_r(jω) complex-formed, T_C(G_r(jω)) = G_c(jω), ω of both signs (Remark 5.24)."""
    Gc = StateSpace(A_sc(w_r), B_SC, np.array([[1.0, 0.0], [0.0, 1.0]]), np.zeros((2, 1)))
    Gr = ss_real_form(Gc)
    for w in (-2000.0, -314.0, -5.0, 0.0, 5.0, 314.0, 2000.0):
        Hr, Hc = Gr.evaluate(1j * w), Gc.evaluate(1j * w)
        assert is_complex_formed(Hr)
        np.testing.assert_allclose(t_c(Hr), Hc, rtol=1e-10, atol=1e-14)
    # the response is not symmetric in ω (Remark 5.24) when ω_r ≠ 0
    assert not np.allclose(np.abs(Gc.evaluate(300j)), np.abs(Gc.evaluate(-300j)), rtol=1e-3)


def test_complex_input_channel_in_time_domain():
    """Driving the complex system with u_k and its real form with [Re u_k; Im u_k] (3.46) gives
    outputs y_k and [Re y_k; Im y_k], with ω_r varying every sample (discretised LFT, 3 kHz)."""
    P = motor_complex_lft()
    Pd_c, Pd_r = bilinear_lft(P, 1 / 3000), bilinear_lft(lft_real_form(P), 1 / 3000)
    rng = np.random.default_rng(9)
    xc, xr = np.zeros((2, 1), complex), np.zeros((4, 1))
    for k in range(150):
        d = 1.2 * np.sin(k / 20.0)
        u = np.array([[300 * np.exp(0.04j * k) + rng.normal(0, 10) + 1j * rng.normal(0, 10)]])
        Gc, Gr = Pd_c.frozen([[d]]), Pd_r.frozen(real_form([[d]]))
        yc, yr = Gc.C @ xc + Gc.D @ u, Gr.C @ xr + Gr.D @ vec_real(u)
        xc, xr = Gc.A @ xc + Gc.B @ u, Gr.A @ xr + Gr.B @ vec_real(u)
        np.testing.assert_allclose(yr, vec_real(yc), rtol=1e-9, atol=1e-9)
    assert np.abs(yc).max() > 0.1


def test_is_complex_formed_tf_is_realisation_independent():
    R = ss_real_form(StateSpace(A_sc(120.0), B_SC, np.eye(2), np.zeros((2, 1))))
    # interleaved state order [i_sD, i_sQ, i_mD, i_mQ]: matrices no longer complex-formed, TF unchanged
    p = interleaved_to_blocked(2)
    np.testing.assert_array_equal(p, [0, 2, 1, 3])
    inv = np.argsort(p)
    inter = StateSpace(R.A[np.ix_(inv, inv)], R.B[inv], R.C[:, inv], R.D)
    assert not is_complex_formed_ss(inter)
    assert is_complex_formed_tf(inter)
    back = StateSpace(inter.A[np.ix_(p, p)], inter.B[p], inter.C[:, p], inter.D)
    assert is_complex_formed_ss(back)
    np.testing.assert_array_equal(back.A, R.A)
    # a random similarity transform keeps the TF complex-formed
    rng = np.random.default_rng(6)
    T = rrand(rng, 4, 4) + 3 * np.eye(4)
    assert is_complex_formed_tf(R.transform(T)) and not is_complex_formed_ss(R.transform(T))
    # a random real system is not complex-formed
    rnd = StateSpace(rrand(rng, 4, 4) - 3 * np.eye(4), rrand(rng, 4, 2), rrand(rng, 2, 4), np.zeros((2, 2)))
    assert not is_complex_formed_tf(rnd)
    # a small violation in the slow (rotor) dynamics is detected: perturb i_mQ -> i_mD coupling
    A_bad = R.A.copy()
    A_bad[1, 3] += 1.0  # ω_r entry −120 -> −119 in one place only
    assert not is_complex_formed_tf(StateSpace(A_bad, R.B, R.C, R.D))


def test_motor_lft_real_form_and_back():
    """lft_real_form closes with real_form(Δ) = blockdiag(Δ, Δ) and reproduces (3.47); T_C undoes it,
    also after Tustin discretisation (which preserves the structure)."""
    P = motor_complex_lft()
    Pr = lft_real_form(P)
    assert (Pr.n_x, Pr.n_zu, Pr.n_wu, Pr.n_zp, Pr.n_wp) == (4, 2, 2, 4, 2)
    assert np.isrealobj(Pr.M)
    for w_r in (-180.0, 75.0):
        d = w_r / W_MAX
        Gr = Pr.frozen(real_form([[d]]))
        np.testing.assert_allclose(Gr.A, A_sr(w_r), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(Gr.B, B_SR, rtol=1e-12)
    back = lft_t_c(Pr)
    np.testing.assert_allclose(back.M, P.M, rtol=1e-14)
    Ts = 1 / 3000
    Pd_r, Pd_c = bilinear_lft(Pr, Ts), bilinear_lft(P, Ts)
    for blk in ("A", "B_u", "C_u", "D_uu", "B_p", "C_p", "D_pp"):
        assert is_complex_formed(Pd_r.block(blk))
    np.testing.assert_allclose(lft_t_c(Pd_r).M, Pd_c.M, rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError, match="not complex-formed"):
        lft_t_c(LFTPlant.from_blocks(rrand(np.random.default_rng(7), 4, 4)))


def test_controller_forms_roundtrip_and_frozen_response():
    rng = np.random.default_rng(8)
    K = LFTController.from_blocks(
        crand(rng, 2, 2) - 3 * np.eye(2), B_c1=crand(rng, 2, 2), B_c2=crand(rng, 2, 1),
        C_c1=crand(rng, 1, 2), D_c11=crand(rng, 1, 2), D_c12=crand(rng, 1, 1),
        C_c2=crand(rng, 1, 2), D_c21=crand(rng, 1, 2), D_c22=0.1 * crand(rng, 1, 1),
    )  # fmt: skip
    Kr = controller_real_form(K)
    assert (Kr.n_c, Kr.n_u, Kr.n_y, Kr.n_zc, Kr.n_wc) == (4, 2, 4, 2, 2)
    np.testing.assert_array_equal(Kr.A_c, real_form(K.A_c))
    np.testing.assert_allclose(controller_t_c(Kr).M, K.M, rtol=1e-14)
    # a real scheduling parameter: frozen real controller = real form of frozen complex controller
    d = 0.4
    Fc, Fr = K.at([[d]]), Kr.at(real_form([[d]]))
    for s in (1j, 10 - 3j):
        np.testing.assert_allclose(t_c(Fr.evaluate(s)), Fc.evaluate(s), rtol=1e-10)
