"""The inverter (mock_hw.inverter): delay, ZOH, SVPWM limit, dead time, enable/coast, fault."""

from __future__ import annotations

import cmath
import math

import pytest

from bench.hal import Command, phase_values, space_vector
from bench.params import T_S_DEFAULT
from mock_hw.inverter import Inverter
from mock_hw.plant import MockConfig, make_mock_rig

DT = T_S_DEFAULT


def truth(rig) -> dict[str, float]:
    return dict(zip(rig.truth.fields, rig.truth.sample()))


def u_truth(rig) -> complex:
    d = truth(rig)
    return complex(d["u_s_re"], d["u_s_im"])


def test_one_sample_delay_through_the_rig():
    """A reference written in tick k is applied over [t_{k+1}, t_{k+2})."""
    rig = make_mock_rig(MockConfig())
    with rig:
        rig.read(0.0)
        rig.write(Command(u_s_ref=0j, enable=True))
        for k in range(1, 5):
            rig.read(k * DT)
            rig.write(Command(u_s_ref=10.0 * k, enable=True))  # tick k writes 10 k
        # tick 4 wrote 40; tick 3 wrote 30
        rig.read(5 * DT)  # integrated [t_4, t_5): the value written in tick 3
        assert u_truth(rig) == 30.0
        rig.write(Command(u_s_ref=50.0, enable=True))
        rig.read(6 * DT)  # [t_5, t_6): written in tick 4
        assert u_truth(rig) == 40.0
        rig.read(7 * DT)  # [t_6, t_7): written in tick 5
        assert u_truth(rig) == 50.0


def test_zero_delay_option_and_last_write_wins():
    inv = Inverter(delay=0)
    inv.enable()
    inv.set_voltage(5.0)
    inv.set_voltage(7.0 + 1j)  # two writes in one period: the last one counts
    assert inv.latch() == 7.0 + 1j
    inv1 = Inverter()
    inv1.enable()
    inv1.set_voltage(7.0)
    assert inv1.latch() == 0j  # one-sample delay: nothing yet
    inv1.set_voltage(9.0)
    assert inv1.latch() == 7.0
    assert inv1.latch() == 9.0  # held (ZOH) while no new reference arrives
    assert inv1.latch() == 9.0


def test_zoh_motor_sees_the_held_voltage():
    """Over a period the motor integrates exactly the latched constant voltage."""
    from mock_hw.motor import InductionMotor

    rig = make_mock_rig(MockConfig())
    plant = rig.truth
    ref = InductionMotor(plant.motor.params)
    with rig:
        for k in range(40):
            rig.read(k * DT)
            rig.write(Command(u_s_ref=150 * cmath.exp(1j * 300 * k * DT), enable=True))
            if k >= 1:
                # the plant applied over [t_{k-1}, t_k) the reference from tick k-2
                u = 150 * cmath.exp(1j * 300 * (k - 2) * DT) if k >= 2 else 0j
                assert u_truth(rig) == pytest.approx(u, abs=1e-12)
                if k >= 2:
                    ref.step(u, 0.0, DT)
        assert abs(plant.motor.i_s - ref.i_s) < 1e-12 + 1e-9 * abs(ref.i_s)
        assert abs(ref.i_s) > 0.5


@pytest.mark.parametrize("u_dc", [560.0, 600.0])
def test_voltage_limit_is_svpwm_linear_range(u_dc):
    inv = Inverter(u_dc, delay=0)
    inv.enable()
    lim = u_dc / math.sqrt(3.0)
    assert inv.u_max == pytest.approx(lim)
    for ang in (0.0, 0.3, 2.0, -1.2):
        big = 1000.0 * cmath.exp(1j * ang)
        inv.set_voltage(big)
        u = inv.latch()
        assert abs(u) == pytest.approx(lim, rel=1e-12)
        assert cmath.phase(u) == pytest.approx(ang, abs=1e-12)
        # at the SVPWM limit the line-to-line voltage just reaches u_dc
        a, b, c = phase_values(u)
        assert max(abs(a - b), abs(b - c), abs(c - a)) <= u_dc * (1 + 1e-12)
        small = 0.5 * lim * cmath.exp(1j * ang)
        inv.set_voltage(small)
        assert inv.latch() == small


@pytest.mark.parametrize("i_s", [1.0 + 0j, -1.0 + 0j, 0.3 + 2j, -2 - 0.1j])
def test_dead_time_error_has_opposite_sign_of_phase_current(i_s):
    t_d, f_pwm, u_dc = 2e-6, 15e3, 560.0
    inv = Inverter(u_dc, delay=0, dead_time=t_d, f_pwm=f_pwm)
    inv.enable()
    inv.set_voltage(100.0 + 50j)
    u = inv.latch(i_s)
    du = t_d * f_pwm * u_dc  # 16.8 V per phase
    ia, ib, ic = phase_values(i_s)
    want = space_vector(*(-du * math.copysign(1.0, i) for i in (ia, ib, ic)))
    assert u - (100.0 + 50j) == pytest.approx(want, abs=1e-9)
    # it opposes the current: the error removes power from the current direction
    assert (want * i_s.conjugate()).real < 0
    # the error vector has the six-step amplitude 4/3 du
    assert abs(want) == pytest.approx(4.0 / 3.0 * du)


def test_dead_time_off_by_default():
    inv = Inverter(delay=0)
    inv.enable()
    inv.set_voltage(10.0)
    assert inv.latch(3 + 1j) == 10.0


def test_coast_mode_forces_zero_current():
    rig = make_mock_rig(MockConfig())
    plant = rig.truth
    with rig:
        for k in range(300):  # magnetise and spin up a little
            rig.read(k * DT)
            rig.write(Command(u_s_ref=100 * cmath.exp(1j * 60 * k * DT), enable=True))
        assert abs(plant.motor.i_s) > 1.0 and rig.inverter.status().enabled
        rig.read(300 * DT)
        rig.write(Command(enable=False))  # disable in tick 300: gates blocked at once
        assert not rig.inverter.status().enabled
        i_m = plant.motor.i_m
        rig.read(301 * DT)  # [t_300, t_301) coasts
        assert plant.motor.i_s == 0j and plant.motor.m_e == 0.0
        assert 0 < abs(plant.motor.i_m) < abs(i_m)  # the flux decays, not vanishes
        rig.read(302 * DT)
        m = rig.read(303 * DT)
        assert abs(m.i_s) < 0.05  # the sensors see (nearly) no current


def test_status_and_fault():
    inv = Inverter(560.0)
    st = inv.status()
    assert (st.enabled, st.fault, st.u_dc) == (False, False, 560.0)
    assert inv.u_dc_nominal == 560.0
    inv.enable()
    inv.set_voltage(50.0)
    inv.latch()
    assert inv.status().enabled
    inv.latch()
    assert inv.latch() == 50.0 and inv.on
    inv.inject_fault("overcurrent")
    st = inv.status()
    assert st.fault and not st.enabled
    assert inv.latch() == 0j and not inv.on  # bridge off from the next period
    inv.enable()  # ignored while faulted
    inv.latch()
    assert inv.latch() == 0j and inv.status().fault
    inv.reset_fault()
    inv.latch()
    assert inv.latch() == 0j and not inv.status().fault  # needs a new enable
    inv.enable()
    inv.latch()
    assert inv.latch() == 50.0


def test_fault_is_reported_through_the_rig():
    rig = make_mock_rig(MockConfig())
    with rig:
        rig.read(0.0)
        rig.write(Command(u_s_ref=20.0, enable=True))
        rig.inverter.inject_fault()
        m = rig.read(DT)
        assert m.inv_fault and not m.inv_enabled
    assert not rig.inverter.status().enabled
