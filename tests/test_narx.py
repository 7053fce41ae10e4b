"""NARX identification (thesis 6.4.2): regressors, ARX by least squares, MLP init and LM training, artifacts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative

from synthesis.artifacts import ArtifactError
from synthesis.narx import (
    Dataset,
    MLPWeights,
    NarxModel,
    Orders,
    Scaling,
    fit_arx,
    free_run,
    init_from_arx,
    load_model,
    metrics,
    regressors,
    residual_autocorrelation,
    save_model,
    torch_jacobian,
    train_lm,
)

UNIT = Scaling(0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0)


def dataset(w, i, d, tau, scaling=UNIT) -> Dataset:
    return Dataset(np.asarray(w, float), np.asarray(i, float), np.asarray(d, float), np.asarray(tau, float), scaling)


def simulate(predict, o: Orders, i, d, tau, noise=None) -> np.ndarray:
    """w_{k+1} = predict(z_{k+1}) driven by the inputs, from w = 0; optional output noise in the regressor."""
    N = len(i)
    w = np.zeros(N)
    for k in range(o.lag - 1, N - 1):
        z = np.concatenate([w[k - np.arange(o.n)], i[k - np.arange(o.n_i)], d[k - np.arange(o.n_u)], tau[k - np.arange(o.n_u)]])
        w[k + 1] = predict(z) + (0.0 if noise is None else noise[k + 1])
    return w


def stable_arx(o: Orders, rng) -> np.ndarray:
    """A stable AR part (poles inside 0.9) and random input gains, as one row M_l."""
    poles = 0.9 * rng.uniform(-1, 1, o.n)
    ar = -np.poly(poles)[1:]  # w_{k+1} = sum a_j w_{k+1-j} + ...
    return np.concatenate([ar, rng.standard_normal(o.dim - o.n) * 0.3]).reshape(1, -1)


def test_regressor_rows_follow_the_thesis_definition():
    o = Orders(3, 2, 2)
    N = 10
    w, i, d, tau = (np.arange(N) + off for off in (0.0, 100.0, 200.0, 300.0))
    Z, y = regressors(dataset(w, i, d, tau), o)
    assert Z.shape == (N - o.lag, o.dim) and y.shape == (N - o.lag,)
    # first row predicts w[3] from w[2], w[1], w[0], i[2], i[1], d[2], d[1], tau[2], tau[1]
    assert Z[0].tolist() == [2, 1, 0, 102, 101, 202, 201, 302, 301]
    assert y[0] == 3 and y[-1] == N - 1
    assert o.labels() == ["w[k]", "w[k-1]", "w[k-2]", "i[k]", "i[k-1]", "d[k]", "d[k-1]", "tau[k]", "tau[k-1]"]


def test_arx_recovers_a_known_linear_system_exactly():
    rng = np.random.default_rng(1)
    o = Orders(4, 1, 2)
    M_true = stable_arx(o, rng)
    N = 3000
    i, d, tau = (rng.standard_normal(N) for _ in range(3))
    w = simulate(lambda z: float(M_true[0] @ z), o, i, d, tau)
    Z, y = regressors(dataset(w, i, d, tau), o)
    M_l = fit_arx(Z, y)
    np.testing.assert_allclose(M_l, M_true, rtol=0, atol=1e-10)
    # the thesis' formula M_l = M_o M_i^+ gives the same gain
    np.testing.assert_allclose(y.reshape(1, -1) @ np.linalg.pinv(Z.T), M_l, atol=1e-10)
    # and the ARX free run then reproduces the noise-free data exactly
    model = NarxModel(o, UNIT, init_from_arx(M_l, 2), M_l, 1 / 600)
    sim, meas = free_run(model, dataset(w, i, d, tau), "arx")
    np.testing.assert_allclose(sim, meas, atol=1e-9)


def test_init_from_arx_is_the_arx_model_with_large_output_small_input_weights():
    rng = np.random.default_rng(2)
    M_l = rng.standard_normal((1, 9))
    w0 = init_from_arx(M_l, 4, scale=1e-3, seed=3)
    assert np.all(w0.Theta_b == 0)
    np.testing.assert_allclose(w0.Theta2 @ w0.Theta1, M_l, atol=1e-14)  # Theta2 Theta1 = M_l (6.4.2)
    assert np.abs(w0.Theta1).max() < 1e-2 and np.abs(w0.Theta2).min() > 100
    # all neurons differ (identical ones would stay identical under LM)
    assert np.linalg.matrix_rank(w0.Theta1) == 4
    Z = rng.standard_normal((500, 9))
    lin = Z @ M_l[0]
    np.testing.assert_allclose(w0.predict(Z), lin, atol=1e-4 * np.abs(lin).max())


def test_torch_jacobian_matches_autograd_forward_mode_and_finite_differences():
    import torch
    from torch.func import functional_call, jacfwd

    from synthesis.narx import NarxMLP

    rng = np.random.default_rng(4)
    Z = rng.standard_normal((200, 7))
    w = MLPWeights(rng.standard_normal((3, 7)) * 0.7, rng.standard_normal(3) * 0.5, rng.standard_normal((1, 3)))
    J = torch_jacobian(w, Z)
    Jfd = approx_derivative(lambda th: MLPWeights.from_vector(th, 7, 3).predict(Z), w.vector(), method="3-point")
    np.testing.assert_allclose(J, Jfd, atol=1e-8)
    model = NarxMLP(7, 3)
    Zt = torch.from_numpy(Z)

    def f(theta):
        a, b, c = torch.split(theta, (21, 3, 3))
        return functional_call(model, {"hidden.weight": a.reshape(3, 7), "hidden.bias": b, "out.weight": c.reshape(1, 3)}, (Zt,))

    np.testing.assert_allclose(J, jacfwd(f)(torch.from_numpy(w.vector())).numpy(), atol=1e-13)
    # and the module computes the same function as the numpy weights
    np.testing.assert_allclose(f(torch.from_numpy(w.vector())).detach().numpy(), w.predict(Z), atol=1e-14)


def teacher_problem(seed: int, noise: float, N: int = 1500):
    """Data from a known 3-neuron MLP NARX model with visible nonlinearity (|xi| up to ~2)."""
    rng = np.random.default_rng(seed)
    o = Orders(2, 1, 1)
    teacher = MLPWeights(rng.standard_normal((3, o.dim)) * 0.6, rng.standard_normal(3) * 0.3, rng.standard_normal((1, 3)) * 0.5)
    teacher.Theta1[:, :2] *= 0.5  # keep the free run bounded
    i, d, tau = (rng.standard_normal(N) for _ in range(3))
    w = simulate(lambda z: float(teacher.predict(z)), o, i, d, tau, noise * rng.standard_normal(N))
    Z, y = regressors(dataset(w, i, d, tau), o)
    return o, teacher, Z, y


def test_lm_training_decreases_the_cost_and_reaches_the_teacher():
    o, teacher, Z, y = teacher_problem(5, 0.0)
    rng = np.random.default_rng(6)
    start = MLPWeights(teacher.Theta1 + 0.2 * rng.standard_normal(teacher.Theta1.shape), teacher.Theta_b + 0.1,
                       teacher.Theta2 * 1.3)  # fmt: skip
    w, info = train_lm(start, Z, y, max_nfev=400)
    assert info.J_final < 1e-3 * info.J_initial
    assert info.J_final < 1e-18  # noise-free data: the teacher's zero cost is reached
    best = np.minimum.accumulate(info.history)
    assert best[-1] == pytest.approx(info.J_final, rel=1e-9)
    np.testing.assert_allclose(w.predict(Z), teacher.predict(Z), atol=1e-8)


def test_lm_with_torch_jacobian_matches_scipy_finite_difference_lm():
    o, teacher, Z, y = teacher_problem(7, 0.05)
    M_l = fit_arx(Z, y)
    w0 = init_from_arx(M_l, 3, scale=0.3, seed=1)
    w_t, info_t = train_lm(w0, Z, y, max_nfev=2000)
    assert info_t.J_final < info_t.J_initial
    # scipy's own LM with its own finite-difference Jacobian from the same start
    ref = least_squares(lambda th: MLPWeights.from_vector(th, o.dim, 3).predict(Z) - y, w0.vector(), method="lm",
                        x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=20000)  # fmt: skip
    assert info_t.status > 0 and ref.status > 0
    assert info_t.J_final == pytest.approx(float(np.mean(ref.fun**2)), rel=1e-6)
    np.testing.assert_allclose(w_t.predict(Z), ref.fun + y, atol=1e-5)
    # with noise sigma = 0.05 the minimum sits at the noise floor
    assert 0.8 * 0.05**2 < info_t.J_final < 1.1 * 0.05**2


def test_scaling_is_deviation_over_std_and_round_trips():
    class Sig:
        rng = np.random.default_rng(8)
        omega_r = rng.normal(10.0, 100.0, 5000)
        i_mR = rng.uniform(0.8, 2.8, 5000)
        i_sd_ref = i_mR + rng.normal(0, 0.3, 5000)
        i_sq_ref = rng.normal(0, 4.0, 5000)
        i_tau = i_sq_ref * i_mR

    sc = Scaling.fit(Sig, {"i_sq_ref0": 0.5})
    assert sc.omega_r0 == 0.0 and sc.i_mR0 == 1.8 and sc.i_tau0 == 0.5 * 1.8
    assert np.std(sc.scale("omega_r", Sig.omega_r)) == pytest.approx(1.0)
    assert np.std(sc.scale("i_tau", Sig.i_tau)) == pytest.approx(1.0)
    np.testing.assert_allclose(sc.unscale("i_mR", sc.scale("i_mR", Sig.i_mR)), Sig.i_mR, atol=1e-12)
    assert Scaling.from_dict(json.loads(json.dumps(sc.to_dict()))) == sc


def test_residual_autocorrelation_of_white_and_coloured_noise():
    rng = np.random.default_rng(9)
    e = rng.standard_normal(20000)
    lags, r, band = residual_autocorrelation(e, 20)
    assert r[lags == 0][0] == pytest.approx(1.0)
    assert np.mean(np.abs(r[lags != 0]) > band) < 0.15
    c = np.convolve(e, [1.0, 0.9], mode="same")
    _, rc, _ = residual_autocorrelation(c, 20)
    assert rc[lags == 1][0] == pytest.approx(0.9 / 1.81, abs=0.03)


def test_model_artifact_round_trip_no_pickle_and_tamper_detection(tmp_path):
    rng = np.random.default_rng(10)
    o = Orders(4, 1, 2)
    mlp = MLPWeights(rng.standard_normal((4, o.dim)), rng.standard_normal(4), rng.standard_normal((1, 4)))
    model = NarxModel(o, Scaling(0.0, 1.8, 1.8, 0.0, 130.0, 0.6, 0.8, 5.7, 3.8), mlp, rng.standard_normal((1, o.dim)), 1 / 600)
    npz, js = save_model(tmp_path / "m", model, {"provenance": {"train": {"sha256": "ab", "seed": 1}}})
    doc = json.loads(js.read_text())
    assert doc["format"] == "imbench.narx_model" and doc["orders"] == {"n": 4, "n_i": 1, "n_u": 2}
    assert doc["meta"]["provenance"]["train"]["seed"] == 1 and "created_utc" in doc
    back = load_model(tmp_path / "m.json")
    Z = rng.standard_normal((50, o.dim))
    np.testing.assert_array_equal(back.mlp.predict(Z), model.mlp.predict(Z))
    assert back.scaling == model.scaling and back.dt == model.dt
    with np.load(npz, allow_pickle=False) as z:  # plain arrays, loadable without pickle
        assert set(z.files) == {"Theta1", "Theta_b", "Theta2", "M_l"}
    raw = bytearray(npz.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    npz.write_bytes(bytes(raw))
    with pytest.raises(ArtifactError, match="checksum"):
        load_model(tmp_path / "m")


def test_metrics_report_the_thesis_quantity_in_three_readings():
    rng = np.random.default_rng(11)
    o = Orders(1, 1, 1)
    N = 4000
    i, d, tau = (rng.standard_normal(N) for _ in range(3))
    M = np.array([[0.5, 0.2, 0.1, 0.3]])
    w = simulate(lambda z: float(M[0] @ z), o, i, d, tau, 0.1 * rng.standard_normal(N))
    sc = Scaling(0.0, 0.0, 0.0, 0.0, 50.0, 1.0, 1.0, 1.0, 1.0)
    model = NarxModel(o, sc, init_from_arx(M, 2), M, 1 / 600)
    m = metrics(model, dataset(w, i, d, tau, sc))["arx"]
    assert m["J"] == pytest.approx(0.01, rel=0.05)
    assert m["rms_rad_s"] == pytest.approx(50.0 * 0.1, rel=0.03)
    assert m["sigma_w_J"] == pytest.approx(50.0 * m["J"]) and m["ms_rad2_s2"] == pytest.approx(2500.0 * m["J"])


def test_lm_training_is_bit_reproducible_whatever_the_array_alignment():
    """MKL's GEMM rounds differently for differently aligned operands; train_lm copies into aligned memory."""
    o, teacher, Z, y = teacher_problem(12, 0.05, N=6000)
    w0 = init_from_arx(fit_arx(Z, y), 3, scale=0.01, seed=2)
    runs = []
    for off in (0, 1, 3):
        buf = np.empty(Z.size + off)
        Zc = buf[off:].reshape(Z.shape)
        Zc[:] = Z
        w, info = train_lm(w0, Zc, y, max_nfev=300)
        runs.append((w.vector(), info.history))
    for vec, hist in runs[1:]:
        np.testing.assert_array_equal(vec, runs[0][0])
        assert hist == runs[0][1]
