"""The compiled plant engine (mock_hw.compiled) against the Python reference: same logs to the last bit."""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
import pytest

from bench.core.config import load as load_rig
from bench.errors import BadInput
from bench.runtime.loop import TIMING_FIELDS
from bench.params import T_S_DEFAULT
from bench.runtime.session import RunOptions, run
from mock_hw.plant import MockConfig, MockPlant, resolve_engine

pytest.importorskip("numba")
DT = T_S_DEFAULT


def session(engine: str, scenario: str, seed: int, duration: float, fault: str | None = None) -> tuple[dict, dict]:
    cfg = load_rig("mock")
    cfg = replace(cfg, mock={**cfg.mock, "engine": engine})
    summary, code = run(RunOptions(rig=cfg, scenario=scenario, seed=seed, duration=duration, progress=False,
                                   log_enabled=False, inject_fault=fault))  # fmt: skip
    rec = summary.pop("record")
    return summary, {tp: rec.read(tp) for tp in rec.topics()}


@pytest.mark.parametrize("scenario,seed,duration,limits", [
    ("demo", 0, 2.0, {}),
    ("fig5.7", 1, 0.8, {}),
    ("fig5.7", 7, 0.5, {}),
    ("load6.4.1", 3, 0.6, {}),
    ("demo", 5, 0.6, {"fault": "over-speed"}),  # an over-speed trip (injected): safe state, the plant coasts
])  # fmt: skip
def test_sessions_log_the_same_with_both_engines(scenario, seed, duration, limits):
    sp, lp = session("python", scenario, seed, duration, **limits)
    sc, lc = session("compiled", scenario, seed, duration, **limits)
    assert sp["ticks"] == sc["ticks"] and sp.get("trip_cause") == sc.get("trip_cause")
    if limits:
        assert sc.get("trip_cause"), "the run was meant to trip"
    assert set(lp) == set(lc) and {"/rig", "/truth"} <= set(lp)
    for topic in lp:
        for f, a in lp[topic].items():
            if f in TIMING_FIELDS:
                continue
            b = lc[topic][f]
            # bit for bit; on a mismatch say how far off it is
            assert np.array_equal(a, b), (topic, f, float(np.max(np.abs(a - b))))


def vf(k: int) -> complex:
    t = k * DT
    f = min(30.0, 75.0 * t)
    return (15.0 + 6.5 * f) * cmath.exp(1j * 2 * math.pi * f * t)


def state(p: MockPlant) -> tuple:
    m = p.motor
    return (p.k, m.i_s, m.i_m, m.omega_r, m.theta_mech, m.u_s, m.m_L, m.coast, p.load.m_L, p.voltages.y,
            p.voltages.dy, p.inverter.on, p.inverter.u_applied, p.inverter.status(), p.currents.read(),
            p.currents.read_raw(), p.voltages.read(), p.voltages.read_raw(), p.encoder.read(), p.sample())  # fmt: skip


@pytest.mark.parametrize("extra", [
    {},
    {"inverter": {"dead_time": 2e-6}, "substeps": 3},
    {"inverter": {"dead_time": 1e-6, "v_on": [1.0, 1.6, 0.4], "i_knee": 0.3}},  # voltage error, soft knee
    {"inverter": {"v_on": 1.5}},  # on-state drop alone, hard sign
    {"thermal": {"enabled": True, "time_scale": 1e4, "G_sr": 1.0, "rise_r0": 30.0, "T_amb": 35.0}},  # R(T)
    {"motor": {"saturation": True, "psi_sat": 0.9}, "substeps": 2},  # main-flux saturation (flux-state model)
    {"motor": {"saturation": True, "hold_speed": True, "omega_r0": 60.0},
     "thermal": {"enabled": True, "time_scale": 1e4},
     "inverter": {"dead_time": 1e-6, "v_on": 1.2, "i_knee": 0.2}},  # everything at once
    {"inverter": {"delay": 0, "u_dc": 300.0}, "motor": {"hold_speed": True, "omega_r0": 80.0}},
    {"currents": {"noise_std": 0.0, "gain_error": [0.01, -0.02, 0.0], "offset": 0.01},
     "encoder": {"index_angle": 1.0, "modulus": 5000}},
])  # fmt: skip
def test_plant_calls_between_ticks_act_alike(extra):
    """HAL commands, faults, calibration, skipped ticks, configure, and a Random taken out and used."""
    plants = [MockPlant(MockConfig.from_dict({**extra, "engine": e}), seed=4) for e in ("python", "compiled")]
    assert [p.engine for p in plants] == ["python", "compiled"]
    logs: list[list[tuple]] = [[], []]
    for p, log in zip(plants, logs):
        inv, load, enc = p.inverter, p.load, p.encoder
        inv.enable()
        k, reset = 0, False
        while k < 2400:
            k += 3 if 600 <= k < 630 else 1  # skipped ticks: several periods in one acquire
            p.acquire(k * DT)
            log.append(state(p))
            inv.set_voltage(vf(k) if k % 500 else 400.0 + 0j)  # beyond the voltage limit now and then
            load.set_torque(2.0 if 300 < k < 900 else -20.0 if 1700 < k < 1750 else 0.0)
            if k == 1000:
                enc.inject_stuck(True)
            if k == 1050:
                enc.inject_stuck(False)
                enc.inject_jump(77)
            if k == 1100:
                p.currents.set_offset_cal((0.004, -0.002, 0.001))
                p.voltages.set_offset_cal(0.01)
            if k == 1200:
                inv.inject_fault("test")  # coast
            if k == 1400:
                inv.reset_fault()
                inv.enable()
            if k == 1500:
                log.append(("drawn", p.currents.adc.rng.random(), p.voltages.adc.rng.gauss(0.0, 1.0)))
            if k == 1800:
                inv.disable()
            if k == 1900:
                inv.enable()
            if k == 2000 and not reset:
                reset = True
                p.acquire(k * DT)  # same instant again: a new sample, nothing integrated
                log.append(state(p))
                p.configure()
                k = 0
                inv.enable()
                log.append(state(p))
    assert len(logs[0]) == len(logs[1])
    for i, (a, b) in enumerate(zip(*logs)):
        assert a == b, (i, a, b)


def test_state_attributes_are_views_on_the_buffer():
    p = MockPlant(MockConfig(engine="compiled"))
    p.motor.reset(i_s=1 + 2j, i_m=0.5j, omega_r=10.0, theta_mech=0.25)
    assert (p.motor.i_s, p.motor.i_m, p.motor.omega_r, p.motor.theta_mech) == (1 + 2j, 0.5j, 10.0, 0.25)
    assert type(p.motor.omega_r) is float and p.sample()[6] == 10.0 and p.truth()["i_s_im"] == 2.0
    q = MockPlant(MockConfig(engine="python"))
    q.motor.reset(i_s=1 + 2j, i_m=0.5j, omega_r=10.0, theta_mech=0.25)
    assert p.sample() == q.sample()


def test_engine_option():
    # the reference by default (bench run asks for "auto" in real time and from 25 s simulated: test_session); sweeps ask for "auto" (test_sweep checks)
    assert MockConfig().engine == "python" and resolve_engine("auto") == "compiled"
    assert MockPlant(MockConfig()).engine == "python" and MockPlant(MockConfig(engine="auto")).engine == "compiled"
    assert MockConfig.from_dict({"engine": "python"}).engine == "python"
    assert MockConfig.from_dict(MockConfig(engine="compiled").as_dict()).engine == "compiled"
    with pytest.raises(BadInput) as ei:
        MockConfig.from_dict({"engine": "fast"})
    msg = str(ei.value)
    assert ei.value.field == "mock.engine" and "\n" not in msg
    assert msg == "mock.engine must be one of 'auto', 'compiled', 'python', got 'fast'"
    with pytest.raises(BadInput, match="mock.engine"):
        MockConfig.from_dict({"engine": 1})


def test_the_plant_calls_the_compiled_overloads_without_the_dispatcher():
    from numba.core.dispatcher import Dispatcher

    from mock_hw import compiled as cm

    p = MockPlant(MockConfig(engine="compiled"))
    assert not isinstance(p._advance, Dispatcher) and not isinstance(p._truth, Dispatcher)
    twin = p._buf.copy()
    args = (3, 100 + 50j, True, 120 + 10j, True, 540.0, 1.0)
    direct = p._advance(p._buf, *args)
    assert direct == cm.advance(twin, *args) and p._buf.tobytes() == twin.tobytes()  # same results, same state
    assert p._truth(p._buf) == cm.truth(twin)
    assert p._advance(p._buf, 1, 100, 1, 0, 0, 540, 0) == cm.advance(twin, 1, 100, 1, 0, 0, 540, 0)  # ints converted
