"""The LPV flux observer of thesis 5.6: model, JL reference, design + verification, behaviour, artifacts."""

from __future__ import annotations

import json

import numpy as np
import pytest

from synthesis.artifacts import ArtifactError, load_controller, save_controller
from synthesis.construct import LPVRuntime
from synthesis.models.flux_observer import (
    JL_K1,
    JL_K2,
    design_flux_observer,
    jl_response,
    observer_response,
    summary,
)
from synthesis.models.motor import MotorData, a_sc, b_sc, flux_observer_plant, jl_observer
from synthesis.verify import verify

# LMIWarning (optimal_inaccurate, re-checked) and scipy ill-conditioning notes are expected here
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

M = MotorData()


def test_jl_observer_is_exact_on_motor_trajectories():
    """JL (4.3.1) combines two exact models: fed with the motor's ī_s and ū_s it returns ī_m, any K_1, K_2."""
    for w_r in (-150.0, 10.0, 200.0):
        A, B = a_sc(w_r), b_sc()
        for K1, K2 in ((JL_K1, JL_K2), (10000.0, 0.0), (5.0 - 2j, 0.3)):
            S = jl_observer(w_r, K1, K2)
            for s in (0.5j, 3 + 40j, -200j, 1000j):
                x = np.linalg.solve(s * np.eye(2) - A, B)  # [ī_s; ī_m] per unit ū_s
                est = S.evaluate(s) @ np.array([[x[0, 0]], [1.0]])
                assert est[0, 0] == pytest.approx(x[1, 0], rel=1e-8)


def test_jl_current_model_limit():
    """K_1 = 10000, K_2 = 0 is practically the current model (4.15): ī_m/ī_s = (R_r/L_r)/(s + R_r/L_r − jω_r)."""
    w = np.array([0.1, 1.0, 10.0, 100.0])
    Hi, Hu = jl_response(10.0, 10000.0, 0.0, w)
    ref = (M.R_r / M.L_r) / (1j * w + M.R_r / M.L_r - 10j)
    np.testing.assert_allclose(Hi, ref, rtol=0.05)
    assert np.all(np.abs(Hu) < 0.01 * np.abs(Hi) + 1e-6)


@pytest.fixture(scope="module")
def design():
    return design_flux_observer(200.0)


def test_design_verifies(design):
    """Thm 5.15 synthesis at 1.1 γ_a, construction, and the independent verification (raises on failure)."""
    d = design
    assert d.verification is not None and d.verification.passed
    assert d.gamma == pytest.approx(1.1 * d.gamma_a)
    assert 0 < d.verification.max_frozen_hinf <= d.gamma
    assert d.controller.K.n_c <= 2 and d.controller.K.n_wc == d.controller.K.n_zc == 1  # complex scalar scheduling
    # re-verify from scratch on a different (finer) grid
    rep = verify(d.plant, d.controller, d.gamma, [np.array([[x]]) for x in np.linspace(-1, 1, 57)], tv_steps=0,
                 lmi_points=0)  # fmt: skip
    assert rep.passed
    s = summary(d)
    json.dumps(s)  # JSON-ready
    assert s["thesis_gamma"] == 3e-4


def _simulate_motor(T: float, n: int, sub: int, omega, u_s):
    """RK4 of the continuous model (5.77) with sub steps per sample; returns sampled ī_s, ī_m."""
    h = T / sub
    x = np.zeros(2, dtype=complex)
    B = b_sc()[:, 0]
    i_s, i_m = np.zeros(n, complex), np.zeros(n, complex)
    for k in range(n):
        i_s[k], i_m[k] = x
        for j in range(sub):
            t = (k * sub + j) * h
            f = lambda tt, xx: a_sc(omega(tt)) @ xx + B * u_s(tt)  # noqa: E731
            k1 = f(t, x)
            k2 = f(t + h / 2, x + h / 2 * k1)
            k3 = f(t + h / 2, x + h / 2 * k2)
            k4 = f(t + h, x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return i_s, i_m


def test_observer_estimates_flux_of_a_simulated_motor(design):
    """End to end: the runtime observer (5.63)/(5.64), scheduled with the measured speed, estimates ī_m of
    a motor simulated in continuous time (RK4) while ω_r sweeps ±150 rad/s."""
    d = design
    T = d.Ts
    n = 1500  # 0.5 s
    omega = lambda t: 150.0 * np.sin(2 * np.pi * 2.0 * t)  # noqa: E731
    u_s = lambda t: 100.0 * np.exp(2j * np.pi * 5.0 * t) + 30.0 * np.exp(-2j * np.pi * 37.0 * t)  # noqa: E731
    i_s, i_m = _simulate_motor(T, n, 4, omega, u_s)
    rt = LPVRuntime(d.controller)
    est = np.array([rt.step([i_s[k], u_s(k * T)], np.array([[omega(k * T) / d.omega_r_max]]))[0] for k in range(n)])
    tail = slice(n // 3, n)
    err = np.sqrt(np.mean(np.abs(est[tail] - i_m[tail]) ** 2)) / np.sqrt(np.mean(np.abs(i_m[tail]) ** 2))
    assert err < 0.02
    # a wrong speed schedule (ω_r = 0 always) is visibly worse: the scheduling does something
    rt.reset()
    est0 = np.array([rt.step([i_s[k], u_s(k * T)], np.zeros((1, 1)))[0] for k in range(n)])
    err0 = np.sqrt(np.mean(np.abs(est0[tail] - i_m[tail]) ** 2)) / np.sqrt(np.mean(np.abs(i_m[tail]) ** 2))
    assert err0 > 3 * err


@pytest.fixture(scope="module")
def design_diagonal():
    return design_flux_observer(200.0, rescale="diagonal", check=False)


def test_fig5_6_shapes(design_diagonal):
    """Claims of 5.6.2 on the Bode data at ω_r = 10: around the rotor frequency the LPV and JL current
    gains are similar; at low frequency the LPV observer uses the voltage (unlike the current model) but
    without the huge gain of the voltage model, whose ū_s → î_m gain is L_r/(L_m² s) by (4.16)/(4.17).

    These hold for a design at γ ≈ 2.5x the optimum (the earlier diagonal re-balancing);
    the certified-optimal design does not share the first (see `test_optimal_observer_leans_on_voltage`)."""
    design = design_diagonal
    w = np.array([0.1, 10.0])
    Hi_l, Hu_l = observer_response(design, 10.0, w)
    Hi_j, Hu_j = jl_response(10.0, JL_K1, JL_K2, w)
    Hi_c, Hu_c = jl_response(10.0, 10000.0, 0.0, w)
    assert abs(abs(Hi_l[1]) / abs(Hi_j[1]) - 1) < 0.5
    assert abs(Hu_l[0]) > 30 * abs(Hu_c[0])
    voltage_model = M.L_r / (M.L_m**2 * w[0])
    assert abs(Hu_l[0]) < 0.05 * voltage_model


def test_optimal_observer_leans_on_voltage(design):
    """Measured (issue 12): at γ_a = the lower bound, the observer's current gain at ω_r = 10, ω = 10 rad/s
    is far below JL's (0.064x at 200 rad/s), i.e. the thesis' "similar current gains" is a property of
    its sub-optimal γ, not of the optimum; the voltage path still stays well below the voltage model."""
    w = np.array([0.1, 10.0])
    Hi_l, Hu_l = observer_response(design, 10.0, w)
    Hi_j, _ = jl_response(10.0, JL_K1, JL_K2, w)
    assert abs(Hi_l[1]) < 0.2 * abs(Hi_j[1])
    assert abs(Hu_l[0]) < 0.05 * M.L_r / (M.L_m**2 * w[0])
    assert design.gamma_a <= 1.01 * design.lower_bound.value


def test_artifact_roundtrip(design, tmp_path):
    d = design
    meta = dict(motor=d.motor.as_dict(), gamma_a=d.gamma_a, omega_r_max=d.omega_r_max,
                verification=d.verification.as_dict(), solver=d.synthesis.settings)  # fmt: skip
    npz, js = save_controller(tmp_path / "flux_observer", d.controller, meta)
    K, doc = load_controller(tmp_path / "flux_observer.json")
    assert doc["meta"]["gamma_a"] == pytest.approx(d.gamma_a) and doc["format_version"] == "1.0"
    for w_r in (-200.0, 10.0, 123.0):
        D = np.array([[w_r / 200.0]])
        a, b = K.frozen(D), d.controller.frozen(D)
        for X, Y in ((a.A, b.A), (a.B, b.B), (a.C, b.C), (a.D, b.D)):
            np.testing.assert_array_equal(X, Y)
    with np.load(npz, allow_pickle=False) as z:  # plain arrays, no pickle needed
        assert set(z.files) >= {"K_M", "sched_P", "sched_U", "sched_lam"}
    raw = bytearray(npz.read_bytes())
    raw[-10] ^= 0xFF
    npz.write_bytes(bytes(raw))
    with pytest.raises(ArtifactError, match="checksum"):
        load_controller(js)


def test_model_lft_matches_thesis_a_sc():
    """Closing Δ = ω_r/ω_r,max on (5.79)/(5.80) gives A_sc(ω_r) of (5.77) (hand-typed version: tests/test_lft.py)."""
    P = flux_observer_plant(200.0)
    for w_r in (-200.0, 0.0, 77.0):
        np.testing.assert_allclose(P.frozen(np.array([[w_r / 200.0]])).A, a_sc(w_r), rtol=1e-12, atol=1e-9)


@pytest.mark.slow
def test_reproductions_write_files(tmp_path):
    from bench.workflows.reproductions.lpv_observer import fig5_5, fig5_6

    r6 = fig5_6(tmp_path)
    assert (tmp_path / "fig5.6.png").stat().st_size > 1000 and r6["lpv"]["verification"]["passed"]
    r5 = fig5_5(tmp_path, omegas=(50, 200))
    assert (tmp_path / "fig5.5.png").stat().st_size > 1000 and len(r5["full"]) == 2
    for row in r5["full"] + r5["thesis_reading"]:
        assert row["gamma_lower_bound"] <= row["gamma_a"]
    assert all(row["gap"] <= 1.01 for row in r5["full"])


def test_the_design_is_continuous_in_the_model() -> None:
    """A design is a continuous function of its motor model (`synthesis.lmi.balanced_centre`): R_r moved by 10⁻⁶
    moves the observer's response by far less than 1 % (centred at the bisection's own scaling it moved 4.9 %:
    which scaling the bisection ends at depends on its path), and R_r moved by 10⁻² moves it by about as much as
    the model (measured 1.1 %): neither a jump nor nothing."""
    from dataclasses import replace

    from bench.workflows.commission.design_spread import change, responses

    ref = responses(design_flux_observer(200.0, check=False))
    moved = {rel: change(responses(design_flux_observer(200.0, check=False, motor=replace(M, R_r=M.R_r * (1 + rel)))),
                         ref) for rel in (1e-6, 1e-2)}  # fmt: skip
    assert moved[1e-6] < 2e-3, moved
    assert 3e-3 < moved[1e-2] < 3e-2, moved
