"""The mock plant behind the HAL (mock_hw.plant): lifecycle, timing, truth, config validation."""

from __future__ import annotations

import cmath
import math

import pytest

from bench.errors import BadInput
from bench.hal import Command, Device, LifecycleError, Rig, RigState
from bench.params import T_S_DEFAULT, MotorParams
from bench.perf.plant import measure
from mock_hw.motor import steady_state
from mock_hw.plant import (
    TRUTH_FIELDS, CurrentsConfig, MockConfig, MockPlant, MotorConfig, VoltagesConfig, make_mock_rig,
)  # fmt: skip

DT = T_S_DEFAULT


def vf_command(k: int, f_end: float = 25.0, ramp: float = 0.4) -> Command:
    t = k * DT
    f = min(f_end, f_end * t / ramp)
    # V/f with boost; the phase is the integral of 2 pi f
    ph = math.pi * f_end / ramp * t * t if t < ramp else math.pi * f_end * ramp + 2 * math.pi * f_end * (t - ramp)
    return Command(u_s_ref=(15.0 + 6.5 * f) * cmath.exp(1j * ph), enable=True)


def test_rig_lifecycle_and_open_loop_start_up():
    rig = make_mock_rig(MockConfig())
    assert isinstance(rig, Rig) and rig.name == "mock"
    assert isinstance(rig.truth, MockPlant) and isinstance(rig.truth, Device)
    assert isinstance(rig.truth.fields, tuple) and len(rig.truth.sample()) == len(rig.truth.fields)
    with pytest.raises(LifecycleError):
        rig.activate()
    rig.configure()
    rig.activate()
    assert rig.state is RigState.ACTIVE
    n = round(1.5 / DT)
    speeds = []
    for k in range(n):
        rig.read(k * DT)
        rig.write(vf_command(k))
        if k >= n // 3:
            speeds.append(rig.truth.motor.omega_r)
    meas = rig.read(n * DT)
    tr = rig.truth.truth()
    w_sync = 2 * math.pi * 25.0
    # no load: the rotor runs at synchronous speed less a tiny slip for friction. (Open-loop V/f
    # at light load is poorly damped: the speed swings a few rad/s about that, so average.)
    w_mean = sum(speeds) / len(speeds)
    assert 0.99 * w_sync < w_mean < 1.001 * w_sync
    assert max(speeds) - min(speeds) < 0.15 * w_sync
    assert tr["p_in"] > 0
    # the measurement agrees with the truth within quantisation and noise
    i_true = complex(tr["i_s_re"], tr["i_s_im"])
    assert abs(meas.i_s - i_true) < 0.05
    assert meas.inv_enabled and not meas.inv_fault and meas.u_dc == 560.0
    rig.deactivate()
    assert rig.state is RigState.INACTIVE
    # safe state: inverter disabled, zero reference, load 0 ...
    st = rig.inverter.status()
    assert not st.enabled and rig.load.m_L_ref == 0.0
    # ... and the plant coasts: no stator current, the flux decays, the shaft slows down
    w = tr["omega_r"]
    rig.truth.acquire((n + 300) * DT)
    tr2 = rig.truth.truth()
    assert tr2["i_s_re"] == tr2["i_s_im"] == 0.0 and tr2["m_e"] == 0.0
    assert 0 < tr2["omega_r"] < w
    assert abs(complex(tr2["i_m_re"], tr2["i_m_im"])) < abs(complex(tr["i_m_re"], tr["i_m_im"]))
    rig.deactivate()  # idempotent


def test_truth_fields_are_consistent():
    rig = make_mock_rig(MockConfig())
    plant = rig.truth
    assert plant.fields == TRUTH_FIELDS and len(TRUTH_FIELDS) == 13
    with rig:
        for k in range(500):
            rig.read(k * DT)
            rig.write(vf_command(k))
        s = plant.sample()
    d = dict(zip(plant.fields, s))
    assert all(isinstance(v, float) for v in s)
    p = plant.motor.params
    assert complex(d["psi_r_re"], d["psi_r_im"]) == pytest.approx(p.L_m * complex(d["i_m_re"], d["i_m_im"]))
    assert d["theta_r"] == pytest.approx(p.Z_p * plant.motor.theta_mech)
    i_s, u_s = complex(d["i_s_re"], d["i_s_im"]), complex(d["u_s_re"], d["u_s_im"])
    assert d["p_in"] == pytest.approx(1.5 * (u_s * i_s.conjugate()).real)
    assert d["m_e"] == pytest.approx(p.torque_constant * (i_s * complex(d["i_m_re"], -d["i_m_im"])).imag)


def test_skipped_ticks_are_integrated():
    cmd = Command(u_s_ref=80 + 30j, enable=True, m_L_ref=0.5)
    a, b = MockPlant(MockConfig()), MockPlant(MockConfig())
    for p in (a, b):
        p.inverter.enable()
        p.inverter.set_voltage(cmd.u_s_ref)
        p.load.set_torque(cmd.m_L_ref)
    for k in range(1, 31):
        a.acquire(k * DT)
    b.acquire(10 * DT)
    b.acquire(10 * DT)  # same time again: nothing to integrate
    b.acquire(30 * DT + 1e-9)  # rounds to the grid
    assert a.k == b.k == 30 and b.t == pytest.approx(30 * DT)
    assert a.sample() == b.sample()
    b.acquire(29 * DT)  # time never runs backwards
    assert b.k == 30


def test_same_seed_same_log_other_seed_other_noise():
    def log(seed: int, cfg: MockConfig) -> list:
        rig = make_mock_rig(cfg, seed=seed)
        out = []
        with rig:
            for k in range(200):
                m = rig.read(k * DT)
                out.append((m.raw_i, m.raw_u, m.enc_count, rig.truth.sample()))
                rig.write(vf_command(k))
        return out

    cfg = MockConfig()
    a, b, c = log(1, cfg), log(1, cfg), log(2, cfg)
    assert a == b
    assert [x[0] for x in a] != [x[0] for x in c]
    assert [x[3] for x in a] == [x[3] for x in c]  # noise does not feed back in open loop
    d = log(1, MockConfig(seed=5))
    assert [x[0] for x in a] != [x[0] for x in d]
    quiet = MockConfig(currents=CurrentsConfig(noise_std=0.0), voltages=VoltagesConfig(noise_std=0.0))
    assert log(1, quiet) == log(2, quiet)


@pytest.mark.parametrize("engine", ["python", "compiled"])
def test_plant_measure_equals_the_rigs_assembly_from_the_ports(engine):
    """The mock rig's one-call read (MockPlant.measure) gives, field for field, what Rig.read assembles
    from the ports; with the inverter's delay, a fault and a skipped tick on the way."""
    if engine == "compiled":
        pytest.importorskip("numba")
    cfg = MockConfig(engine=engine)
    fast, ports = make_mock_rig(cfg, seed=3), make_mock_rig(cfg, seed=3)
    ports._measure = None  # Rig.read's general path: acquire every device, read every port
    assert fast._measure is not None
    got: list[list] = [[], []]
    for rig, out in zip((fast, ports), got):
        with rig:
            for k in [*range(0, 120), *range(122, 200)]:
                if k == 150:
                    rig.devices[0].inverter.inject_fault("test")
                out.append(rig.read(k * DT))
                rig.write(vf_command(k))
    assert got[0] == got[1] and len(got[0]) == 198
    assert any(m.inv_fault for m in got[0]) and any(m.inv_enabled for m in got[0])


def test_params_true_overrides_the_config():
    hot = MotorParams().with_(R_r=1.5 * 3.3)
    rig = make_mock_rig(MockConfig(motor=MotorConfig(hold_speed=True, omega_r0=100.0)), params_true=hot)
    plant = rig.truth
    assert plant.motor.params.R_r == pytest.approx(4.95)
    with rig:
        w_mR, u = 110.0, 140.0
        n = 9000
        for k in range(n):
            rig.read(k * DT)
            # the inverter delays by one sample: pre-rotate by one period
            rig.write(Command(u_s_ref=u * cmath.exp(1j * w_mR * (k + 1) * DT), enable=True))
        rig.read(n * DT)
    _, _, m_hot = steady_state(hot, u, w_mR, 100.0)
    _, _, m_cold = steady_state(MotorParams(), u, w_mR, 100.0)
    # (ZOH of a rotating voltage at 3 kHz: small amplitude/phase error, hence 2 %)
    assert plant.motor.m_e == pytest.approx(m_hot, rel=0.02)
    assert abs(m_hot - m_cold) > 0.1 * abs(m_hot)


def test_configure_resets_the_simulation():
    rig = make_mock_rig(MockConfig())
    with rig:
        for k in range(100):
            rig.read(k * DT)
            rig.write(vf_command(k))
    plant = rig.truth
    assert plant.k == 99 and plant.motor.i_m != 0j
    rig.state = RigState.UNCONFIGURED  # a fresh configure, as after a rig re-load
    rig.configure()
    assert plant.k == 0 and plant.motor.i_m == 0j and plant.motor.omega_r == 0.0


# --- configuration --------------------------------------------------------------------------
def test_from_dict_builds_and_round_trips():
    d = {
        "motor": {"R_r": 4.95, "J": 0.02, "omega_eps": 0.02, "hold_speed": True, "omega_r0": 50},
        "inverter": {"u_dc": 600, "dead_time": 2e-6},
        "currents": {"adc_bits": 14, "offset": [0.01, 0.0, -0.01], "gain_error": 0.01},
        "voltages": {"zeta": 1.0},
        "encoder": {"lines": 2048, "modulus": 1 << 32},
        "load": {"tau": 0.005},
        "substeps": 2,
        "seed": 9,
    }
    cfg = MockConfig.from_dict(d)
    assert cfg.motor.params.R_r == 4.95 and cfg.motor.params.L_s == MotorParams().L_s
    assert cfg.motor.hold_speed and cfg.motor.omega_r0 == 50.0
    assert cfg.inverter.u_dc == 600.0 and cfg.currents.gain_error == (0.01, 0.01, 0.01)
    assert cfg.currents.offset == (0.01, 0.0, -0.01)
    assert MockConfig.from_dict(cfg.as_dict()) == cfg
    assert MockConfig.from_dict({}) == MockConfig()
    rig = make_mock_rig(cfg)
    assert rig.encoder.counts_per_rev == 8192 and rig.truth.motor.substeps == 2
    assert rig.inverter.u_max == pytest.approx(600 / math.sqrt(3))


@pytest.mark.parametrize(
    "d,field,words",
    [
        ({"currents": {"adc_bits": 40}}, "mock.currents.adc_bits", "integer in 8..24, got 40"),
        ({"currents": {"adc_bits": 12.0}}, "mock.currents.adc_bits", "integer"),
        ({"currents": {"bits": 12}}, "mock.currents.bits", "allowed: turns_ratio, burden, adc_bits"),
        ({"currents": {"offset": [0.1, 0.2]}}, "mock.currents.offset", "list of 3"),
        ({"inverter": {"u_dc": -5}}, "mock.inverter.u_dc", "in [1, 2000]"),
        ({"inverter": {"delay": 2}}, "mock.inverter.delay", "0..1"),
        ({"motor": {"R_s": 0}}, "mock.motor.R_s", "in [0.001, 1000]"),
        ({"motor": {"L_m": 0.36}}, "mock.motor.L_m", "L_m^2 < L_s*L_r"),
        ({"motor": {"hold_speed": 1}}, "mock.motor.hold_speed", "true or false"),
        ({"encoder": {"lines": 1024, "modulus": 100}}, "mock.encoder.modulus", ">= 4*lines"),
        ({"load": {"tau": float("nan")}}, "mock.load.tau", "in [1e-05, 10]"),
        ({"substeps": 0}, "mock.substeps", "1..1000"),
        ({"inverterr": {}}, "mock.inverterr", "allowed: motor, inverter, currents"),
        ({"voltages": 3}, "mock.voltages", "must be a table"),
    ],
)
def test_from_dict_errors_name_the_field(d, field, words):
    with pytest.raises(ValueError) as ei:
        MockConfig.from_dict(d)
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith(field + " ")
    assert words in msg
    assert isinstance(ei.value, BadInput) and ei.value.field == field  # the CLI's error type


def test_motor_section_accepts_every_motor_parameter():
    from dataclasses import fields

    from mock_hw.plant import _RULES

    names = {f.name for f in fields(MotorParams)}
    assert names <= set(_RULES["motor"])  # a new MotorParams field needs a validation rule
    d = {n: getattr(MotorParams(), n) for n in names}
    assert MockConfig.from_dict({"motor": d}).motor.params == MotorParams()


def test_per_tick_cost_is_in_budget():
    """read + write per tick; the target on the dev machine is about 15 us (bench perf plant)."""
    r = measure(ticks=3000, repeats=2)
    assert r["plant_tick_us"] < 60.0  # generous: a regression guard, not a benchmark
