"""DC load drive (mock_hw.load): first-order lag, torque limit, sign in the mechanics (3.37)."""

from __future__ import annotations

import math

import pytest

from bench.hal import Command
from bench.params import T_S_DEFAULT, MotorParams
from mock_hw.load import DcLoadDrive
from mock_hw.plant import MockConfig, MotorConfig, make_mock_rig

DT = T_S_DEFAULT


def test_first_order_lag_step_response_is_exact():
    ld = DcLoadDrive()
    assert ld.tau == 2e-3 and ld.torque_limit == 15.0
    ld.set_torque(5.0)
    for k in range(1, 60):
        mean = ld.advance(DT)
        t = k * DT
        assert ld.m_L == pytest.approx(5.0 * (1 - math.exp(-t / 2e-3)), abs=1e-12)
        # the mean over the period is the integral of the exponential / h
        t0 = t - DT
        exact = 5.0 - 5.0 * 2e-3 / DT * (math.exp(-t0 / 2e-3) - math.exp(-t / 2e-3))
        assert mean == pytest.approx(exact, abs=1e-12)
    assert ld.m_L == pytest.approx(5.0, abs=5e-4)  # after ~10 tau


def test_time_constant_is_where_63_percent_is_reached():
    ld = DcLoadDrive(tau=0.01)
    ld.set_torque(-2.0)
    t = 0.0
    while ld.m_L > -2.0 * (1 - math.exp(-1)):
        ld.advance(1e-5)
        t += 1e-5
    assert t == pytest.approx(0.01, abs=2e-5)


@pytest.mark.parametrize("ref,want", [(100.0, 15.0), (-40.0, -15.0), (14.0, 14.0)])
def test_torque_limit(ref, want):
    ld = DcLoadDrive()
    ld.set_torque(ref)
    for _ in range(100):
        ld.advance(DT)
    assert ld.m_L == pytest.approx(want, rel=1e-6)  # 16 tau


def test_positive_load_brakes_positive_rotation_in_the_plant():
    """(3.37): J/Z_p d omega_r/dt = m_e - m_L (- friction); compare two coasting runs."""
    p = MotorParams(B_visc=0.0, m_coulomb=0.0)  # frictionless: the difference is all m_L

    def final_speed(m_L_ref: float) -> float:
        rig = make_mock_rig(MockConfig(motor=MotorConfig(omega_r0=200.0)), params_true=p)
        with rig:
            for k in range(600):  # 0.2 s, inverter off: m_e = 0
                rig.read(k * DT)
                rig.write(Command(enable=False, m_L_ref=m_L_ref))
            rig.read(600 * DT)
            return rig.truth.motor.omega_r

    w0, w3 = final_speed(0.0), final_speed(3.0)
    assert w3 < w0 == pytest.approx(200.0)
    # the extra deceleration is Z_p/J * 3 N m over 0.2 s, less the lag's missing area (3 N m * tau)
    expect = p.Z_p / p.J * 3.0 * (600 * DT - 2e-3 * (1 - math.exp(-0.2 / 2e-3)))
    assert w0 - w3 == pytest.approx(expect, rel=1e-9)
    wneg = final_speed(-3.0)
    assert wneg > w0


def test_safe_state_sets_load_to_zero():
    rig = make_mock_rig(MockConfig())
    with rig:
        rig.read(0.0)
        rig.write(Command(m_L_ref=4.0))
        assert rig.load.m_L_ref == 4.0
    assert rig.load.m_L_ref == 0.0
