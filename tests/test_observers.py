"""Flux observers and speed estimators against closed-form behaviour (thesis Secs 3.3.4, 4.3, 4.4).

The reference signals are the steady state of (3.41) from (3.54)(3.55): in a frame rotating at
omega_mR the currents and the voltage are constant. Voltages are given to the observers as the
value at the middle of each period (the observers assume a held voltage; the difference is a
factor sinc(omega_mR T/2), below 1e-6 here).
"""

from __future__ import annotations

import cmath

import numpy as np
import pytest

from bench.controllers.observers import (
    OBSERVERS,
    CurrentModelObserver,
    JansenLorenzObserver,
    KubotaObserver,
    VoltageModelObserver,
    kubota_gain,
    sc_matrix,
)
from bench.controllers.speed_estimators import KubotaSpeed, RotorEquationSpeed
from bench.params import T_S_DEFAULT, MotorParams

M = MotorParams()
T = T_S_DEFAULT


def steady(omega_r: float, omega_mR: float, i_mR: float = 2.5, motor: MotorParams = M):
    """(i_ss, i_ms, u_ss) of (3.54)(3.55) for a real magnetising current i_mR in the flux frame."""
    R_s, R_r, L_s, L_r, L_m = motor.R_s, motor.R_r, motor.L_s, motor.L_r, motor.L_m
    w_sl = omega_mR - omega_r
    den = R_s * R_r + 1j * w_sl * R_s * L_r + 1j * omega_mR * L_s * R_r + omega_mR * w_sl * (L_m**2 - L_r * L_s)
    i_ms = complex(i_mR)
    u_ss = i_ms * den / R_r  # (3.55) solved for u_ss
    i_ss = (R_r + 1j * w_sl * L_r) * u_ss / den  # (3.54)
    return i_ss, i_ms, u_ss


def signals(omega_r: float, omega_mR: float, n: int, i_mR: float = 2.5, motor: MotorParams = M):
    """Per sample k: (i_s(t_k), u_s at the middle of [t_{k-1}, t_k), i_m(t_k)), stator-fixed."""
    i_ss, i_ms, u_ss = steady(omega_r, omega_mR, i_mR, motor)
    for k in range(n):
        rot = cmath.exp(1j * omega_mR * k * T)
        yield i_ss * rot, u_ss * cmath.exp(1j * omega_mR * (k - 0.5) * T), i_ms * rot


def run(obs, omega_r: float, omega_mR: float, seconds: float, start_psi_s: bool = False,
        **kw) -> tuple[complex, complex]:  # fmt: skip
    """Feed the steady state; return the last (estimate, truth).

    ``start_psi_s``: after the first sample, set the voltage model's stator flux to the true
    psi_s = L'_s i_s + L'_m i_m (a pure integrator keeps whatever initial error it has)."""
    est = true = 0j
    for k, (i_s, u_s, i_m) in enumerate(signals(omega_r, omega_mR, int(seconds / T), **kw)):
        est = obs.update(i_s, u_s, omega_r)
        if k == 0 and start_psi_s:
            motor = kw.get("motor", M)
            obs.psi_s = motor.Ls_p * i_s + motor.Lm_p * i_m
        true = i_m
    return est, true


CASES = [(45.0, 50.0), (10.0, 4.0), (-70.0, -80.0), (10.0, 13.0), (150.0, 152.0)]


@pytest.mark.parametrize("omega_r, omega_mR", CASES)
def test_current_model_and_jl_converge_to_3_55(omega_r, omega_mR):
    """(4.15) and the JL observer (thesis gains) settle on i_ms of (3.55) from a zero start."""
    for obs, seconds in ((CurrentModelObserver(M, T), 1.5), (JansenLorenzObserver(M, T), 3.0)):
        est, true = run(obs, omega_r, omega_mR, seconds)
        assert abs(est - true) < 2e-3 * abs(true), (obs.name, est, true)


@pytest.mark.parametrize("omega_r, omega_mR", CASES)
def test_voltage_model_follows_3_55_from_the_true_initial_flux(omega_r, omega_mR):
    """A pure integrator keeps its initial error, so start (4.16) at the true stator flux."""
    est, true = run(VoltageModelObserver(M, T), omega_r, omega_mR, 1.0, start_psi_s=True)
    assert abs(est - true) < 2e-3 * abs(true)


def test_voltage_model_drift_under_dc_offset():
    """A DC offset u_0 on the voltage makes psi_s grow at u_0, so i_m_hat drifts at (L_r/L_m^2) u_0 (4.17)."""
    obs = VoltageModelObserver(M, T)
    u0 = 0.5 - 0.2j  # [V]
    n = 3000
    for _ in range(n):
        est = obs.update(0j, u0, 0.0)
    slope = est / (n * T)
    assert slope == pytest.approx(M.L_r / M.L_m**2 * u0, rel=1e-9)
    # with the optional low-pass (tau) the drift saturates at tau u_0 L_r/L_m^2 instead
    # (to O(T/tau): the discrete low-pass has the gain T/(1 - e^{-T/tau}) = tau + T/2 + ...)
    lp = VoltageModelObserver(M, T, tau=0.05)
    for _ in range(int(1.0 / T)):
        est = lp.update(0j, u0, 0.0)
    assert abs(est - 0.05 * u0 * M.L_r / M.L_m**2) < 5e-3 * abs(est)


@pytest.mark.parametrize("k1, k2", [(32.0, 2.0), (3.2, 0.2)])
def test_jl_response_to_a_dc_voltage_offset_is_closed_form(k1, k2):
    """With i_s = 0, omega = 0 and a DC offset u_0, the JL loop (4.3.1) is d/dt psi_s = u_0 - K_1 c psi_s + K_2 g,
    d/dt g = -c psi_s (c = L_r/L_m): psi_s(t) = u_0 (e^{p_1 t} - e^{p_2 t})/(p_1 - p_2) with p_1,2 the roots of
    s^2 + K_1 c s + K_2 c. Unlike the voltage model's ramp it returns to zero, through the slow root
    (-0.063 rad/s for the thesis' K, -0.066 for C of Fig. 4.8), and its peak scales with 1/K_1."""
    K1, K2 = k1 * (1 + 0.1j), k2 * (1 + 0.1j)
    obs = JansenLorenzObserver(M, T, K1_re=K1.real, K1_im=K1.imag, K2_re=K2.real, K2_im=K2.imag)
    c = M.L_r / M.L_m
    p1, p2 = np.roots([1.0, K1 * c, K2 * c])
    u0 = 0.4 - 0.1j
    worst = peak = 0.0
    for k in range(1, int(3.0 / T) + 1):
        obs.update(0j, u0, 0.0)
        t = k * T
        want = u0 * (cmath.exp(p1 * t) - cmath.exp(p2 * t)) / (p1 - p2)
        worst, peak = max(worst, abs(obs.psi_s - want)), max(peak, abs(want))
    assert worst < 1e-6 * peak
    assert abs(obs.i_m - M.L_r / M.L_m**2 * obs.psi_s) < 1e-12  # i_s = 0: i_m_hat = (L_r/L_m^2) psi_s (4.17)
    assert peak == pytest.approx(abs(u0) / abs(K1 * c), rel=0.1)


def test_jl_limits_are_current_and_voltage_models():
    """K_1 -> infinity gives the current model, K_1 = K_2 = 0 the voltage model (4.3.1), for any inputs."""
    rng = np.random.default_rng(1)
    t = np.arange(600) * T

    def smooth(scale: float) -> np.ndarray:  # a few phasors below 300 rad/s, random amplitudes
        f, a = rng.uniform(-300, 300, 4), rng.normal(size=4) + 1j * rng.normal(size=4)
        return scale * (a[None, :] * np.exp(1j * np.outer(t, f))).sum(axis=1)

    i_s, u_s, w = smooth(1.0), smooth(50.0), 40.0 * smooth(1.0).real
    cm, vm = CurrentModelObserver(M, T), VoltageModelObserver(M, T)
    stiff = JansenLorenzObserver(M, T, K1_re=1e6, K1_im=0.0, K2_re=0.0, K2_im=0.0)
    open_ = JansenLorenzObserver(M, T, K1_re=0.0, K1_im=0.0, K2_re=0.0, K2_im=0.0)
    worst_c = worst_v = 0.0
    for k in range(600):
        a, b, c = complex(i_s[k]), complex(u_s[k]), float(w[k])
        worst_c = max(worst_c, abs(stiff.update(a, b, c) - cm.update(a, b, c)))
        worst_v = max(worst_v, abs(open_.update(a, b, c) - vm.update(a, b, c)))
    assert worst_v < 1e-9
    # K_1 = 1e6: psi_rv follows psi_rc within about |u_s - R_s i_s|/K_1 ~ 1e-4 Wb, i.e. ~3e-4 A in i_m
    assert worst_c < 2e-3


def test_kubota_gain_places_poles_at_k_times_model_poles():
    for omega in (-150.0, 0.0, 10.0, 200.0):
        a11, a12, a21, a22 = sc_matrix(M, omega)
        A = np.array([[a11, a12], [a21, a22]])
        for k in (1.0, 1.1, 1.2, 2.0):
            g1, g2 = kubota_gain(M, omega, k)
            Aobs = A + np.array([[g1, 0], [g2, 0]])  # A + G C, C = [1 0]
            got = np.sort_complex(np.linalg.eigvals(Aobs))
            want = np.sort_complex(k * np.linalg.eigvals(A))
            assert np.allclose(got, want, rtol=1e-9, atol=1e-9), (omega, k)


def test_sc_matrix_is_3_41():
    """Entries against the thesis' printed A_sc (3.41) at omega_r = 37."""
    L_s, L_r, L_m, R_s, R_r, w = M.L_s, M.L_r, M.L_m, M.R_s, M.R_r, 37.0
    a11, a12, a21, a22 = sc_matrix(M, w)
    d = L_r * (L_m**2 - L_s * L_r)
    assert a11 == pytest.approx((L_m**2 * R_r + R_s * L_r**2) / d)
    assert a12 == pytest.approx(L_m**2 * (1j * L_r * w - R_r) / d)
    assert a21 == pytest.approx(R_r / L_r) and a22 == pytest.approx(1j * w - R_r / L_r)


@pytest.mark.parametrize("omega_r, omega_mR", CASES)
def test_kubota_equilibrium_at_the_true_speed(omega_r, omega_mR):
    """Started on the true state and speed, (4.20)(4.21) stay there: e_is = 0 makes d omega_hat/dt = 0.

    In the regenerating case (omega_mR = 4 < omega_r R_s/(R_s+R_r)) the equilibrium is unstable
    (Sec. 4.4.2), so the small discretisation error of the test signals grows: a looser bound."""
    i_ss, i_ms, _ = steady(omega_r, omega_mR)
    obs = KubotaObserver(M, T, pole_ratio=1.1, lambda_c=1000.0, omega0=omega_r)
    back = cmath.exp(-1j * omega_mR * T)  # the first update advances from t_{-1} to t_0
    obs.i_s_hat, obs.i_m = i_ss * back, i_ms * back
    worst = 0.0
    for i_s, u_s, i_m in signals(omega_r, omega_mR, 3000):
        obs.update(i_s, u_s, 0.0)
        worst = max(worst, abs(obs.omega_hat - omega_r))
    unstable = 0 < omega_mR < omega_r * M.R_s / (M.R_s + M.R_r)
    assert worst < (0.1 if unstable else 0.02)
    assert abs(obs.i_m - i_m) < 2e-3 * abs(i_m)


def test_kubota_converges_when_motoring_and_diverges_when_regenerating():
    """Sec. 4.4.2: with G = 0, lambda_c = 1000 the estimate started 2 rad/s high returns to
    omega_r = 10 when motoring (omega_mR = 14) but runs away at omega_mR = 4 (Fig. 4.7)."""
    out = {}
    for omega_mR in (14.0, 4.0):
        i_ss, i_ms, _ = steady(10.0, omega_mR)
        obs = KubotaObserver(M, T, pole_ratio=1.0, lambda_c=1000.0, omega0=12.0)
        back = cmath.exp(-1j * omega_mR * T)
        obs.i_s_hat, obs.i_m = i_ss * back, i_ms * back
        for i_s, u_s, _ in signals(10.0, omega_mR, int(4.0 / T)):
            obs.update(i_s, u_s, 0.0)
        out[omega_mR] = obs.omega_hat
    assert abs(out[14.0] - 10.0) < 0.2
    assert out[4.0] > 14.0  # moved further away from 10


@pytest.mark.parametrize("omega_r, omega_mR", [(45.0, 50.0), (10.0, 13.0), (-70.0, -80.0)])
def test_rotor_equation_speed_returns_the_true_speed_on_true_signals(omega_r, omega_mR):
    """(4.19) on the exact magnetising current and stator current gives omega_r."""
    est = RotorEquationSpeed(M, T, tau=0.005)
    for i_s, u_s, i_m in signals(omega_r, omega_mR, 600):
        w = est.update(i_s, u_s, i_m)
    assert w == pytest.approx(omega_r, abs=1e-6 * max(1.0, abs(omega_mR)) + 1e-3)


def test_rotor_equation_on_a_current_model_flux_returns_its_own_speed():
    """Thesis after (4.19): a current-model flux makes (4.19) return the speed the flux was built with."""
    omega_r, omega_mR, wrong = 10.0, 13.0, 25.0
    cm = CurrentModelObserver(M, T)
    est = RotorEquationSpeed(M, T, tau=0.005)
    for i_s, u_s, _ in signals(omega_r, omega_mR, int(2.0 / T)):
        w = est.update(i_s, u_s, cm.update(i_s, u_s, wrong))
    assert w == pytest.approx(wrong, abs=0.05)


def test_kubota_speed_estimator_shares_or_owns_its_observer():
    shared = KubotaObserver(M, T, omega0=3.0)
    s = KubotaSpeed(M, T, shared=shared)
    s.update(1.0 + 0j, 10.0 + 0j, 0j)
    assert shared.i_m == 0j  # a shared observer is not stepped by the estimator
    own = KubotaSpeed(M, T, observer_params={"omega0": 3.0})
    own.update(1.0 + 0j, 10.0 + 0j, 0j)
    assert own.obs.i_s_hat != 0j and own.omega_r == pytest.approx(own.obs.omega_hat)


def test_registry_and_unknown_parameters():
    assert set(OBSERVERS) >= {"current_model", "voltage_model", "jl", "kubota"}
    with pytest.raises(ValueError, match="bogus"):
        JansenLorenzObserver(M, T, bogus=1.0)


def test_jl_thesis_gains_are_the_defaults():
    jl = JansenLorenzObserver(M, T)
    assert jl.K1 == pytest.approx(32 * (1 + 0.1j)) and jl.K2 == pytest.approx(2 * (1 + 0.1j))


def test_observers_under_rotor_resistance_mismatch_order():
    """With R_r 50 % high in the plant, the current model's steady-state flux error exceeds the JL
    observer's, and the voltage model (no R_r) has none: the weighting argument of 4.3.1."""
    hot = M.with_(R_r=1.5 * M.R_r)
    errs = {}
    for cls in (CurrentModelObserver, JansenLorenzObserver, VoltageModelObserver):
        obs = cls(M, T)
        est, true = run(obs, 100.0, 103.0, 3.0, start_psi_s=cls is VoltageModelObserver, motor=hot)
        errs[cls.name] = abs(est - true) / abs(true)
    assert errs["voltage_model"] < 5e-3
    assert errs["jl"] < errs["current_model"]
    assert errs["current_model"] > 0.02
