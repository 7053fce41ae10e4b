"""Independent lower bounds (synthesis.lower_bound): closed-form H∞ optima, duality, discretisation invariance,
and the flux-observer bound below every shipped/verified γ."""

from __future__ import annotations

import glob
import math

import numpy as np
import pytest

from synthesis.discretize import bilinear_lti
from synthesis.lft import StateSpace
from synthesis.lower_bound import (
    cayley_to_continuous,
    frozen_plant,
    hinf_norm,
    hinf_optimal_gamma,
    lpv_lower_bound,
)


def _filter_plant(a: float, sigma: float, w0: float = 0.0) -> StateSpace:
    """ẋ = (a + jω0) x + w_1, y = x + σ w_2, z = u − x: estimate x from a noisy measurement.

    Closed form: at each frequency the best estimate of G w_1 from G w_1 + σ w_2 leaves
    σ|G|/√(σ² + |G|²), largest where |G| = 1/|a| (ω = ω0); the H∞ filter Riccati
    2aY + (γ^{-2} − σ^{-2})Y² + 1 = 0 has a real root iff γ ≥ σ/√(1 + a²σ²) -- the same number.
    """
    A = np.array([[a + 1j * w0]]) if w0 else np.array([[a]])
    B = np.array([[1.0, 0.0, 0.0]])
    C = np.array([[-1.0], [1.0]])
    D = np.array([[0.0, 0.0, 1.0], [0.0, sigma, 0.0]])
    return StateSpace(A, B, C, D)


@pytest.mark.parametrize("a,sigma,w0", [(-1.0, 1.0, 0.0), (-2.0, 0.3, 0.0), (-1.0, 0.5, 5.0), (-50.0, 1e-3, 0.0)])
def test_filter_closed_form(a: float, sigma: float, w0: float) -> None:
    exact = sigma / math.sqrt(1.0 + a * a * sigma * sigma)
    g = hinf_optimal_gamma(_filter_plant(a, sigma, w0), 1, 2, rtol=1e-7)
    assert exact <= g <= exact * (1 + 2e-6)


@pytest.mark.parametrize("Ts", [1.0 / 3000.0, 0.01, 0.5])
def test_discrete_optimum_equals_continuous(Ts: float) -> None:
    """Tustin maps the frequency axis onto the unit circle: the optimum must not change (Cayley path)."""
    sys = _filter_plant(-2.0, 0.3)
    exact = 0.3 / math.sqrt(1.0 + 4.0 * 0.09)
    g = hinf_optimal_gamma(bilinear_lti(sys, Ts), 1, 2, rtol=1e-7)
    assert exact <= g <= exact * (1 + 2e-6)


def test_cayley_preserves_frequency_response() -> None:
    rng = np.random.default_rng(3)
    A = 0.5 * rng.standard_normal((3, 3)) / 3
    sys = StateSpace(A, rng.standard_normal((3, 2)), rng.standard_normal((2, 3)), rng.standard_normal((2, 2)), 0.1)
    c = cayley_to_continuous(sys)
    for th in (0.1, 1.0, 2.5):
        nu = math.tan(th / 2)
        assert np.allclose(c.evaluate(1j * nu), sys.evaluate(np.exp(1j * th)), atol=1e-10)


def test_dual_problem_same_optimum() -> None:
    """The transposed plant (a control problem: B_2 ≠ 0, the X Riccati does the work) has the same optimum."""
    sys = _filter_plant(-2.0, 0.3)
    # reorder to the transposed generalised plant: inputs [z-dual; y-dual] ↔ outputs [w-dual; u-dual]
    T = StateSpace(sys.A.T, sys.C.T, sys.B.T, sys.D.T)
    g = hinf_optimal_gamma(sys, 1, 2, rtol=1e-7)
    gt = hinf_optimal_gamma(T, 2, 1, rtol=1e-7)
    assert gt == pytest.approx(g, rel=1e-6)


def test_lower_bound_below_a_stabilising_controller() -> None:
    """Any fixed stabilising controller's closed-loop norm is ≥ γ_opt; the static optimum k = 1/(1+σ²) of
    the memoryless problem (a = −∞ limit) is not optimal for a = −1, so the bound must be strictly smaller."""
    a, s = -1.0, 1.0
    sys = _filter_plant(a, s)
    g = hinf_optimal_gamma(sys, 1, 2, rtol=1e-7)
    for k in (0.2, 0.5, 0.8):  # u = k y: z = (k−1) x + kσ w_2, x = w_1/(s − a)
        cl = StateSpace(np.array([[a]]), np.array([[1.0, 0.0]]), np.array([[k - 1.0]]), np.array([[0.0, k * s]]))
        assert hinf_norm(cl) >= g * (1 - 1e-6)


def test_flux_observer_lower_bounds() -> None:
    """Both readings of 5.6.1 at ω_r,max = 200: the worst frozen point is ω_r = 0 (Δ = 0), values as in issue 12."""
    from synthesis.models.motor import flux_observer_plant_discrete

    grid = [np.array([[d]]) for d in np.linspace(-1, 1, 5)]
    full = lpv_lower_bound(flux_observer_plant_discrete(200.0, variant="full"), grid)
    thesis = lpv_lower_bound(flux_observer_plant_discrete(200.0, variant="partial"), grid)
    assert full.value == pytest.approx(1.961e-5, rel=2e-3)
    assert thesis.value == pytest.approx(9.957e-5, rel=2e-3)
    assert float(np.real(full.delta_worst[0, 0])) == 0.0
    # the frozen bound at Δ = 0 does not depend on ω_r,max (ω_r enters only through Δ·ω_r,max)
    other = lpv_lower_bound(flux_observer_plant_discrete(400.0, variant="full"), [np.zeros((1, 1))])
    assert other.value == pytest.approx(full.value, rel=1e-4)


def test_shipped_flux_observer_respects_lower_bound() -> None:
    """The verified shipped observer's frozen closed-loop norm cannot beat the frozen optimum."""
    from synthesis.artifacts import load_controller
    from synthesis.models.motor import flux_observer_plant_discrete
    from synthesis.verify import frozen_closed_loop
    from synthesis.verify import hinf_norm as vnorm

    path = sorted(glob.glob("bench/controllers/artifacts/flux_observer_*rad_3000Hz.json"))[0]
    ctrl, doc = load_controller(path)
    meta = doc["meta"]
    P = flux_observer_plant_discrete(float(meta["omega_r_max"]), variant=meta["variant"])
    D0 = np.zeros((1, 1))
    norm0 = vnorm(frozen_closed_loop(P, ctrl, D0))[0]
    lb = lpv_lower_bound(P, [D0]).value
    assert norm0 >= lb
    assert frozen_plant(P, D0).n_inputs == P.n_wp + P.n_u


# --------------------------------------------------------------------------------------------------
# the synthesis reaches the bounds (issue 12)
# --------------------------------------------------------------------------------------------------
def test_balance_from_solution_balances() -> None:
    """x = T x': X' = T^* X T and Y' = T^{-1} Y T^{-*} come out equal and diagonal; d equalises ‖P‖, ‖P̃‖."""
    from synthesis.lmi import PlantScaling, balance_from_solution

    rng = np.random.default_rng(0)
    G = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    H = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    X, Y = G @ G.conj().T + 1e3 * np.eye(3), H @ H.conj().T + 1e-2 * np.eye(3)
    sc = balance_from_solution(PlantScaling(np.array([2.0, 1.0, 0.5]), 1.0, 1.0), X, Y, 1e6 * np.eye(2), np.eye(2))
    T0 = np.diag([2.0, 1.0, 0.5])
    Tb = np.linalg.solve(T0, sc.T)  # the similarity applied on top of T0 (X, Y are in the T0 coordinates)
    Xb = Tb.conj().T @ X @ Tb
    Yb = np.linalg.solve(Tb, np.linalg.solve(Tb, Y).conj().T).conj().T
    assert np.allclose(Xb, Yb, rtol=1e-8, atol=1e-8 * np.abs(Xb).max())
    assert np.allclose(Xb, np.diag(np.diag(Xb)), atol=1e-8 * np.abs(Xb).max())
    assert sc.d == pytest.approx(1e6**0.25)


@pytest.mark.parametrize("omega_max", [400.0, 10.0])
def test_flux_observer_reaches_lower_bound_full(omega_max: float) -> None:
    """The project's reading: γ_a ≤ 1.01 x the certified bound -- at the shipped range (400 rad/s) and at 10 rad/s,
    where the re-balancing stalled at 13x until `bisect_gamma` escaped such stalls (its time: `bench perf
    synthesis`, not asserted here: a loaded machine is no slower synthesis)."""
    from synthesis.models.flux_observer import flux_gamma_a, flux_lower_bound
    from synthesis.models.motor import flux_observer_plant_discrete

    lb = flux_lower_bound(flux_observer_plant_discrete(omega_max)).value
    b = flux_gamma_a(omega_max, lower_bound=lb)
    assert lb <= b.gamma_a <= 1.01 * lb


def test_current_controller_reaches_lower_bound() -> None:
    """Current controller 6.2.2 at 600 Hz (causal discretisation): γ_a ≤ 1.01 x the frozen-grid bound."""
    from synthesis.lmi import bisect_gamma
    from synthesis.models.current_controller import CurrentSpec, current_plant_discrete, delta_grid, parameter_set

    P = current_plant_discrete(CurrentSpec(rate_hz=600.0))
    lb = lpv_lower_bound(P, delta_grid(5)).value
    b = bisect_gamma(P, parameter_set(), lower_bound=lb)
    assert lb <= b.gamma_a <= 1.01 * lb


def test_switching_bound_reproduces_the_frozen_optimum_from_below() -> None:
    """The Krein-space (a posteriori H∞ filter) recursion of `switching_filter_lower_bound` is a second, independent
    route to the frozen optimum: for a constant ω_r = 0 it approaches the Cayley/Glover-Doyle value from below
    (flux observer, thesis' reading, at T_s = 10 ms so that 1000 samples reach steady state)."""
    from synthesis.lower_bound import switching_filter_lower_bound
    from synthesis.models.motor import flux_observer_plant_discrete

    P = flux_observer_plant_discrete(400.0, Ts=0.01, variant="partial")
    frozen = lpv_lower_bound(P, [np.zeros((1, 1))], rtol=1e-6).value
    short = switching_filter_lower_bound(P, [np.zeros((1, 1))], repeats=300, rtol=1e-5)
    long = switching_filter_lower_bound(P, [np.zeros((1, 1))], repeats=1000, rtol=1e-5)
    assert short < long <= frozen * (1 + 1e-5)
    assert long >= 0.995 * frozen
    with pytest.raises(ValueError, match="filtering"):  # a control problem (u drives the state) is refused
        from synthesis.models.current_controller import CurrentSpec, current_plant_discrete

        switching_filter_lower_bound(current_plant_discrete(CurrentSpec()), [np.zeros((2, 2))], repeats=1)
