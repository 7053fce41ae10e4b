"""Every emulator fault (issue 3, section 3) against the real drivers: the supervisor's reaction,
the safe state within one tick, and a complete, readable log up to and after the trip.

Runs are in lockstep with the emulators in-process (python-can virtual bus, socket:// serial,
Modbus TCP on 127.0.0.1); faults are scheduled in seconds of loop time, so each hits the same
sample in every run.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from bench.core import scenarios
from bench.daq import LogReader, LogWriter, Topic
from bench.hal import (
    ST_INV_STALE, ST_LINK_DOWN, ST_MEAS_CRC, ST_MEAS_DUP, ST_MEAS_LATE, ST_MEAS_STALE,
)  # fmt: skip
from bench.runtime.loop import TimedLoop, log_topics
from bench.runtime.compose import build_rig, make_controller
from bench.core.supervisor import Supervisor
from mock_hw.emulators.testing import emulated_config

T = 1.0 / 3000
AT = 0.5  # [s] the motor is accelerating towards 100 rad/s by then (demo scenario)
K_AT = round(AT / T)


def run_emulated(tmp_path: Path, faults: list[dict], duration: float = AT + 0.1, timeout: float = 0.2,
                 **limits) -> tuple[object, LogReader]:  # fmt: skip
    # tests with many intended stale ticks pass a short frame timeout to keep them cheap; the default is
    # long enough that an emulator thread starved of CPU on a loaded machine is not a stale measurement
    cfg = emulated_config("virtual", emulator={"faults": faults}, limits={"ride_through": 0.01, **limits},
                          serial={"timeout": timeout},  # (a drive's set-point watchdog covers its ride-through)
                          can={"heartbeat_timeout": 0.01})  # a real drive's 10 ms: the watchdogs' timing is tested
    rig = build_rig(cfg, seed=1)
    ctrl = make_controller(cfg, rig, "foc", {})
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    path = tmp_path / "fault.mcap"
    topics = [Topic(n, s, f) for n, s, f in log_topics(rig, ctrl)]
    with LogWriter(path, topics, metadata={"run": {"faults": str(faults)}}) as log:
        rig.configure()
        rig.activate()
        try:
            res = TimedLoop(rig, ctrl, scenarios.get("demo"), sup, T_s=cfg.T_s, duration=duration, log=log).run()
        finally:
            rig.deactivate()
    return res, LogReader(path)


def assert_safe_and_logged(res, r: LogReader, status_frames: bool = True) -> int:
    """Trip latched, safe command from the trip tick on, every tick logged; returns the trip tick."""
    loop = cmd = meas = r.read("/rig")
    assert r.summary()["topics"]["/rig"]["messages"] == res.ticks  # complete up to and after the trip
    assert np.all(np.diff(loop["tick"]) == 1)
    tripped = loop["tripped"].astype(bool)
    k = int(np.argmax(tripped))
    assert tripped[k] and not tripped[:k].any() and tripped[k:].all()  # latched
    assert cmd["enable"][:k].all() and not cmd["enable"][k:].any()  # safe in the trip tick itself
    assert np.all(cmd["m_l_ref"][k:] == 0.0)
    assert meas["t"][k] == pytest.approx(res.trip_t)
    truth = r.read("/truth")  # the emulator's plant: the bridge really stops (coasting: i_s = 0)
    # (+1 tick of slack: with the link down the loop does not wait for the emulator's sample)
    assert np.all(truth["i_s_re"][k + 3:] == 0.0) and np.all(truth["i_s_im"][k + 3:] == 0.0)
    if status_frames:  # and the drive reports it (status every 3rd tick)
        assert not meas["inv_enabled"][k + 5:].any()
    return k


def test_no_fault_no_trip_and_clean_status(tmp_path):
    res, r = run_emulated(tmp_path, [])
    assert res.trip_cause is None
    assert not np.any(r.read("/rig")["status"])


def test_single_dropped_frame_is_tolerated_and_logged(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "drop", "at": AT}])
    assert res.trip_cause is None
    st = r.read("/rig")["status"]
    assert np.flatnonzero(st & ST_MEAS_STALE).tolist() == [K_AT]


def test_dropped_frames_trip_stale(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "drop", "at": AT, "duration": 0.01}], timeout=0.01)
    assert res.trip_cause.startswith("measurement stale")
    k = assert_safe_and_logged(res, r)
    assert k == K_AT + 3  # the 4th stale tick (limits.stale_ticks = 3)
    assert np.all(r.read("/rig")["status"][K_AT:k + 1] & ST_MEAS_STALE)


def test_stalled_stream_trips_stale(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "stall", "at": AT, "duration": 0.05}], timeout=0.01, stale_ticks=10)
    assert res.trip_cause.startswith("measurement stale: no fresh frame for 11 ticks")
    assert assert_safe_and_logged(res, r) == K_AT + 10


def test_corrupt_frames_trip_crc_burst(tmp_path):
    faults = [{"kind": "corrupt", "at": AT + 2 * n * T} for n in range(5)]  # every other frame
    res, r = run_emulated(tmp_path, faults)
    assert res.trip_cause.startswith("CRC error burst")
    k = assert_safe_and_logged(res, r)
    assert k == K_AT + 8
    st = r.read("/rig")["status"]
    assert np.flatnonzero(st & ST_MEAS_CRC).tolist() == [K_AT + 2 * n for n in range(5)]


def test_fewer_corrupt_frames_than_a_burst_do_not_trip(tmp_path):
    faults = [{"kind": "corrupt", "at": AT + 2 * n * T} for n in range(4)]
    res, r = run_emulated(tmp_path, faults)
    assert res.trip_cause is None
    assert np.count_nonzero(r.read("/rig")["status"] & ST_MEAS_CRC) == 4


def test_delayed_frames_trip_frame_loss_burst(tmp_path):
    faults = [{"kind": "delay", "at": AT + 3 * n * T, "arg": 1} for n in range(5)]
    res, r = run_emulated(tmp_path, faults)
    assert res.trip_cause.startswith("frame loss burst")
    k = assert_safe_and_logged(res, r)
    st = r.read("/rig")["status"]
    late = np.flatnonzero(st & ST_MEAS_LATE)
    assert late.tolist() == [K_AT + 3 * n + 1 for n in range(5)] and k == late[-1]


def test_duplicated_frames_trip_frame_loss_burst(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "duplicate", "at": AT, "duration": 0.01}])
    assert res.trip_cause.startswith("frame loss burst")
    k = assert_safe_and_logged(res, r)
    st = r.read("/rig")["status"]
    assert np.all(st[K_AT + 1:k + 1] & ST_MEAS_DUP) and not np.any(st[K_AT + 1:k + 1] & ST_MEAS_STALE)


def test_disconnect_trips_link_down(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "disconnect", "at": AT}], timeout=0.01)
    assert res.trip_cause.startswith("link down")
    k = assert_safe_and_logged(res, r)
    assert k == K_AT
    assert r.read("/rig")["status"][k] & ST_LINK_DOWN


def test_encoder_jump_trips(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "encoder_jump", "at": AT, "arg": 1000}])
    assert re.match(r"encoder jump: \+10\d\d counts in 1 tick > 88", res.trip_cause)  # 1000 + the shaft's own
    assert assert_safe_and_logged(res, r) == K_AT


def test_stuck_encoder_trips(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "encoder_stuck", "at": AT, "duration": 0.5}], duration=AT + 0.4)
    assert res.trip_cause.startswith("encoder stuck")
    k = assert_safe_and_logged(res, r)
    count = r.read("/rig")["enc_count"]
    assert np.all(count[K_AT:k + 1] == count[K_AT])  # the logged counter really froze
    assert K_AT + 599 <= k < K_AT + 900  # enc_stuck_time = 0.2 s


def test_inverter_fault_trips(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "inverter_fault", "at": AT}])
    assert res.trip_cause == "inverter fault reported: injected"  # the drive names its fault (VLT_STATUS.FAULT)
    k = assert_safe_and_logged(res, r)
    meas = r.read("/rig")
    assert meas["inv_fault"][k] and not meas["inv_fault"][:k].any()
    assert k - K_AT <= 3  # reported with the next status frame (every 3rd tick)


def test_lost_heartbeat_trips(tmp_path):
    res, r = run_emulated(tmp_path, [{"kind": "heartbeat_lost", "at": AT, "duration": 0.1}])
    assert res.trip_cause.startswith("inverter heartbeat lost")
    k = assert_safe_and_logged(res, r, status_frames=False)
    assert r.read("/rig")["status"][k] & ST_INV_STALE
    assert 28 <= k - K_AT <= 31  # can.heartbeat_timeout = 10 ms = 30 ticks after the last status


def test_dc_link_under_voltage_trips_at_once(tmp_path):
    cfg = emulated_config("virtual", mock={"inverter": {"u_dc": 380.0}})
    rig = build_rig(cfg, seed=1)
    ctrl = make_controller(cfg, rig, "foc", {})
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    with rig:
        res = TimedLoop(rig, ctrl, scenarios.get("demo"), sup, T_s=cfg.T_s, duration=0.05).run()
    assert res.trip_cause == "DC link 380.0 V outside [400, 750] V" and res.trip_t == 0.0


def test_controller_nan_makes_the_emulated_rig_safe(tmp_path):
    """A controller failure (loop-level trip) reaches the drive over the wire within one tick."""
    cfg = emulated_config("virtual")
    rig = build_rig(cfg, seed=1)
    ctrl = make_controller(cfg, rig, "foc", {})
    step, n = ctrl.step, [0]

    def nan_after(meas, w, i):
        n[0] += 1
        return complex("nan") if n[0] > K_AT else step(meas, w, i)

    ctrl.step = nan_after
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    path = tmp_path / "nan.mcap"
    with LogWriter(path, [Topic(a, b, c) for a, b, c in log_topics(rig, ctrl)]) as log:
        with rig:
            res = TimedLoop(rig, ctrl, scenarios.get("demo"), sup, T_s=cfg.T_s, duration=AT + 0.1, log=log).run()
    assert res.trip_cause.startswith("controller output not finite")
    assert assert_safe_and_logged(res, LogReader(path)) == K_AT
