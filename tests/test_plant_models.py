"""The mock plant's non-ideal models: inverter voltage error (dead time, on-state drop, soft knee),
main-flux saturation and the thermal state. Each is off by default and then changes nothing; on, each
is checked against closed forms and balances that do not reuse its construction."""

from __future__ import annotations

import cmath
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from bench.core import config
from bench.errors import BadInput
from bench.params import T_S_DEFAULT, MotorParams
from bench.runtime.session import RunOptions, run
from mock_hw.inverter import Inverter
from mock_hw.motor import InductionMotor, SaturatedInductionMotor, Saturation
from mock_hw.plant import TRUTH_FIELDS, MockConfig, MockPlant, resolve_engine
from mock_hw.thermal import ALPHA_AL, ALPHA_CU, ThermalModel, resistance

P = MotorParams()
DT = T_S_DEFAULT
SQ3 = math.sqrt(3.0)


def phases(x: complex) -> tuple[float, float, float]:
    """Phase values of an amplitude-invariant space vector (3.17) without zero sequence."""
    return x.real, -0.5 * x.real + 0.5 * SQ3 * x.imag, -0.5 * x.real - 0.5 * SQ3 * x.imag


def trajectory(cfg: MockConfig, n: int = 2400) -> list[tuple]:
    """Everything a log holds of a plant run (truth and the sensors' codes), with a coast in it."""
    p = MockPlant(cfg, seed=4)
    p.inverter.enable()
    out = []
    for k in range(n):
        t = k * DT
        f = min(30.0, 75.0 * t)
        p.inverter.set_voltage((15.0 + 6.5 * f) * cmath.exp(1j * 2 * math.pi * f * t))
        if k == 1500:
            p.inverter.disable()
        if k == 1800:
            p.inverter.enable()
        p.step()
        out.append((p.sample(), p.currents.read_raw(), p.voltages.read_raw(), p.encoder.read()))
    return out


# --- off by default: the plant is what it was ------------------------------------------------------
OFF = {"inverter": {"v_on": 0.0, "i_knee": 0.0}, "motor": {"saturation": False},
       "thermal": {"enabled": False, "time_scale": 100.0}}  # fmt: skip


@pytest.mark.parametrize("extra", [{}, {"inverter": {"dead_time": 2e-6}}, {"motor": {"R_r": 4.95}}])
def test_everything_off_is_bit_identical_to_the_default_plant(extra):
    """The new knobs at their off values change no bit of truth or measurements (the plant before
    them is the default one: tests/test_compiled_plant.py keeps that bit-identical to the compiled
    engine, which has none of the new code)."""
    a = MockConfig.from_dict(extra)
    merged = {k: {**OFF.get(k, {}), **extra.get(k, {})} for k in {*OFF, *extra}}
    b = MockConfig.from_dict(merged)
    pa, pb = MockPlant(a), MockPlant(b)
    assert pa.fields is TRUTH_FIELDS and pb.fields is TRUTH_FIELDS and pb.thermal is None
    assert type(pb.motor) is InductionMotor
    assert trajectory(a) == trajectory(b)


def test_everything_off_keeps_the_compiled_engine():
    pytest.importorskip("numba")
    from mock_hw import compiled as cm

    cfg = MockConfig.from_dict({**OFF, "engine": "compiled"})
    p = MockPlant(cfg)
    assert p.engine == "compiled" and type(p.motor) is cm.MotorView and p.thermal is None
    assert resolve_engine("auto") == "compiled"


# --- inverter voltage error ------------------------------------------------------------------------
def dc_plant(u: complex, **inverter: object) -> MockPlant:
    """Standstill (shaft held), DC voltage reference, run to steady state (slowest pole 0.18 s: 6 s)."""
    cfg = MockConfig.from_dict({"inverter": inverter, "motor": {"hold_speed": True}, "currents": {"noise_std": 0.0}})
    p = MockPlant(cfg)
    p.inverter.enable()
    p.inverter.set_voltage(u)
    p.step(18000)
    return p


@pytest.mark.parametrize("u,v_on", [(20.0, 1.5), (-20.0, 1.5), (12.0, 0.7)])
def test_dc_steady_state_with_on_state_drop(u, v_on):
    """DC along phase a (i_b = i_c = -i_a/2): two devices conduct in series with 3/2 R_s, so the line
    voltage is 3/2 R_s i + 2 v_on; in space vectors u = R_s i + 4/3 v_on sign(i)."""
    p = dc_plant(u, v_on=v_on)
    i = p.motor.i_s
    assert abs(i.imag) < 1e-9
    assert u == pytest.approx(P.R_s * i.real + 4.0 / 3.0 * v_on * math.copysign(1.0, i.real), rel=1e-9)
    assert p.sample()[TRUTH_FIELDS.index("u_s_re")] == pytest.approx(P.R_s * i.real, rel=1e-9)  # applied voltage


def test_dc_steady_state_with_per_phase_drops_and_dead_time():
    """Unequal drops: the error is the space vector of the phase errors, here with a beta part."""
    va, vb, vc, t_d = 1.0, 2.0, 0.5, 1e-6
    u = 25.0
    p = dc_plant(u, v_on=[va, vb, vc], dead_time=t_d)
    ia, ib, ic = phases(p.motor.i_s)
    assert ia > 0 and ib < 0 and ic < 0
    d = t_d * 15e3 * 560.0
    # per phase: R_s i_x = u_x - (d + v_x) sign(i_x) up to a common-mode voltage (isolated neutral)
    ua, ub, uc = phases(u)
    ea, eb, ec = -(d + va), d + vb, d + vc
    r = [P.R_s * ia - ua - ea, P.R_s * ib - ub - eb, P.R_s * ic - uc - ec]
    assert max(r) - min(r) == pytest.approx(0.0, abs=1e-9)


def test_soft_knee_dc_steady_state():
    """With the soft sign s(i) = i/sqrt(i^2 + k^2) the DC steady state solves
    u = R_s i + 2/3 v (s(i) + s(i/2)) (phase a carries i, phases b and c carry -i/2 each)."""
    v, k, u = 2.0, 0.5, 3.0
    p = dc_plant(u, v_on=v, i_knee=k)
    i = p.motor.i_s.real
    s = lambda x: x / math.sqrt(x * x + k * k)  # noqa: E731
    assert 0 < i < 2 * k  # in the knee: the hard sign would give (3 - 8/3)/5 = 0.067 A
    assert P.R_s * i + 2.0 / 3.0 * v * (s(i) + s(0.5 * i)) == pytest.approx(u, rel=1e-9)


def test_voltage_error_is_dissipative_and_continuous_with_a_knee():
    rng = np.random.default_rng(1)
    inv = Inverter(560.0, delay=0, dead_time=1e-6, v_on=(1.0, 1.2, 0.8), i_knee=0.3)
    hard = Inverter(560.0, delay=0, dead_time=1e-6, v_on=(1.0, 1.2, 0.8))
    for _ in range(200):
        i = complex(*rng.normal(0, 2, 2))
        for e in (inv.voltage_error(i), hard.voltage_error(i)):
            assert (e * i.conjugate()).real <= 0.0  # it never feeds power into the current
        # the knee only lowers the magnitude, per phase, toward the hard value
        assert abs(inv.voltage_error(i)) <= abs(hard.voltage_error(i)) + 1e-12
    e_plus, e_minus = inv.voltage_error(1e-7 + 0j), inv.voltage_error(-1e-7 + 0j)
    assert abs(e_plus - e_minus) < 1e-5  # continuous through zero current
    h_plus, h_minus = hard.voltage_error(1e-7 + 0j), hard.voltage_error(-1e-7 + 0j)
    assert abs(h_plus - h_minus) > 20.0  # the hard sign jumps by 2 * 4/3 (d + v)


# --- main-flux saturation ------------------------------------------------------------------------
SAT = Saturation(P.L_m)


def test_saturation_curve_at_rated_flux_and_its_derivatives():
    assert SAT.L_m_of(SAT.psi_rated) == pytest.approx(P.L_m, rel=1e-14)
    assert SAT.L_m0 == pytest.approx(P.L_m * (1 + (0.88 / 1.1) ** 7), rel=1e-14)
    psi = np.linspace(0.01, 1.5, 60)
    i = np.array([SAT.i_mu(x) for x in psi])
    assert np.all(np.diff(i) > 0)  # one current per flux
    assert all(SAT.L_m_of(a) > SAT.L_m_of(b) for a, b in zip(psi[:-1], psi[1:]))  # it saturates
    h = 1e-6
    for x in (0.2, 0.88, 1.2):
        # incremental inductance = d psi / d i_mu; stored energy' = 3/2 i_mu (3.17 scaling)
        assert SAT.L_dyn(x) == pytest.approx(2 * h / (SAT.i_mu(x + h) - SAT.i_mu(x - h)), rel=1e-7)
        assert (SAT.energy(x + h) - SAT.energy(x - h)) / (2 * h) == pytest.approx(1.5 * SAT.i_mu(x), rel=1e-7)
        assert SAT.L_dyn(x) < SAT.L_m_of(x)
    for w, g in ((0.5, 0.0), (3.0, 1 / 0.011), (400.0, 2 / 0.011), (1e-9, 10.0)):
        x = SAT.solve(w, g)
        assert SAT.i_mu(x) + g * x == pytest.approx(w, rel=1e-12)


def drive(m: InductionMotor, T: float, h: float, coast: tuple[int, int] = (-1, -1)) -> None:
    for k in range(round(T / h)):
        t = k * h
        f = min(50.0, 50.0 * t / 0.3)  # V/f start-up, a coast, a load step
        m.coast = coast[0] <= k < coast[1]
        m.step((20.0 + 6.0 * f) * cmath.exp(1j * math.pi * f * t), 4.0 if t > 0.35 else 0.0, h)


def test_saturated_model_without_saturation_is_the_linear_model():
    """psi_sat -> infinity: the flux-state model and (3.41) are linear transforms of each other; RK4
    commutes with those, so the trajectories agree to rounding, coasting included."""
    lin = InductionMotor(P)
    sat = SaturatedInductionMotor(P, Saturation(P.L_m, psi_sat=1e6))
    drive(lin, 0.6, DT, (1000, 1200))
    drive(sat, 0.6, DT, (1000, 1200))
    assert abs(lin.omega_r) > 50
    assert abs(sat.i_s - lin.i_s) < 1e-9 and abs(sat.i_m - lin.i_m) < 1e-9
    assert sat.omega_r == pytest.approx(lin.omega_r, abs=1e-9) and sat.m_e == pytest.approx(lin.m_e, abs=1e-9)
    assert abs(sat.psi_s - lin.psi_s) < 1e-9 and sat.magnetic_energy() == pytest.approx(lin.magnetic_energy())


@pytest.mark.parametrize("psi", [0.3, 0.88, 1.1])
def test_no_load_steady_state_lies_on_the_saturation_curve(psi):
    """Shaft at synchronous speed: no rotor current, i_s = i_mu. The stator flux from the voltage
    equation (3.26), psi_s = (u - R_s i_s)/(j w), less the leakage flux L_ss i_s, is the main flux:
    (|psi_m|, |i_s|) must lie on the curve. At 0.3 Wb L_m is 21 % above rated; at 1.05 Wb it is 0.71
    of rated, and the linear model's current is 30 % short."""
    w = 2 * math.pi * 10.0
    u_amp = psi * w * 1.04  # roughly psi plus the stator's drops
    m = SaturatedInductionMotor(P, SAT, hold_speed=True, omega_r0=w)
    n = round(2.0 / DT)
    for k in range(n):
        m.step(u_amp * cmath.exp(1j * w * (k + 0.5) * DT), 0.0, DT)
    t_end = n * DT
    u = u_amp * cmath.exp(1j * w * t_end)
    i_s = m.i_s
    assert abs(m.i_rs) < 1e-3 * abs(i_s)
    psi_s = (u - P.R_s * i_s) / (1j * w)
    psi_m = abs(psi_s) - (P.L_s - P.L_m) * abs(i_s)
    assert abs(i_s) == pytest.approx(SAT.i_mu(psi_m), rel=2e-3)
    lin_i = psi_m / P.L_m
    if psi > 1.0:
        assert abs(i_s) > 1.3 * lin_i
    elif psi < 0.5:
        assert abs(i_s) == pytest.approx(psi_m / SAT.L_m0, rel=2e-3) and abs(i_s) < 0.85 * lin_i


def test_power_balance_of_the_saturated_model():
    """int p_in dt = W(T) - W(0) + int copper losses + int m_e omega_mech, with W the leakage fields
    plus (3/2) int i_mu dpsi: only a consistent torque and flux model balances."""
    m = SaturatedInductionMotor(P, SAT)
    h = 1.0 / 60000
    W0 = m.magnetic_energy()
    e_in = e_cu = e_mech = 0.0
    peak = 0.0
    for k in range(round(0.35 / h)):
        t = k * h
        u = 200.0 * cmath.exp(1j * 2 * math.pi * 25.0 * t) * min(1.0, 0.3 + t / 0.1)
        m_L = 2.0 if t > 0.25 else 0.0

        def powers() -> tuple[float, float, float]:
            return 1.5 * (u * m.i_s.conjugate()).real, m.copper_losses(), m.m_e * m.omega_mech

        a = powers()
        m.step(u, m_L, h)
        b = powers()
        e_in += 0.5 * h * (a[0] + b[0])
        e_cu += 0.5 * h * (a[1] + b[1])
        e_mech += 0.5 * h * (a[2] + b[2])
        peak = max(peak, abs(m.psi_m))
    assert peak > 1.1 and m.L_m_now < 0.8 * SAT.L_m0  # it went deep into saturation
    assert abs(m.omega_r) > 10.0
    assert e_in == pytest.approx(m.magnetic_energy() - W0 + e_cu + e_mech, rel=1e-5)


def test_saturated_plant_truth_and_coast():
    cfg = MockConfig.from_dict({"motor": {"saturation": True}})
    p = MockPlant(cfg)
    assert p.fields == TRUTH_FIELDS + ("psi_m", "l_m")
    p.inverter.enable()
    for k in range(900):
        p.inverter.set_voltage(60.0 * cmath.exp(1j * 2 * math.pi * 10.0 * k * DT))
        p.step()
    tr = p.truth()
    assert tr["psi_m"] > 0.3 and tr["l_m"] == pytest.approx(SAT.L_m_of(tr["psi_m"]))
    assert math.hypot(tr["psi_r_re"], tr["psi_r_im"]) == pytest.approx(abs(p.motor.psi_r), rel=1e-12)
    p.inverter.disable()
    p.step(3)
    assert p.motor.i_s == 0j and p.truth()["m_e"] == 0.0
    psi0 = abs(p.motor.psi_r)
    p.step(300)  # the rotor flux decays through the rotor circuit alone
    assert 0.0 < abs(p.motor.psi_r) < psi0


# --- thermal state -------------------------------------------------------------------------------
def test_resistance_of_temperature():
    assert resistance(5.0, ALPHA_CU, 20.0) == 5.0
    assert resistance(5.0, ALPHA_CU, 95.0) == pytest.approx(5.0 * 1.29475)
    assert resistance(3.3, ALPHA_AL, 144.0) == pytest.approx(1.5 * 3.3, rel=2e-3)  # the hot rotor of Sec. 3.4
    th = ThermalModel(5.0, 3.3, T_amb=40.0, rise_r0=10.0)
    assert th.R_s == pytest.approx(5.0 * (1 + 0.00393 * 20)) and th.R_r == pytest.approx(3.3 * (1 + 0.00403 * 30))


@pytest.mark.parametrize("k", [1.0, 100.0])
def test_step_of_losses_rises_with_the_time_constant_to_p_r_th(k):
    th = ThermalModel(5.0, 3.3, T_amb=25.0, R_th_s=0.4, tau_s=600.0, R_th_r=0.9, tau_r=300.0, time_scale=k)
    P_s, P_r = 150.0, 80.0
    h = 0.01 * 300.0 / k
    for _ in range(100):  # t = tau_r / k
        th.advance(P_s, P_r, h)
    assert th.T_r - 25.0 == pytest.approx(P_r * 0.9 * (1 - math.exp(-1)), rel=1e-9)
    assert th.T_s - 25.0 == pytest.approx(P_s * 0.4 * (1 - math.exp(-0.5)), rel=1e-9)
    th.advance(P_s, P_r, 40 * 600.0 / k)  # 40 stator time constants
    assert th.T_s - 25.0 == pytest.approx(P_s * 0.4, rel=1e-12) and th.T_r - 25.0 == pytest.approx(P_r * 0.9)


def test_coupled_network_balances_heat():
    """With stator-rotor coupling, at steady state each node's loss leaves to ambient and across the gap;
    along the way, heat in = heat stored + heat out."""
    th = ThermalModel(5.0, 3.3, G_sr=2.0, R_th_s=0.35, tau_s=100.0, R_th_r=0.8, tau_r=80.0)
    P_s, P_r = 200.0, 100.0
    h, e_out, xs, xr = 0.05, 0.0, 0.0, 0.0
    for _ in range(4000):  # 200 s
        th.advance(P_s, P_r, h)
        ys, yr = th.T_s - 20.0, th.T_r - 20.0
        e_out += 0.5 * h * (xs / 0.35 + ys / 0.35 + xr / 0.8 + yr / 0.8)  # trapezoid
        xs, xr = ys, yr
    stored = th.C_s * xs + th.C_r * xr
    assert stored + e_out == pytest.approx((P_s + P_r) * 200.0, rel=1e-4)
    th.advance(P_s, P_r, 1e5)
    xs, xr = th.T_s - 20.0, th.T_r - 20.0
    assert P_s == pytest.approx(xs / 0.35 + 2.0 * (xs - xr), rel=1e-12)
    assert P_r == pytest.approx(xr / 0.8 + 2.0 * (xr - xs), rel=1e-12)
    assert (th.T_s, th.T_r) == pytest.approx(th.steady_state(P_s, P_r), rel=1e-12)


def test_warm_plant_stays_cold_without_current_and_reports_truth():
    p = MockPlant(MockConfig.from_dict({"thermal": {"enabled": True}}))
    assert p.fields == TRUTH_FIELDS + ("temp_s", "temp_r", "r_s", "r_r")
    p.step(300)
    tr = p.truth()
    assert (tr["temp_s"], tr["temp_r"], tr["r_s"], tr["r_r"]) == (20.0, 20.0, P.R_s, P.R_r)


def test_dc_current_follows_the_hot_stator_resistance():
    """Thermal on (compressed 100x), DC at standstill: the current falls as the winding warms, and at
    each moment it is the steady state u/R_s(T_s) of the resistance the truth reports. The electrical
    model does use R(T)."""
    cfg = MockConfig.from_dict({"motor": {"hold_speed": True}, "thermal": {"enabled": True, "time_scale": 100.0}})
    p = MockPlant(cfg)
    p.inverter.enable()
    p.inverter.set_voltage(30.0)
    p.step(round(1.0 / DT))
    i_cold = p.motor.i_s.real
    assert i_cold == pytest.approx(30.0 / p.truth()["r_s"], rel=2e-3)
    p.step(round(14.0 / DT))
    tr = p.truth()
    assert tr["temp_s"] > 60.0 and tr["r_s"] == pytest.approx(P.R_s * (1 + ALPHA_CU * (tr["temp_s"] - 20)))
    assert tr["i_s_re"] == pytest.approx(30.0 / tr["r_s"], rel=2e-3) and tr["i_s_re"] < 0.87 * i_cold
    assert tr["r_r"] == pytest.approx(P.R_r, rel=1e-3)  # no rotor current at DC steady state


def test_mock_warm_rotor_resistance_rises_40_percent_within_tens_of_seconds():
    """rigs/mock-warm.toml: locked rotor, 55 V at 10 Hz (about 6 A): R_r +40 % in under 30 simulated seconds."""
    rig = config.load("mock-warm")
    cfg = MockConfig.from_dict({**rig.mock, "motor": {"hold_speed": True}})
    p = MockPlant(cfg)
    p.inverter.enable()
    w = 2 * math.pi * 10.0
    t_40 = None
    for s in range(30):
        for k in range(3000):
            p.inverter.set_voltage(55.0 * cmath.exp(1j * w * (s * 3000 + k) * DT))
            p.step()
        if t_40 is None and p.truth()["r_r"] >= 1.4 * P.R_r:
            t_40 = s + 1
    tr = p.truth()
    assert 4.0 < math.hypot(tr["i_s_re"], tr["i_s_im"]) < 8.0
    assert t_40 is not None and t_40 <= 30, tr
    assert tr["r_r"] == pytest.approx(P.R_r * (1 + ALPHA_AL * (tr["temp_r"] - 20)))


# --- configuration and engines -------------------------------------------------------------------
@pytest.mark.parametrize("d,field,words", [
    ({"inverter": {"v_on": -1.0}}, "mock.inverter.v_on", "in [0, 10]"),
    ({"inverter": {"v_on": [1.0, 2.0]}}, "mock.inverter.v_on", "list of 3"),
    ({"inverter": {"i_knee": "0.1"}}, "mock.inverter.i_knee", "finite number in [0, 100]"),
    ({"motor": {"sat_exp": 0.5}}, "mock.motor.sat_exp", "in [1, 30]"),
    ({"motor": {"saturation": "yes"}}, "mock.motor.saturation", "true or false"),
    ({"motor": {"saturation": True, "L_m": 0.35, "L_s": 0.4, "L_r": 0.34}}, "mock.motor.saturation", "L_m < L_r"),
    ({"thermal": {"time_scale": 0.5}}, "mock.thermal.time_scale", "in [1, 100000]"),
    ({"thermal": {"tau": 3.0}}, "mock.thermal.tau", "allowed: enabled, T_amb"),
    ({"thermal": {"T_amb": 500}}, "mock.thermal.T_amb", "in [-40, 100]"),
    ({"thermal": 1}, "mock.thermal", "must be a table"),
])  # fmt: skip
def test_bad_settings_name_the_field(d, field, words):
    with pytest.raises(BadInput) as ei:
        MockConfig.from_dict(d)
    assert ei.value.field == field and words in ei.value.problem and "\n" not in str(ei.value)


@pytest.mark.parametrize("rig", ["mock-warm", "mock-real"])
def test_sessions_log_the_same_with_both_engines(rig):
    """The compiled plant has every model: a session logs the same to the last bit with either engine
    (tests/test_compiled_plant.py checks the plant calls between ticks)."""
    pytest.importorskip("numba")
    from bench.runtime.loop import TIMING_FIELDS

    logs = []
    for engine in ("python", "compiled"):
        cfg = config.load(rig)
        mock = {**cfg.mock, "engine": engine, "thermal": {**cfg.mock.get("thermal", {}), "enabled": True}}
        cfg = replace(cfg, mock=mock)
        summary, code = run(RunOptions(rig=cfg, scenario="load6.4.1", seed=3, duration=1.0, progress=False,
                                       log_enabled=False))  # fmt: skip
        assert code == 0
        rec = summary["record"]
        logs.append({tp: rec.read(tp) for tp in ("/rig", "/truth")})
    a, b = logs
    assert a["/truth"]["temp_r"][-1] > a["/truth"]["temp_r"][0]  # it warmed
    assert ("psi_m" in a["/truth"]) == (rig == "mock-real")
    for tp in a:
        for f in a[tp]:
            if f not in TIMING_FIELDS:
                assert np.array_equal(a[tp][f], b[tp][f]), (tp, f)


def test_round_trip_of_the_new_settings():
    d = {"inverter": {"v_on": [1.0, 1.1, 0.9], "i_knee": 0.2}, "motor": {"saturation": True, "psi_sat": 1.2},
         "thermal": {"enabled": True, "G_sr": 1.5, "time_scale": 50.0, "rise_r0": 5.0}}  # fmt: skip
    cfg = MockConfig.from_dict(d)
    assert MockConfig.from_dict(cfg.as_dict()) == cfg
    assert cfg.inverter.v_on == (1.0, 1.1, 0.9) and cfg.thermal.G_sr == 1.5


def test_bad_setting_in_a_rig_file_exits_2_with_one_line(tmp_path):
    text = (config.RIGS_DIR / "mock-warm.toml").read_text().replace("time_scale = 100.0", "time_scale = 0.1")
    rig = tmp_path / "bad.toml"
    rig.write_text(text)
    r = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(rig), "--duration", "0.1"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "mock.thermal.time_scale" in lines[0] and "Traceback" not in r.stderr


@pytest.mark.parametrize("name,extra", [("mock-real", ("psi_m", "l_m")),
                                        ("mock-warm", ("temp_s", "temp_r", "r_s", "r_r"))])
def test_example_rigs_run_a_session_and_log_the_extra_truth(name, extra):
    cfg = config.load(name)
    summary, code = run(RunOptions(rig=cfg, scenario="demo", seed=1, duration=0.6, progress=False, log_enabled=False))
    assert code == 0, summary
    truth = summary["record"].read("/truth")
    assert {f.lower() for f in TRUTH_FIELDS + extra} <= set(truth)  # the log's field names are lower case
    assert np.all(np.isfinite(truth[extra[0]]))
    if name == "mock-warm":
        assert np.all(np.diff(truth["temp_s"]) >= -1e-12)  # only heating from ambient
        assert truth["r_s"][0] == pytest.approx(P.R_s, rel=1e-6)


def test_saturated_motor_state_set_from_currents_reads_back():
    m = SaturatedInductionMotor(P, SAT)
    m.reset(i_s=3 - 2j, i_m=2.5 + 1j, omega_r=120.0, theta_mech=0.3)
    assert abs(m.i_s - (3 - 2j)) < 1e-12 and abs(m.i_m - (2.5 + 1j)) < 1e-12
    assert m.psi_r == pytest.approx(P.L_m * (2.5 + 1j))
    # the T circuit holds: psi_s = L_ss i_s + psi_m, psi_r = L_rs i_rs + psi_m, psi_m = L_m(|psi_m|)(i_s + i_rs)
    assert abs(m.psi_s - ((P.L_s - P.L_m) * m.i_s + m.psi_m)) < 1e-12
    assert abs(m.psi_r - ((P.L_r - P.L_m) * m.i_rs + m.psi_m)) < 1e-12
    assert abs(m.psi_m - SAT.L_m_of(abs(m.psi_m)) * (m.i_s + m.i_rs)) < 1e-12
    with pytest.raises(NotImplementedError):
        m.derivatives(0j, 0.0)


def test_emulated_rig_runs_the_models_and_logs_their_truth():
    """The device emulators run the same plant: the extra truth reaches the host's log."""
    from mock_hw.emulators.testing import emulated_config

    cfg = emulated_config("virtual", mock={"motor": {"saturation": True}, "thermal": {"enabled": True},
                                           "inverter": {"v_on": 1.0}})  # fmt: skip
    summary, code = run(RunOptions(rig=cfg, scenario="demo", seed=2, duration=0.4, progress=False, log_enabled=False))
    assert code == 0, summary
    truth = summary["record"].read("/truth")
    assert {"psi_m", "l_m", "temp_s", "temp_r", "r_s", "r_r"} <= set(truth)
    assert np.nanmax(truth["psi_m"]) > 0.1 and np.nanmax(truth["temp_s"]) > 20.0
