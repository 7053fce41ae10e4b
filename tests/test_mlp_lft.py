"""MLP -> quasi-LPV LFT (thesis 6.3): tanh sector bounds, centring, exactness of the LFT, gain uncertainty."""

from __future__ import annotations

import math

import numpy as np
import pytest

from synthesis.mlp_lft import (
    equilibrium,
    gain_uncertainty,
    mlp_to_lft,
    secant,
    sector_bounds,
    tangent_point,
    xi_b_thesis,
)
from synthesis.narx import Dataset, MLPWeights, NarxModel, Orders, Scaling, regressors

SC = Scaling(0.0, 1.8, 1.8, 0.0, 130.0, 0.6, 0.8, 5.7, 3.8)


def sigma_p(b, xi):
    return np.tanh(xi + b) - np.tanh(b)


@pytest.mark.parametrize("b", [0.0, 0.05, 0.4, 1.3, 2.5, -0.7, -2.0])
@pytest.mark.parametrize("rng_", [(-0.3, 0.2), (-3.0, 1.0), (-0.01, 4.0), (-6.0, 6.0), (0.5, 2.0)])
def test_sector_bounds_hold_pointwise_on_a_dense_grid_and_are_tight(b, rng_):
    lo, hi = rng_
    k_min, k_max = sector_bounds(b, lo, hi)
    xi = np.linspace(lo, hi, 200_001)
    xi = xi[xi != 0]
    s = sigma_p(b, xi)
    tol = 1e-13
    # (6.23): k_min xi^2 <= sigma'(xi) xi <= k_max xi^2 at every point
    assert np.all(s * xi >= k_min * xi**2 - tol)
    assert np.all(s * xi <= k_max * xi**2 + tol)
    # tight: the grid comes within its resolution of both bounds (away from 0, where s/xi cancels)
    far = np.abs(xi) > 1e-4
    g = s[far] / xi[far]
    assert g.min() == pytest.approx(k_min, abs=1e-8)
    assert g.max() == pytest.approx(k_max, abs=1e-8)


def test_secant_is_accurate_near_zero_and_continuous():
    for b in (0.0, 0.3, -1.7):
        xi = np.array([-1e-3, -1e-7, 0.0, 1e-7, 1e-3])
        g = secant(b, xi)
        assert g[2] == pytest.approx(1 - math.tanh(b) ** 2, abs=1e-15)
        mp = [float((math.tanh(x + b) - math.tanh(b)) / x) for x in (-1e-3, 1e-3)]
        np.testing.assert_allclose(g[[0, 4]], mp, rtol=1e-10)
        assert abs(g[1] - g[2]) < 1e-6 and abs(g[3] - g[2]) < 1e-6


def test_tangent_point_is_where_the_line_through_the_origin_touches_and_matches_the_thesis_fit():
    for b in np.linspace(0.02, 3.0, 60):
        xb = tangent_point(b)
        assert xb < -b  # left of the inflection point of tanh(xi + b)
        # tangency: the slope of sigma' at xb equals the secant slope through the origin
        assert 1 - math.tanh(xb + b) ** 2 == pytest.approx(float(secant(b, xb)), abs=1e-12)
        # the secant slope is maximal there
        xi = np.linspace(xb - 2, xb + 2, 40001)
        assert float(secant(b, xb)) >= secant(b, xi).max() - 1e-14
        # the thesis' polynomial gives k_max with errors "of the order 1e-5" (6.3.2): measured <= 4.0e-5
        assert abs(float(secant(b, xi_b_thesis(b))) - float(secant(b, xb))) < 5e-5
        assert tangent_point(-b) == -xb
    assert tangent_point(0.0) == 0.0


def random_model(o: Orders, seed: int, scale: float = 0.5) -> NarxModel:
    rng = np.random.default_rng(seed)
    l = 4
    mlp = MLPWeights(rng.standard_normal((l, o.dim)) * scale, rng.standard_normal(l) * 0.5, rng.standard_normal((1, l)) * 0.4)
    mlp.Theta1[:, : o.n] *= 0.3
    return NarxModel(o, SC, mlp, rng.standard_normal((1, o.dim)), 1 / 600)


def random_data(model: NarxModel, seed: int, N: int = 3000) -> Dataset:
    """Inputs random, speed from the model itself plus noise (so the ranges are those of a plausible set)."""
    rng = np.random.default_rng(seed)
    o = model.orders
    i, d, tau = (rng.standard_normal(N) for _ in range(3))
    w = np.zeros(N)
    for k in range(o.lag - 1, N - 1):
        z = np.concatenate([w[k - np.arange(o.n)], i[k - np.arange(o.n_i)], d[k - np.arange(o.n_u)], tau[k - np.arange(o.n_u)]])
        w[k + 1] = float(model.mlp.predict(z)) + 0.01 * rng.standard_normal()
    return Dataset(w, i, d, tau, SC)


@pytest.mark.parametrize("orders", [Orders(4, 1, 2), Orders(3, 2, 3), Orders(2, 0, 1)])
def test_lft_reproduces_the_mlp_predictions_exactly(orders):
    model = random_model(orders, 1)
    ds = random_data(model, 2)
    lft = mlp_to_lft(model, [ds])
    P = lft.plant
    assert P.dt == 1 / 600 and P.n_wu == P.n_zu == 4 and P.n_u == 3 and P.n_y == 1 and P.n_wp == P.n_zp == 0
    assert np.all(P.F_3 == 0) and np.all(P.D_uu == 0)
    Z, y = regressors(ds, orders)
    pred = model.mlp.predict(Z)
    o = orders
    errs = []
    for k in range(o.lag - 1, len(ds) - 1, 37):  # z_{k+1} is row k - lag + 1
        x = lft.state_from_history(ds.w[k::-1], ds.i[k - 1 :: -1] if k >= 1 else [], ds.d[k - 1 :: -1], ds.tau[k - 1 :: -1])
        u = np.array([ds.i[k], ds.d[k], ds.tau[k]]) - lft.u0
        x_next, y_k = lft.step(x, u)
        errs.append(x_next[0] + lft.w0 - pred[k - o.lag + 1])
        assert y_k + lft.w0 == pytest.approx(ds.w[k], abs=1e-12)
        # the delay states shift as the state definition says
        x_want = lft.state_from_history(np.r_[pred[k - o.lag + 1], ds.w[k::-1]], ds.i[k::-1], ds.d[k::-1], ds.tau[k::-1])
        np.testing.assert_allclose(x_next[1:], x_want[1:], atol=1e-12)
    assert np.max(np.abs(errs)) < 1e-12


def test_free_run_of_the_lft_equals_the_mlp_free_run():
    from synthesis.narx import free_run

    o = Orders(4, 1, 2)
    model = random_model(o, 3)
    ds = random_data(model, 4, 800)
    lft = mlp_to_lft(model, [ds])
    sim, _ = free_run(model, ds, "mlp")
    k = o.lag - 1
    x = lft.state_from_history(ds.w[k::-1], ds.i[k - 1 :: -1], ds.d[k - 1 :: -1], ds.tau[k - 1 :: -1])
    out = []
    for kk in range(k, len(ds) - 1):
        x, _ = lft.step(x, np.array([ds.i[kk], ds.d[kk], ds.tau[kk]]) - lft.u0)
        out.append(x[0] + lft.w0)
    np.testing.assert_allclose(out, sim, atol=1e-10)


def test_equilibrium_and_centring():
    o = Orders(4, 1, 2)
    model = random_model(o, 5)
    ds = random_data(model, 6)
    lft = mlp_to_lft(model, [ds], eps=1e-6)
    # the equilibrium is a fixed point of the MLP
    z0 = np.r_[np.full(4, lft.w0), 0.0, 0.0, 0.0, 0.0, 0.0]
    assert float(model.mlp.predict(z0)) == pytest.approx(lft.w0, abs=1e-13)
    assert equilibrium(model) == lft.w0
    # after the shift sigma'(0) = 0 and Theta_o sigma(theta_b) reproduces w0
    assert np.all(lft.sigma_prime(np.zeros((1, 4))) == 0)
    assert float((lft.Theta_o @ np.tanh(lft.theta_b))[0]) == pytest.approx(lft.w0, abs=1e-13)
    # gains sorted by decreasing width; every residual gain in (-1, 1) on its active range (6.28)
    assert np.all(np.diff(lft.widths) <= 0)
    for j in range(4):
        xi = np.linspace(lft.xi_min[j], lft.xi_max[j], 50001)
        g = lft.gain(j, xi)
        assert np.all(np.abs(g) < 1.0)
        assert np.abs(g).max() > 0.99  # and they use the sector: tight up to eps
    # (6.25)-(6.27) by hand for the first row
    c = 0.5 * (lft.k_min + lft.k_max)
    h = 0.5 * (lft.k_max - lft.k_min) + lft.eps
    np.testing.assert_allclose(lft.plant.B_u[0], (lft.Theta_o * h)[0])
    np.testing.assert_allclose(lft.plant.A[0], ((lft.Theta_o * c) @ lft.plant.C_u)[0])
    np.testing.assert_allclose(lft.plant.B[0], ((lft.Theta_o * c) @ lft.plant.E_u)[0])


def test_keep_the_widest_gains_drops_the_others_at_their_sector_centre():
    o = Orders(4, 1, 2)
    model = random_model(o, 7)
    ds = random_data(model, 8)
    lft = mlp_to_lft(model, [ds])
    two = lft.widest(2)
    assert two.plant.n_wu == 2 and list(two.widths) == list(lft.widths[:2])
    assert list(two.neurons) == list(lft.neurons[:2])
    # with the two narrow gains at their centre the model differs from the MLP by those gains' terms only
    x = lft.state_from_history(ds.w[10::-1], ds.i[9::-1], ds.d[9::-1], ds.tau[9::-1])
    u = np.array([ds.i[10], ds.d[10], ds.tau[10]]) - lft.u0
    full, _ = lft.step(x, u)
    red, _ = two.step(x, u)
    xi = lft.xi(x, u)
    dropped = float(sum(lft.plant.B_u[0, j] * lft.Omega(xi[None, :])[0, j] for j in (2, 3)))
    assert full[0] - red[0] == pytest.approx(dropped, abs=1e-12)


def test_gain_uncertainty_bound_holds_for_random_noise_and_scales_with_it():
    o = Orders(4, 1, 2)
    model = random_model(o, 9)
    ds = random_data(model, 10)
    lft = mlp_to_lft(model, [ds])
    assert np.all(gain_uncertainty(lft, 0.0) == 0)
    b1, b2 = gain_uncertainty(lft, 0.5), gain_uncertainty(lft, 1.0)
    assert np.all(b1 > 0) and np.all(b2 > b1)
    # Monte Carlo: speed taps off by at most 0.5 rad/s never change a gain by more than the bound
    rng = np.random.default_rng(11)
    eta_w = 0.5 / SC.sigma_omega
    for j in range(4):
        xi = rng.uniform(lft.xi_min[j], lft.xi_max[j], 20000)
        noise = rng.uniform(-eta_w, eta_w, (20000, o.n))
        d_xi = noise @ lft.Theta_xi[j, : o.n]
        change = np.abs(lft.gain(j, xi + d_xi) - lft.gain(j, xi))
        assert change.max() <= b1[j] * (1 + 1e-6)


def test_lft_rebuilt_from_the_model_artifact_equals_the_one_from_the_data(tmp_path):
    from synthesis.mlp_lft import lft_from_model
    from synthesis.narx import load_model, save_model

    o = Orders(4, 1, 2)
    model = random_model(o, 12)
    ds = random_data(model, 13)
    lft = mlp_to_lft(model, [ds])
    save_model(tmp_path / "m", model, {"lft": lft.summary()})
    again = lft_from_model(load_model(tmp_path / "m"))
    np.testing.assert_array_equal(again.plant.M, lft.plant.M)
    np.testing.assert_array_equal(again.neurons, lft.neurons)
    np.testing.assert_array_equal(again.widths, lft.widths)
    assert again.plant.dt == lft.plant.dt and again.w0 == lft.w0
    with pytest.raises(ValueError, match="no LFT ranges"):
        lft_from_model(model)
