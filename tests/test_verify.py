"""Tests for synthesis.verify: the independent checks pass good controllers and reject perturbed ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from synthesis.construct import ScheduledController, construct_controller
from synthesis.lft import LFTController, StateSpace
from synthesis.lmi import ParameterSet, SynthesisProblem, bisect_gamma
from synthesis.verify import (
    VerificationError,
    analysis_lmi_gamma,
    frozen_closed_loop,
    hinf_norm,
    tv_energy_gain,
    verify,
)
from tests.test_construct import small_lpv

# LMIWarning (optimal_inaccurate, re-checked) and scipy ill-conditioning notes are expected here
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


@pytest.fixture(scope="module")
def design():
    P = small_lpv(True)
    ps = ParameterSet.interval(1)
    b = bisect_gamma(P, ps, rtol=3e-3)
    g = 1.2 * b.gamma_a
    res = SynthesisProblem(P, ps, scaling=b.scaling).centered(g)
    return P, ps, g, construct_controller(res)


def test_good_controller_passes(design):
    P, ps, g, K = design
    rep = verify(P, K, g, ps.grid(21), tv_steps=600, tv_iter=15)
    assert rep.passed and all(rep.checks.values())
    assert rep.max_spectral_radius < 1
    assert rep.max_frozen_hinf <= g and rep.lmi_gamma <= g * (1 + 1e-3) and rep.tv_gain <= g
    # the common-𝒳 LMI bound can never be below the frozen norms it bounds
    assert rep.lmi_gamma >= rep.max_frozen_hinf * (1 - 1e-3)


def _perturb(K: ScheduledController, block: str, factor: complex) -> ScheduledController:
    M = K.K.M.copy()
    Kp = LFTController(M, K.K.n_c, K.K.n_u, K.K.n_zc, K.K.n_y, K.K.n_wc, K.K.dt)
    r = Kp._rows[{"A_c": 0, "C_c1": 1, "D_c11": 1, "B_c1": 0}[block]]
    c = Kp._cols[{"A_c": 0, "C_c1": 0, "D_c11": 1, "B_c1": 1}[block]]
    M[r, c] *= factor
    return dataclasses.replace(K, K=dataclasses.replace(Kp, M=M))


@pytest.mark.parametrize("block,factor", [("D_c11", 1.6), ("C_c1", -1.0), ("A_c", 1.8)])
def test_perturbed_controller_raises(design, block, factor):
    P, ps, g, K = design
    Kp = _perturb(K, block, factor)
    with pytest.raises(VerificationError):
        verify(P, Kp, g, ps.grid(21), tv_steps=300, tv_iter=10, lmi_points=7)
    rep = verify(P, Kp, g, ps.grid(21), tv_steps=0, lmi_points=0, raise_on_fail=False)
    assert not rep.passed


def test_scheduling_matters(design):
    """Replacing Δ_c(Δ) by its value at Δ = 0 (an LTI controller) must be caught on the grid."""
    P, ps, g, K = design
    frozen_dc = K.delta_c(np.zeros((1, 1)))

    class Unscheduled:
        def __init__(self):
            self.K = K.K

        def delta_c(self, D):
            return frozen_dc

    rep = verify(P, Unscheduled(), g, ps.grid(21), tv_steps=300, tv_iter=10, raise_on_fail=False)
    good = verify(P, K, g, ps.grid(21), tv_steps=0, lmi_points=0, raise_on_fail=False)
    assert rep.max_frozen_hinf > good.max_frozen_hinf


def test_lti_checks_agree_with_the_norm():
    """For one LTI system the analysis LMI (bounded-real lemma) gives its H∞ norm and the power
    iteration over a long horizon approaches it from below."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((3, 3))
    A = 0.9 * A / max(abs(np.linalg.eigvals(A)))
    S = StateSpace(A, rng.standard_normal((3, 2)), rng.standard_normal((1, 3)), 0.1 * rng.standard_normal((1, 2)), 0.01)
    h, _ = hinf_norm(S)
    g, status = analysis_lmi_gamma([S], gamma_ref=h)
    assert g == pytest.approx(h, rel=2e-3)

    class Wrap:  # a "closed loop" with no parameter: plant = S, no controller
        K = LFTController(np.zeros((0, 0)), 0, 0, 0, 0, 0, 0.01)

        @staticmethod
        def delta_c(D):
            return np.zeros((0, 0))

    from synthesis.lft import LFTPlant

    P = LFTPlant.from_blocks(S.A, B_p=S.B, C_p=S.C, D_pp=S.D, B=np.zeros((3, 0)), C=np.zeros((0, 3)), dt=0.01)
    assert np.allclose(frozen_closed_loop(P, Wrap(), np.zeros((0, 0))).A, S.A)
    tv = tv_energy_gain(P, Wrap(), [np.zeros((0, 0))], np.zeros(2000, dtype=int), n_iter=40)
    assert 0.9 * h <= tv <= h * (1 + 1e-9)


def test_analysis_lmi_does_not_depend_on_how_the_states_are_scaled():
    """A controller's states can be scaled 1e5 x the plant's (the thesis-reading flux observer at 100 rad/s and
    600 Hz): the same two systems under diagonal similarities must give the same common-𝒳 γ (it failed at 1e5
    before the exact power-of-two balancing of A), and that γ is not below their frozen norms."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((4, 4))
    A = 0.99 * A / max(abs(np.linalg.eigvals(A)))
    B, C, D = rng.standard_normal((4, 2)), rng.standard_normal((1, 4)), 0.1 * rng.standard_normal((1, 2))
    A2 = A.copy()
    A2[0, 1] += 0.01
    systems = [StateSpace(A, B, C, D, 0.01), StateSpace(A2, B, C, D, 0.01)]
    h = max(hinf_norm(s)[0] for s in systems)
    ref, _ = analysis_lmi_gamma(systems, gamma_ref=h)
    assert h <= ref < 1.1 * h
    for k in (1e3, 1e5, 1e6):
        s = np.array([1.0, k, 1.0 / k, 1.0])
        scaled = [StateSpace(x.A * (s[None, :] / s[:, None]), x.B / s[:, None], x.C * s[None, :], x.D, 0.01)
                  for x in systems]  # fmt: skip
        g, status = analysis_lmi_gamma(scaled, gamma_ref=h)
        assert g == pytest.approx(ref, rel=1e-6), (k, status)
