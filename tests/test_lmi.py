"""Tests for synthesis.lmi: the discrete synthesis LMIs of Thm 5.15 (and the whole design pipeline).

Known answers used:
- LTI H∞ (no parameter block): the optimal γ of a continuous plant by the Riccati / Hamiltonian test of
  Doyle-Glover-Khargonekar-Francis (implemented here with scipy, independently of the code under test),
  compared with γ_a of the discrete LMIs for the Tustin-discretised plant (the bilinear map preserves
  H∞ norms and maps proper controllers one to one, so the optimal γ is the same). python-control's
  `hinfsyn` needs slycot, which is not installed.
- Cor. 5.33: restricting the solution of a complex plant to complex-formed matrices loses nothing,
  so γ_a of the complex plant equals γ_a of its real form with unrestricted real variables.
- The decay-rate margin β of 5.4.4 can only increase γ_a and bounds the closed-loop spectral radius.
"""

from __future__ import annotations


import numpy as np
import pytest
import scipy.linalg as sla

from synthesis.complex_formed import lft_real_form, real_form
from synthesis.construct import construct_controller
from synthesis.discretize import bilinear_lft
from synthesis.lft import LFTPlant, remove_feedthrough
from synthesis.lmi import (
    ParameterSet,
    SynthesisProblem,
    bisect_gamma,
    lmi_residuals,
    null_basis,
)
from synthesis.verify import frozen_closed_loop, hinf_norm, verify

# LMIWarning (optimal_inaccurate, re-checked) and scipy ill-conditioning notes are expected here
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


# -------------------------------------------------------------------------------------------------
# independent reference: continuous H∞ optimum by the DGKF Riccati conditions
# -------------------------------------------------------------------------------------------------
def _ric(H: np.ndarray) -> np.ndarray | None:
    """Stabilising solution of the Riccati equation with Hamiltonian H, or None."""
    n = H.shape[0] // 2
    ev = np.linalg.eigvals(H)
    if np.min(np.abs(ev.real)) < 1e-9 * max(1.0, np.abs(ev).max()):
        return None
    T, Z, sdim = sla.schur(H, sort="lhp")
    if sdim != n:
        return None
    X1, X2 = Z[:n, :n], Z[n:, :n]
    if np.linalg.cond(X1) > 1e12:
        return None
    X = X2 @ np.linalg.inv(X1)
    return 0.5 * (X + X.T)


def dgkf_feasible(A, B1, B2, C1, C2, g) -> bool:
    """DGKF: D11 = 0, D12 = [0; I] ⊥ C1, D21 = [0 I] ⊥ B1, D22 = 0."""
    HX = np.block([[A, B1 @ B1.T / g**2 - B2 @ B2.T], [-C1.T @ C1, -A.T]])
    HY = np.block([[A.T, C1.T @ C1 / g**2 - C2.T @ C2], [-B1 @ B1.T, -A]])
    X, Y = _ric(HX), _ric(HY)
    if X is None or Y is None:
        return False
    if np.linalg.eigvalsh(X)[0] < -1e-9 or np.linalg.eigvalsh(Y)[0] < -1e-9:
        return False
    return max(abs(np.linalg.eigvals(X @ Y))) < g**2


def dgkf_gamma(A, B1, B2, C1, C2, lo=1e-3, hi=1e3, rtol=1e-6) -> float:
    assert dgkf_feasible(A, B1, B2, C1, C2, hi)
    while hi - lo > rtol * hi:
        mid = np.sqrt(lo * hi)
        if dgkf_feasible(A, B1, B2, C1, C2, mid):
            hi = mid
        else:
            lo = mid
    return hi


def dgkf_plant(seed: int):
    rng = np.random.default_rng(seed)
    n = 3
    A = rng.standard_normal((n, n))
    A = A - (max(np.linalg.eigvals(A).real) - 0.5) * np.eye(n)  # one unstable mode at +0.5
    B1a = rng.standard_normal((n, 1))
    B2 = rng.standard_normal((n, 1))
    C1a = rng.standard_normal((1, n))
    C2 = rng.standard_normal((1, n))
    B1 = np.hstack([B1a, np.zeros((n, 1))])  # w = [process; sensor noise]
    C1 = np.vstack([C1a, np.zeros((1, n))])  # z = [C1a x; u]
    D12 = np.array([[0.0], [1.0]])
    D21 = np.array([[0.0, 1.0]])
    plant = LFTPlant.from_blocks(A, B_p=B1, B=B2, C_p=C1, E_p=D12, C=C2, F_p=D21)
    return plant, (A, B1, B2, C1, C2)


@pytest.mark.parametrize("seed", [3, 11])
def test_lti_limit_matches_riccati_optimum_and_constructs(seed):
    """No parameter block: γ_a of Thm 5.15 on the Tustin plant = continuous DGKF optimum; the
    controller constructed at 1.2 γ_a (via Γ for the discrete F_3 ≠ 0) achieves ≤ 1.2 γ_a and > γ_opt."""
    Pc, mats = dgkf_plant(seed)
    g_ref = dgkf_gamma(*mats)
    Pd = bilinear_lft(Pc, 0.05)
    assert np.abs(Pd.F_3).max() > 1e-6  # Tustin creates u -> y feedthrough: exercise Γ (Example 2.22)
    Pp, F3 = remove_feedthrough(Pd)
    b = bisect_gamma(Pp, ParameterSet.empty(), rtol=1e-3)
    assert b.gamma_a == pytest.approx(g_ref, rel=0.02)
    g = 1.2 * b.gamma_a
    res = SynthesisProblem(Pp, ParameterSet.empty(), scaling=b.scaling).centered(g)
    assert res.feasible and all(v < 0 for k, v in res.residuals.items() if k != "(5.60)")
    K = construct_controller(res, feedthrough=F3)
    rep = verify(Pd, K, g, [np.zeros((0, 0))], tv_steps=400)
    assert rep.passed
    # nothing beats the optimum: the achieved norm lies between γ_opt and the design γ
    assert g_ref * (1 - 1e-3) <= rep.max_frozen_hinf <= g * (1 + 1e-3)


def random_lpv(rng: np.random.Generator, cplx: bool, dt: float = 0.1) -> LFTPlant:
    def r(m, n, s=1.0):
        X = rng.standard_normal((m, n))
        if cplx:
            X = X + 1j * rng.standard_normal((m, n))
        return s * X

    n = 2
    A = r(n, n)
    A = 0.7 * A / max(abs(np.linalg.eigvals(A)))
    return LFTPlant.from_blocks(
        A, B_u=r(n, 1, 0.5), B_p=np.hstack([r(n, 1), np.zeros((n, 1))]), B=r(n, 1),
        C_u=r(1, n, 0.5), D_uu=r(1, 1, 0.1), D_up=np.zeros((1, 2)), E_u=r(1, 1, 0.2),
        C_p=np.vstack([r(1, n), np.zeros((1, n))]), D_pu=np.zeros((2, 1)), D_pp=np.zeros((2, 2)),
        E_p=np.array([[0.0], [0.5]]), C=r(1, n), F_u=r(1, 1, 0.2), F_p=np.array([[0.0, 1.0]]), dt=dt,
    )  # fmt: skip


def test_complex_formed_restriction_loses_nothing():
    """Cor. 5.33: γ_a (complex Hermitian ≡ complex-formed real variables) = γ_a of the real form (unrestricted)."""
    rng = np.random.default_rng(7)
    P = random_lpv(rng, cplx=True)
    ps = ParameterSet.interval(1)
    ga_c = bisect_gamma(P, ps, rtol=1e-3).gamma_a
    Pr = lft_real_form(P)
    assert not np.iscomplexobj(Pr.M)
    ps_r = ParameterSet((real_form(-np.eye(1)), real_form(np.eye(1))), None)  # Δ I_2
    ga_r = bisect_gamma(Pr, ps_r, rtol=1e-3).gamma_a
    assert ga_c == pytest.approx(ga_r, rel=0.02)
    # and the parameter variation matters at all (else this test would be vacuous)
    ga_0 = bisect_gamma(P, ParameterSet((np.zeros((1, 1)),), None), rtol=1e-3).gamma_a
    assert ga_0 < 0.98 * ga_c


def test_lpv_design_end_to_end_and_residuals():
    """A random complex LPV plant: solution re-checks negative, the controller verifies at γ."""
    rng = np.random.default_rng(5)
    P = random_lpv(rng, cplx=True)
    ps = ParameterSet.interval(1)
    b = bisect_gamma(P, ps, rtol=2e-3)
    g = 1.15 * b.gamma_a
    res = SynthesisProblem(P, ps, scaling=b.scaling).centered(g)
    assert res.feasible
    # independent numpy evaluation of (5.59)-(5.62) at the returned point
    again = lmi_residuals(res.plant, ps, res.X, res.Y, res.P, res.Pt, res.gamma_scaled)
    scale = max(1.0, np.linalg.norm(res.X, 2), np.linalg.norm(res.Y, 2))
    assert all(v < 0 for k, v in again.items() if k != "(5.60)") and again["(5.60)"] <= 1e-6 * scale  # non-strict
    K = construct_controller(res)
    rep = verify(P, K, g, ps.grid(21), tv_steps=500, tv_iter=15)
    assert rep.passed and rep.max_frozen_hinf <= g
    # a γ below γ_a is reported infeasible
    assert not SynthesisProblem(P, ps, scaling=b.scaling).feasibility(0.8 * b.gamma_a).feasible


def test_decay_rate_margin():
    """5.4.4: β > 0 can only raise γ_a, and the frozen closed-loop spectral radius is < 1 − β."""
    rng = np.random.default_rng(5)
    P = random_lpv(rng, cplx=False)
    ps = ParameterSet.interval(1)
    beta = 0.25
    g0 = bisect_gamma(P, ps, rtol=2e-3).gamma_a
    bb = bisect_gamma(P, ps, rtol=2e-3, beta=beta)
    assert bb.gamma_a >= g0 * (1 - 5e-3)
    res = SynthesisProblem(P, ps, beta=beta, scaling=bb.scaling).centered(1.2 * bb.gamma_a)
    K = construct_controller(res)
    rho = max(max(abs(np.linalg.eigvals(frozen_closed_loop(P, K, D).A))) for D in ps.grid(11))
    assert rho < 1 - beta
    # without the margin the same plant's optimal loop is allowed slower poles (the margin did something)
    res0 = SynthesisProblem(P, ps, scaling=bb.scaling).centered(1.2 * g0)
    K0 = construct_controller(res0)
    rho0 = max(max(abs(np.linalg.eigvals(frozen_closed_loop(P, K0, D).A))) for D in ps.grid(11))
    assert rho0 < 1


def test_null_basis_and_parameter_set():
    M = np.array([[1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    N = null_basis(M)
    assert N.shape == (3, 1) and np.allclose(M @ N, 0) and np.allclose(N.T @ N, np.eye(1))
    ps = ParameterSet.interval(2, -1, 0.5)
    g = ps.grid(5)
    assert len(g) == 5 and np.allclose(g[0], -np.eye(2)) and np.allclose(g[-1], 0.5 * np.eye(2))
    gen = ParameterSet((np.diag([1.0, -1.0]), np.diag([-1.0, 1.0]), np.eye(2)), None)
    pts = gen.grid(9)
    assert len(pts) > 3 and all(p.shape == (2, 2) for p in pts)


def test_rejects_bad_plants():
    rng = np.random.default_rng(1)
    P = random_lpv(rng, cplx=False)
    with pytest.raises(ValueError, match="discrete"):
        SynthesisProblem(P.with_matrix(P.M).__class__(**{**P.__dict__, "dt": None}), ParameterSet.interval(1))
    bad = P.with_matrix(P.M.copy())
    bad.M[-1, -1] = 0.3  # F_3 ≠ 0
    with pytest.raises(ValueError, match="F_3"):
        SynthesisProblem(bad, ParameterSet.interval(1))
    with pytest.raises(ValueError, match="generators"):
        SynthesisProblem(P, ParameterSet.interval(2))


def test_hinf_norm_helper_against_analytic():
    """The verification's sweep: real G = b/(z − a) peaks at z = 1; complex a peaks at z = e^{j arg a}."""
    from synthesis.lft import StateSpace

    S = StateSpace([[0.9]], [[0.5]], [[1.0]], [[0.0]], 0.01)
    assert hinf_norm(S)[0] == pytest.approx(0.5 / 0.1, rel=1e-6)
    a = 0.95 * np.exp(0.3j)
    Sc = StateSpace([[a]], [[1.0]], [[1.0]], [[0.0]], 0.01)
    val, th = hinf_norm(Sc)
    assert val == pytest.approx(1 / 0.05, rel=1e-4) and th == pytest.approx(0.3, abs=1e-3)
    Sm = StateSpace([[np.conj(a)]], [[1.0]], [[1.0]], [[0.0]], 0.01)  # negative frequency
    assert hinf_norm(Sm)[1] == pytest.approx(-0.3, abs=1e-3)


def test_diagonal_parameter_set_and_multipliers():
    """Ch. 7 hooks: ParameterSet.diagonal has the 2^n vertices and a tensor grid; diagonal multipliers are
    diagonal and cannot beat full-block ones."""
    ps = ParameterSet.diagonal(2, -1.0, [1.0, 0.5])
    assert len(ps.generators) == 4 and ps.shape == (2, 2)
    assert {tuple(np.diag(g)) for g in ps.generators} == {(-1, -1), (-1, 0.5), (1, -1), (1, 0.5)}
    pts = ps.grid(25)
    assert len(pts) == 25 and all(np.count_nonzero(p - np.diag(np.diag(p))) == 0 for p in pts)
    with pytest.raises(ValueError, match="lo <= hi"):
        ParameterSet.diagonal(2, 1.0, -1.0)
    rng = np.random.default_rng(5)
    P = random_lpv(rng, cplx=False)
    p1 = ParameterSet.diagonal(1)
    gd = bisect_gamma(P, p1, rtol=2e-3, multipliers="diagonal")
    gf = bisect_gamma(P, p1, rtol=2e-3)
    assert gf.gamma_a <= gd.gamma_a * (1 + 5e-3)
    r = gd.result
    assert np.count_nonzero(r.P - np.diag(np.diag(r.P))) == 0 and np.count_nonzero(r.Pt - np.diag(np.diag(r.Pt))) == 0
    with pytest.raises(ValueError, match="diagonal multipliers"):
        SynthesisProblem(random_lpv(rng, cplx=True), p1, multipliers="diagonal")
