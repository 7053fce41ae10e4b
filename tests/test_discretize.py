"""Tests for synthesis.discretize: Tustin discretisation as D_bl ⋆ M (thesis Sec. 5.4.1).

References are independent implementations: scipy.signal.cont2discrete(method='bilinear') and
python-control's sample_system(..., 'tustin'), applied to the frozen continuous plant.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from scipy.linalg import block_diag
from scipy.signal import cont2discrete

from synthesis.discretize import bilinear_lft, bilinear_lti, d_bl, tustin_period
from synthesis.lft import IllPosedError, LFTPlant, StateSpace

TS = 1.0 / 3000.0  # the lab's sampling period (App. A)
L_s, L_r, L_m, R_s, R_r = 0.352, 0.352, 0.341, 5.0, 3.3  # (3.57)
W_MAX = 200.0


def rand(rng, m, n, scale=1.0):
    return scale * rng.standard_normal((m, n))


def A_sr(w_r: float) -> np.ndarray:
    """Real 4-state motor model (3.47), state [i_sD, i_mD, i_sQ, i_mQ], typed from the thesis."""
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
C_SR = np.eye(4)  # measure all four currents


def motor_real_lft() -> LFTPlant:
    """(3.47) in LFT form with Δ = ω_r/ω_r,max · I_2 (parameter channel of width 2)."""
    d = L_m**2 - L_s * L_r
    A0 = A_sr(0.0)
    Aw = A_sr(1.0) - A0  # ∂A/∂ω_r, rank 2: columns 2 and 4 only
    B1 = Aw[:, [1, 3]]
    C1 = np.zeros((2, 4))
    C1[0, 1] = C1[1, 3] = 1.0
    assert np.allclose(B1 @ C1, Aw) and d < 0
    return LFTPlant.from_blocks(A0, B_u=math.sqrt(W_MAX) * B1, C_u=math.sqrt(W_MAX) * C1, B_p=B_SR, C_p=C_SR)


def random_lpv(rng, n=3, nw=2, nz=2, m=2, p=2) -> LFTPlant:
    """A random plant with D_uu ≠ 0, so Δ enters A, B, C and D non-trivially."""
    return LFTPlant.from_blocks(
        rand(rng, n, n) - 3 * np.eye(n),
        B_u=rand(rng, n, nw), C_u=rand(rng, nz, n), D_uu=rand(rng, nz, nw, 0.2), D_up=rand(rng, nz, m),
        B_p=rand(rng, n, m), C_p=rand(rng, p, n), D_pu=rand(rng, p, nw), D_pp=rand(rng, p, m),
    )  # fmt: skip


def to_control(S: StateSpace) -> control.StateSpace:
    return control.ss(S.A, S.B, S.C, S.D, 0 if S.dt is None else S.dt)


def z_points(Ts: float) -> np.ndarray:
    """z = exp(jωT_s) from DC over a few rad/s up to 95 % of Nyquist."""
    w = np.array([0.0, 1.0, 30.0, 300.0, 0.2 * math.pi / Ts, 0.6 * math.pi / Ts, 0.95 * math.pi / Ts])
    return np.exp(1j * w * Ts)


def test_d_bl_is_thesis_matrix():
    D = d_bl(2, 0.01)
    r = math.sqrt(0.01)
    np.testing.assert_allclose(D.M, np.block([[np.eye(2), r * np.eye(2)], [r * np.eye(2), 0.005 * np.eye(2)]]))
    assert (D.n_out1, D.n_in1) == (2, 2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lti_unbalanced_equals_scipy_exactly_and_balanced_is_similar(seed):
    rng = np.random.default_rng(seed)
    A, B, C, D = rand(rng, 4, 4) - 2 * np.eye(4), rand(rng, 4, 2), rand(rng, 3, 4), rand(rng, 3, 2)
    Ts = 0.05
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), Ts, method="bilinear")
    ub = bilinear_lti(StateSpace(A, B, C, D), Ts, balanced=False)
    for ours, ref in zip((ub.A, ub.B, ub.C, ub.D), (Ad, Bd, Cd, Dd)):
        np.testing.assert_allclose(ours, ref, rtol=1e-11, atol=1e-13)
    # the thesis' D_bl: state x_k = ξ_k/√T_s, i.e. ξ = √T_s x
    bal = bilinear_lti(StateSpace(A, B, C, D), Ts)
    assert bal.dt == Ts
    sim = bal.transform(math.sqrt(Ts) * np.eye(4))
    for ours, ref in zip((sim.A, sim.B, sim.C, sim.D), (Ad, Bd, Cd, Dd)):
        np.testing.assert_allclose(ours, ref, rtol=1e-11, atol=1e-13)
    # transfer functions agree with python-control's Tustin
    ref_pc = control.sample_system(control.ss(A, B, C, D), Ts, method="tustin")
    for z in z_points(Ts):
        np.testing.assert_allclose(bal.evaluate(z), ref_pc(z), rtol=1e-9, atol=1e-12)


def test_prewarp_matches_python_control():
    rng = np.random.default_rng(3)
    A, B, C, D = rand(rng, 3, 3) - 2 * np.eye(3), rand(rng, 3, 1), rand(rng, 1, 3), rand(rng, 1, 1)
    Ts, wp = 0.02, 40.0
    ours = bilinear_lti(StateSpace(A, B, C, D), Ts, prewarp=wp)
    ref = control.sample_system(control.ss(A, B, C, D), Ts, method="tustin", prewarp_frequency=wp)
    plain = bilinear_lti(StateSpace(A, B, C, D), Ts)
    for z in z_points(Ts):
        np.testing.assert_allclose(ours.evaluate(z), ref(z), rtol=1e-9, atol=1e-12)
    # prewarping makes the response exact at ω_p, plain Tustin is not
    G_c = StateSpace(A, B, C, D).evaluate(1j * wp)
    np.testing.assert_allclose(ours.evaluate(np.exp(1j * wp * Ts)), G_c, rtol=1e-10)
    assert not np.allclose(plain.evaluate(np.exp(1j * wp * Ts)), G_c, rtol=1e-3)
    assert tustin_period(Ts, wp) > Ts


@pytest.mark.parametrize("seed", [4, 5])
def test_lft_discretisation_keeps_parameter_block(seed):
    """(D_bl ⋆ M) ⋆ Δ = Tustin(M ⋆ Δ) for several frozen Δ, with the same Δ block."""
    rng = np.random.default_rng(seed)
    P = random_lpv(rng)
    Ts = 0.05
    Pd = bilinear_lft(P, Ts)
    Pd_ub = bilinear_lft(P, Ts, balanced=False)
    assert Pd.dt == Ts and P.dt is None
    assert (Pd.n_x, Pd.n_zu, Pd.n_wu, Pd.n_zp, Pd.n_wp, Pd.n_y, Pd.n_u) == (
        P.n_x, P.n_zu, P.n_wu, P.n_zp, P.n_wp, P.n_y, P.n_u,
    )  # fmt: skip
    responses = []
    for Delta in (np.zeros((2, 2)), np.diag([0.8, -0.5]), rand(rng, 2, 2, 0.6)):
        cont = P.frozen(Delta)
        disc = Pd.frozen(Delta)
        assert disc.dt == Ts
        # exact realisation: unbalanced D_bl gives scipy's matrices, by associativity of ⋆
        Ad, Bd, Cd, Dd, _ = cont2discrete((cont.A, cont.B, cont.C, cont.D), Ts, method="bilinear")
        ub = Pd_ub.frozen(Delta)
        for ours, ref in zip((ub.A, ub.B, ub.C, ub.D), (Ad, Bd, Cd, Dd)):
            np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-12)
        ref_pc = control.sample_system(to_control(cont), Ts, method="tustin")
        for z in z_points(Ts):
            np.testing.assert_allclose(disc.evaluate(z), ref_pc(z), rtol=1e-9, atol=1e-12)
        responses.append(disc.evaluate(np.exp(0.3j)))
    # Δ genuinely changes the discrete plant
    assert not np.allclose(responses[0], responses[1], rtol=1e-3)


@pytest.mark.parametrize("w_r", [-200.0, -60.0, 0.0, 150.0, 297.4])
def test_motor_lft_discretised_at_3khz(w_r):
    """The real motor model (3.47) with ω_r as parameter, discretised once at 3 kHz."""
    P = motor_real_lft()
    np.testing.assert_allclose(P.frozen(w_r / W_MAX * np.eye(2)).A, A_sr(w_r), rtol=1e-12, atol=1e-9)
    Pd = bilinear_lft(P, TS)
    disc = Pd.frozen(w_r / W_MAX * np.eye(2))
    ref = control.sample_system(control.ss(A_sr(w_r), B_SR, C_SR, 0), TS, method="tustin")
    for z in z_points(TS):
        np.testing.assert_allclose(disc.evaluate(z), ref(z), rtol=1e-8, atol=1e-12)
    H = disc.freqresp([10.0, 500.0, 9000.0])  # z = exp(jωT_s)
    assert H.shape == (3, 4, 2)
    np.testing.assert_allclose(H[1], ref(np.exp(500j * TS)), rtol=1e-8, atol=1e-12)
    # eigenvalues map by z = (1 + λT/2)/(1 − λT/2)
    lam = np.linalg.eigvals(A_sr(w_r))
    np.testing.assert_allclose(
        np.sort_complex(disc.poles()), np.sort_complex((1 + lam * TS / 2) / (1 - lam * TS / 2)), rtol=1e-10
    )
    assert np.all(np.abs(disc.poles()) < 1)


def test_time_varying_parameter_is_trapezoidal_rule_with_frozen_delta():
    """Simulate the discrete LFT with Δ_k changing every sample; it must equal the trapezoidal rule
    ξ_{k+1} = ξ_k + T (A(Δ_k) (ξ_k + ξ_{k+1})/2 + B(Δ_k) u_k) with ξ = √T x (Sec. 5.4.1)."""
    P = motor_real_lft()
    Pd = bilinear_lft(P, TS)
    rng = np.random.default_rng(6)
    n = 4
    x = np.zeros(n)
    xi = np.zeros(n)
    for k in range(200):
        w_r = 250.0 * math.sin(2 * math.pi * k / 90.0)
        u = np.array([300.0 * math.cos(0.05 * k), 300.0 * math.sin(0.05 * k)]) + rng.normal(0, 5, 2)
        D = w_r / W_MAX * np.eye(2)
        Gd, Gc = Pd.frozen(D), P.frozen(D)
        y = Gd.C @ x + Gd.D @ u
        x = Gd.A @ x + Gd.B @ u
        # trapezoidal rule, solved for ξ_{k+1}; output at the midpoint r_k
        Ac, Bc = Gc.A, Gc.B
        xi_next = np.linalg.solve(np.eye(n) - TS / 2 * Ac, xi + TS / 2 * Ac @ xi + TS * Bc @ u)
        y_ref = Gc.C @ ((xi + xi_next) / 2) + Gc.D @ u
        xi = xi_next
        np.testing.assert_allclose(y, y_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(math.sqrt(TS) * x, xi, rtol=1e-9, atol=1e-9)
    assert np.max(np.abs(xi)) > 1.0  # the currents actually moved


def test_discretised_feedthrough_blocks_appear():
    """D_uu,d = D_uu + (T/2) C_u (I − (T/2)A)^{-1} B_u: zero in continuous time, not in discrete time."""
    P = motor_real_lft()
    Pd = bilinear_lft(P, TS)
    assert not np.any(P.D_uu)
    ref = TS / 2 * P.C_u @ np.linalg.solve(np.eye(4) - TS / 2 * P.A, P.B_u)
    np.testing.assert_allclose(Pd.D_uu, ref, rtol=1e-12)
    assert np.linalg.norm(Pd.D_uu) > 0


def test_errors():
    P = motor_real_lft()
    Pd = bilinear_lft(P, TS)
    with pytest.raises(ValueError, match="already discrete"):
        bilinear_lft(Pd, TS)
    with pytest.raises(ValueError, match="already discrete"):
        bilinear_lti(Pd.frozen(np.zeros((2, 2))), TS)
    with pytest.raises(ValueError, match="positive"):
        bilinear_lft(P, 0.0)
    with pytest.raises(ValueError, match="prewarp"):
        bilinear_lft(P, TS, prewarp=2 * math.pi / TS)
    # an eigenvalue at 2/T_s: I − (T/2) A singular -> not well-posed
    Ts = 0.1
    with pytest.raises(IllPosedError):
        bilinear_lti(StateSpace(np.array([[2 / Ts]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))), Ts)


def test_complex_plant_discretises_like_its_real_form():
    """Tustin on the complex 2-state motor model equals Tustin on the real 4-state model (3.45)."""
    d = L_m**2 - L_s * L_r
    A0 = A_sr(0.0)[:2, :2].astype(complex)
    A1 = np.array([[1j * L_m**2 / d], [1j]])
    P = LFTPlant.from_blocks(
        A0, B_u=math.sqrt(W_MAX) * A1, C_u=math.sqrt(W_MAX) * np.array([[0.0, 1.0]]),
        B_p=B_SR[:2, :1], C_p=np.eye(2),
    )  # fmt: skip
    Pd = bilinear_lft(P, TS)
    assert np.iscomplexobj(Pd.M)
    Pr = bilinear_lft(motor_real_lft(), TS)
    for w_r in (-120.0, 80.0):
        Gc = Pd.frozen([[w_r / W_MAX]])
        Gr = Pr.frozen(w_r / W_MAX * np.eye(2))
        for z in z_points(TS):
            Hc, Hr = Gc.evaluate(z), Gr.evaluate(z)
            # complex input u applied to the real form: output [Re y; Im y] (3.46), for u = 1 and u = j
            np.testing.assert_allclose(Hr[:2, 0] + 1j * Hr[2:, 0], Hc[:, 0], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(Hr[:2, 1] + 1j * Hr[2:, 1], 1j * Hc[:, 0], rtol=1e-9, atol=1e-12)


def test_block_diagonal_parameter_block():
    """Two independent parameters, Δ = blockdiag(δ1, δ2 I_2), survive discretisation unchanged."""
    rng = np.random.default_rng(7)
    P = random_lpv(rng, n=3, nw=3, nz=3, m=1, p=1)
    Pd = bilinear_lft(P, 0.01)
    for d1, d2 in ((0.3, -0.2), (-0.9, 0.7)):
        Delta = block_diag([[d1]], d2 * np.eye(2))
        ref = control.sample_system(to_control(P.frozen(Delta)), 0.01, method="tustin")
        got = Pd.frozen(Delta)
        for z in z_points(0.01):
            np.testing.assert_allclose(got.evaluate(z), ref(z), rtol=1e-9, atol=1e-12)
