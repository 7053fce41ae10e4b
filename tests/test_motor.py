"""Physics of the induction-motor model (mock_hw.motor) against the thesis' equations."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from bench.params import T_S_DEFAULT, MotorParams
from mock_hw.motor import InductionMotor, steady_state

P = MotorParams()


def a_sc(p: MotorParams, w: float) -> np.ndarray:
    """A_sc of (3.41), entry by entry as printed."""
    d = p.L_r * (p.L_m**2 - p.L_s * p.L_r)
    return np.array([
        [(p.L_m**2 * p.R_r + p.R_s * p.L_r**2) / d, p.L_m**2 * (1j * p.L_r * w - p.R_r) / d],
        [p.R_r / p.L_r, 1j * w - p.R_r / p.L_r],
    ])  # fmt: skip


def b_sc(p: MotorParams) -> np.ndarray:
    return np.array([p.L_r / (p.L_s * p.L_r - p.L_m**2), 0.0])


def run_rotating(m: InductionMotor, u_ss: complex, w_mR: float, T: float, h: float) -> float:
    """Feed u_ss e^{j w_mR t}, sampled at mid-step (error ~ (w h)^2/24); return the end time."""
    n = round(T / h)
    for k in range(n):
        m.step(u_ss * cmath.exp(1j * w_mR * (k + 0.5) * h), 0.0, h)
    return n * h


# --- model equations ---------------------------------------------------------------------
@settings(max_examples=50, deadline=None)
@given(
    st.complex_numbers(max_magnitude=20, allow_nan=False, allow_infinity=False),
    st.complex_numbers(max_magnitude=10, allow_nan=False, allow_infinity=False),
    st.floats(-400, 400),
    st.complex_numbers(max_magnitude=500, allow_nan=False, allow_infinity=False),
)
def test_derivatives_satisfy_voltage_equations_334_335(i_s, i_m, w, u):
    """The state equations solve (3.34)/(3.35) in the original (i_s, i_rs) variables."""
    m = InductionMotor(P)
    m.reset(i_s=i_s, i_m=i_m, omega_r=w)
    di_s, di_m, _, dth = m.derivatives(u, 0.0)
    i_rs = P.L_m / P.L_r * (i_m - i_s)  # inverse of (3.39)
    di_rs = P.L_m / P.L_r * (di_m - di_s)
    scale = 1.0 + abs(u) + abs(i_s) + abs(i_m)
    assert abs(P.R_s * i_s + P.L_s * di_s + P.L_m * di_rs - u) < 1e-9 * scale  # (3.34)
    res = P.L_m * (di_s - 1j * w * i_s) + P.R_r * i_rs + P.L_r * (di_rs - 1j * w * i_rs)
    assert abs(res) < 1e-9 * scale * (1 + abs(w))  # (3.35)
    assert dth == pytest.approx(w / P.Z_p)  # (3.32)
    # and they are the matrices of (3.41)
    x = np.array([i_s, i_m])
    ref = a_sc(P, w) @ x + b_sc(P) * u
    assert abs(di_s - ref[0]) < 1e-9 * scale * (1 + abs(w)) and abs(di_m - ref[1]) < 1e-9 * scale * (1 + abs(w))


def test_rk4_path_matches_reference_rhs():
    """The inlined RK4 right-hand side equals `derivatives` (finite difference of a tiny step)."""
    m = InductionMotor(P, omega_eps=0.5)
    m.reset(i_s=3 - 2j, i_m=1.5 + 1j, omega_r=120.0, theta_mech=0.3)
    u, m_L, h = 250 + 80j, 1.5, 1e-6
    d = m.derivatives(u, m_L)
    s0 = (m.i_s, m.i_m, m.omega_r, m.theta_mech)
    m.step(u, m_L, h)
    fwd = (m.i_s, m.i_m, m.omega_r, m.theta_mech)
    m.reset(i_s=s0[0], i_m=s0[1], omega_r=s0[2], theta_mech=s0[3])
    m.step(u, m_L, -h)  # central difference: error O(h^2)
    bwd = (m.i_s, m.i_m, m.omega_r, m.theta_mech)
    for a, b, want in zip(fwd, bwd, d):
        assert abs((a - b) / (2 * h) - want) <= 1e-6 * (1 + abs(want))


@settings(max_examples=100, deadline=None)
@given(
    st.complex_numbers(max_magnitude=20, allow_nan=False, allow_infinity=False),
    st.complex_numbers(max_magnitude=10, allow_nan=False, allow_infinity=False),
)
def test_torque_336_equals_341_and_46(i_s, i_m):
    m = InductionMotor(P)
    m.reset(i_s=i_s, i_m=i_m)
    i_rs = m.i_rs
    assert i_m == pytest.approx(i_s + P.L_r / P.L_m * i_rs, abs=1e-9)  # (3.39)
    m_336 = 1.5 * P.Z_p * P.L_m * (i_s * i_rs.conjugate()).imag
    # (4.6) in rotor-flux coordinates: rho = angle(i_m), i_mR = |i_m|, i_sq = Im{i_s e^{-j rho}}
    rho = cmath.phase(i_m)
    i_sq = (i_s * cmath.exp(-1j * rho)).imag
    m_46 = 1.5 * P.Z_p * P.Lm_p * abs(i_m) * i_sq
    tol = 1e-9 * (1 + abs(i_s) * abs(i_m))
    assert m.m_e == pytest.approx(m_336, abs=tol)
    assert m.m_e == pytest.approx(m_46, abs=tol)
    assert m.psi_r == pytest.approx(P.L_m * i_m)  # (3.40)


def test_steady_state_closed_form_matches_matrix_form():
    """(3.54)/(3.55) equal -(A_sc - j w_mR)^-1 B_sc u_ss (3.53); (3.56) equals (4.6)."""
    for w_mR, w_r in [(100.0, 90.0), (50.0, 60.0), (-80.0, -70.0), (20.0, 0.0), (300.0, 297.4)]:
        u = 120.0 * cmath.exp(0.4j)
        x = -np.linalg.solve(a_sc(P, w_r) - 1j * w_mR * np.eye(2), b_sc(P) * u)
        i_ss, i_ms, m_e = steady_state(P, u, w_mR, w_r)
        assert abs(i_ss - x[0]) < 1e-9 * abs(x[0])
        assert abs(i_ms - x[1]) < 1e-9 * abs(x[1])
        i_sq = (i_ss * cmath.exp(-1j * cmath.phase(i_ms))).imag
        assert m_e == pytest.approx(P.torque_constant * abs(i_ms) * i_sq, rel=1e-9)


# --- steady state of the simulated motor -----------------------------------------------------
STEADY_CASES = [
    (100.0, 95.0),  # motoring
    (300.0, 290.0),  # near rated speed
    (50.0, 60.0),  # generating (negative slip)
    (-100.0, -95.0),  # negative speed, motoring
    (-50.0, -60.0),  # negative speed, generating
    (15.0, 0.0),  # locked rotor
]


@pytest.mark.parametrize("w_mR,w_r", STEADY_CASES)
def test_simulated_steady_state_matches_354_356(w_mR, w_r):
    u_ss = (10.0 + 1.05 * abs(w_mR)) * cmath.exp(0.7j)  # about 3 A magnetising current
    m = InductionMotor(P, hold_speed=True, omega_r0=w_r)
    h = 1.0 / 20000
    t = run_rotating(m, u_ss, w_mR, 2.5, h)
    assert m.omega_r == w_r  # hold_speed
    i_ss, i_ms, m_e = steady_state(P, u_ss, w_mR, w_r)
    rot = cmath.exp(-1j * w_mR * t)
    assert abs(m.i_s * rot - i_ss) < 1e-3 * abs(i_ss)
    assert abs(m.i_m * rot - i_ms) < 1e-3 * abs(i_ms)
    assert m.m_e == pytest.approx(m_e, rel=1e-3, abs=1e-6)
    # motoring vs generating: torque has the sign of the slip (3.56)
    assert math.copysign(1.0, m.m_e) == math.copysign(1.0, w_mR - w_r)
    # steady-state power balance: no change of stored energy, p_in = copper + mechanical
    p_in = 1.5 * (u_ss * i_ss.conjugate()).real
    p_mech = m.m_e * w_r / P.Z_p
    assert p_in == pytest.approx(m.copper_losses() + p_mech, rel=2e-3)


def test_power_balance_along_a_transient():
    """int p_in dt = W_mag(T) - W_mag(0) + int copper losses + int m_e omega_mech (free shaft)."""
    m = InductionMotor(P)
    h = 1.0 / 60000
    W0 = m.magnetic_energy()
    e_in = e_cu = e_mech = 0.0
    e_fric_load = 0.0
    prev = None
    for k in range(round(0.4 / h)):
        t = k * h
        u = 250.0 * cmath.exp(1j * 2 * math.pi * 25.0 * t) * min(1.0, 0.3 + t / 0.1)
        m_L = 2.0 if t > 0.25 else 0.0
        # powers at both ends of the step with the step's (held) voltage: trapezoid
        def powers() -> tuple[float, float, float, float]:
            return (1.5 * (u * m.i_s.conjugate()).real, m.copper_losses(), m.m_e * m.omega_mech,
                    (m_L + m.m_friction) * m.omega_mech)  # fmt: skip
        a = powers()
        m.step(u, m_L, h)
        b = powers()
        e_in += 0.5 * h * (a[0] + b[0])
        e_cu += 0.5 * h * (a[1] + b[1])
        e_mech += 0.5 * h * (a[2] + b[2])
        e_fric_load += 0.5 * h * (a[3] + b[3])
        prev = b
    assert prev is not None and abs(m.omega_r) > 10.0  # it did accelerate
    dW = m.magnetic_energy() - W0
    assert e_in > 100.0
    assert e_in == pytest.approx(dW + e_cu + e_mech, rel=1e-5)
    # mechanical side: int m_e w = kinetic energy + int (m_L + friction) w
    e_kin = 0.5 * P.J * m.omega_mech**2
    assert e_mech == pytest.approx(e_kin + e_fric_load, rel=1e-4)


# --- integration accuracy ------------------------------------------------------------------
def _startup(m: InductionMotor, T: float, h: float) -> None:
    for k in range(round(T / h)):
        t = k * h
        f = min(50.0, 50.0 * t / 0.3)  # V/f ramp, then a load step
        u = (20.0 + 6.0 * f) * cmath.exp(1j * math.pi * f * t)
        m.step(u, 4.0 if t > 0.35 else 0.0, h)


def test_rk4_at_3khz_matches_100x_finer_step():
    """Default integration at h = 1/3000 s vs 100 RK4 sub-steps, through start-up and a load step.

    Bound: |i_s error| < 5e-4 A (the ADC LSB is 9.8 mA), |i_m error| < 1e-5 A,
    speed < 5e-4 rad/s (measured: 4e-5 A, 1.5e-6 A, 4e-5 rad/s).
    """
    h = T_S_DEFAULT
    coarse, fine = InductionMotor(P), InductionMotor(P, substeps=100)
    assert coarse.substeps == 1
    _startup(coarse, 0.5, h)
    _startup(fine, 0.5, h)
    assert fine.omega_r > 100.0 and abs(fine.i_s) > 1.0  # a demanding trajectory
    assert abs(coarse.i_s - fine.i_s) < 5e-4
    assert abs(coarse.i_m - fine.i_m) < 1e-5
    assert abs(coarse.omega_r - fine.omega_r) < 5e-4
    assert abs(coarse.theta_mech - fine.theta_mech) < 1e-4
    # the bound discriminates: explicit Euler at the same step is far outside it
    eu = InductionMotor(P)
    for k in range(round(0.5 / h)):
        t = k * h
        f = min(50.0, 50.0 * t / 0.3)
        u = (20.0 + 6.0 * f) * cmath.exp(1j * math.pi * f * t)
        di_s, di_m, dw, dth = eu.derivatives(u, 4.0 if t > 0.35 else 0.0)
        eu.reset(i_s=eu.i_s + h * di_s, i_m=eu.i_m + h * di_m, omega_r=eu.omega_r + h * dw,
                 theta_mech=eu.theta_mech + h * dth)  # fmt: skip
    assert abs(eu.i_s - fine.i_s) > 1e-2


# --- modes and mechanics ---------------------------------------------------------------------
def test_coast_decays_flux_by_current_model_with_zero_current():
    m = InductionMotor(P, hold_speed=True)
    i_m0 = 3.0 + 0.5j
    m.reset(i_s=2 + 1j, i_m=i_m0, omega_r=150.0)
    m.coast = True
    h, n = T_S_DEFAULT, 300
    for _ in range(n):
        m.step(400 + 0j, 0.0, h)  # the voltage is ignored: the bridge is off
    t = n * h
    assert m.i_s == 0j and m.m_e == 0.0
    expect = i_m0 * cmath.exp((-P.R_r / P.L_r + 1j * 150.0) * t)  # (4.15) with i_s = 0
    assert abs(m.i_m - expect) < 1e-6 * abs(i_m0)
    # terminal voltage is the back-EMF L'_m d i_m/dt (mean over the last step)
    i_m_prev = i_m0 * cmath.exp((-P.R_r / P.L_r + 1j * 150.0) * (t - h))
    assert abs(m.u_s - P.Lm_p * (m.i_m - i_m_prev) / h) < 1e-4 * abs(m.u_s)
    assert m.p_in == 0.0


def test_free_coast_follows_friction_and_load():
    """With no torque the speed obeys J/Z_p dw_r/dt = -(m_L + B w_m + m_c tanh(w_m/eps))."""
    m = InductionMotor(P, omega_r0=200.0)
    m.coast = True
    m_L = 0.3

    def rhs(_t, y):
        wm = y[0] / P.Z_p
        return [-P.Z_p / P.J * (m_L + P.B_visc * wm + P.m_coulomb * math.tanh(wm / m.omega_eps))]

    ref = solve_ivp(rhs, (0, 0.5), [200.0], rtol=1e-10, atol=1e-10)
    for _ in range(1500):
        m.step(0j, m_L, T_S_DEFAULT)
    assert m.omega_r == pytest.approx(ref.y[0, -1], abs=1e-6)
    assert m.omega_r < 200.0 - 0.5 * P.Z_p / P.J * m_L * 0.5 * 0.9  # positive m_L brakes


def test_coulomb_friction_is_regularised_and_holds_below_breakaway():
    m = InductionMotor(P)
    m.coast = True
    for _ in range(3000):  # 1 s with a load torque of 80 % of Coulomb friction
        m.step(0j, 0.8 * P.m_coulomb, T_S_DEFAULT)
    creep = m.omega_eps * math.atanh(0.8)  # documented creep (B_visc negligible here)
    assert abs(m.omega_mech) < 1.2 * creep
    assert m.omega_mech < 0  # it creeps in the direction of the load
    m2 = InductionMotor(P)
    m2.coast = True
    for _ in range(3000):  # 1.5x breakaway: it really accelerates
        m2.step(0j, -1.5 * P.m_coulomb, T_S_DEFAULT)
    assert m2.omega_mech > 1.0


def test_theta_integrates_speed_and_hold_speed_keeps_it():
    m = InductionMotor(P, hold_speed=True, omega_r0=-75.0)
    for _ in range(3000):
        m.step(100j, 0.0, T_S_DEFAULT)
    assert m.omega_r == -75.0
    assert m.theta_mech == pytest.approx(-75.0 / P.Z_p * 1.0, rel=1e-9)
    assert m.theta_r == pytest.approx(P.Z_p * m.theta_mech)


def test_invalid_construction():
    with pytest.raises(ValueError):
        InductionMotor(P, substeps=0)
    with pytest.raises(ValueError):
        InductionMotor(P.with_(L_m=0.4))
