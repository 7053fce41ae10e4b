"""Stall ride-through: the drive turns a missed reference at the field's frequency, counts, coasts after its
budget, trips on its own over-current; the controller resynchronises; a lockstep run with an injected stall
(the ticks a stalled real-time loop skips) at the rated point goes on."""

from __future__ import annotations

import cmath
import dataclasses
import math

import numpy as np
import pytest

from bench.core.config import load
from bench.perf.stall import case
from bench.runtime.session import RunOptions, run
from mock_hw.inverter import OVER_CURRENT, SETPOINT_WATCHDOG, Inverter

T = 1 / 3000


def _enabled(**kw) -> Inverter:
    inv = Inverter(T_s=T, **kw)
    inv.enable()
    return inv


def test_the_drive_turns_a_missed_reference_at_the_field_frequency() -> None:
    inv = _enabled(ride_through=0.002)  # 6 periods
    u, w = 100.0 + 20.0j, 600.0
    inv.set_voltage(u, w)
    inv.latch()  # the reference is taken at this boundary (one-sample delay) ...
    assert inv.latch() == u  # ... and applied over the next period, from whose start no reference comes
    for n in range(1, 6):  # the substitutes: the last reference turned by omega_u T each period
        assert inv.latch() == pytest.approx(u * cmath.rect(1.0, w * T * n), abs=1e-9)
        assert inv.status().enabled and not inv.status().fault
    assert (inv.missed, inv.ride_throughs, inv.longest) == (6, 1, 6)
    inv.latch()  # 6 periods (the budget) after the last reference's: the drive coasts with a latched fault
    st = inv.status()
    assert st.fault and not st.enabled and st.fault_name == SETPOINT_WATCHDOG and inv.latch() == 0j


def test_a_fresh_reference_ends_the_ride_through_and_the_next_stall_counts_anew() -> None:
    inv = _enabled(ride_through=0.002)
    for _ in range(3):  # three stalls of 5 missed references each: within the budget every time
        inv.set_voltage(50.0 + 0j, 300.0)
        for _ in range(6):
            inv.latch()
    assert (inv.missed, inv.ride_throughs, inv.longest) == (15, 3, 5) and not inv.status().fault


def test_a_disabled_drive_misses_nothing_and_a_bare_plant_holds() -> None:
    inv = Inverter(T_s=T, ride_through=0.0)
    inv.set_voltage(10.0 + 0j, 300.0)
    for _ in range(100):
        inv.latch()
    assert inv.missed == 0 and not inv.status().fault  # not enabled: no set-points needed
    inv = _enabled()  # ride_through None: a zero-order hold for ever (tests that step a bare plant)
    inv.set_voltage(10.0 + 5.0j)
    out = [inv.latch() for _ in range(1000)]
    assert out[-1] == 10.0 + 5.0j and not inv.status().fault and inv.missed == 999


def test_the_drive_trips_on_its_own_over_current() -> None:
    inv = _enabled(i_trip=10.0)
    inv.set_voltage(10.0 + 0j)
    inv.latch(50.0 + 0j)  # the bridge switches from the next period on (one-sample delay): nothing to trip on yet
    inv.set_voltage(10.0 + 0j)
    inv.latch(9.9 + 0j)
    assert not inv.status().fault and inv.i_peak == pytest.approx(9.9)
    inv.set_voltage(10.0 + 0j)
    inv.latch(complex(-5.0, 6.0))  # phase b: -0.5 (-5) + 0.866 * 6 = 7.7 A; phase c: 2.5 - 5.2 = -2.7 A
    assert not inv.status().fault
    inv.set_voltage(10.0 + 0j)
    inv.latch(complex(0.0, 11.6))  # phase b: 10.05 A
    st = inv.status()
    assert st.fault and st.fault_name == OVER_CURRENT and inv.latch() == 0j
    off = Inverter(T_s=T, i_trip=10.0)  # gates blocked: no current to trip on
    off.latch(50.0 + 0j)
    assert not off.status().fault


@pytest.mark.parametrize("stall_ms", [4.0, 16.0, 20.0, 40.0])
def test_the_rated_point_rides_through_a_stall(stall_ms: float) -> None:
    """297 rad/s, 10 N m: a stall within the budget leaves the current below the trip and the speed within
    1 rad/s; the drive of before (held stator-fixed voltage, no resynchronisation) over-currents at 4 ms."""
    r = case("hold", 1.5, stall_ms, "ride-through")
    assert not r["tripped"], r
    assert r["i_peak_ride_through"] < 0.5 * 15.0 and r["i_peak_after"] < 0.5 * 15.0, r
    assert 297.0 - 0.5 < r["speed_before"] < 297.0 + 0.5 and r["speed_dip"] < 1.0, r
    old = case("hold", 1.5, stall_ms, "hold")
    assert old["tripped"] and old["trip_cause"].startswith("over-current"), old


def test_a_stall_longer_than_the_budget_coasts_and_the_trip_names_it() -> None:
    cfg = load("mock")  # the mock rig's drive bridges 50 ms (its max_stall); a real drive's 20 ms here
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(cfg.limits, ride_through=0.02))
    s, code = run(RunOptions(rig=cfg, scenario="hold", duration=1.6, realtime=False, log_enabled=False,
                             progress=False, inject_stalls={1.5: 0.032}))  # fmt: skip
    assert code == 1
    assert s["trip_cause"] == ("inverter fault reported: set-point watchdog; 0.0 ms after a 32.0 ms loop stall "
                               "(longer than the drive's 20 ms ride-through)")  # fmt: skip
    st = s["stalls"]
    assert st["count"] == 1 and st["events"] == [[1.532, 32.0]] and st["drive"]["missed"] == 61, st
    rig = s["record"].read("/rig")
    after = rig["t"] >= 1.532 - 1e-9
    assert np.all(~rig["enable"][after].astype(bool)) and np.all(rig["u_s_ref_re"][after] == 0.0)  # safe at once


def _record(rig, params: dict, stalls: dict) -> dict:
    s, code = run(RunOptions(rig=rig, scenario="hold", duration=1.62, realtime=False, log_enabled=False,
                             progress=False, params=params, inject_stalls=stalls))  # fmt: skip
    assert code == 0, s["trip_cause"]
    return {tp: s["record"].read(tp) for tp in ("/rig", "/ctrl", "/truth")}


@pytest.mark.parametrize("params", [{}, {"observer": "jl", "rr_adapt": "mras"}], ids=["current_model", "jl+mras"])
def test_the_compiled_engines_ride_through_to_the_bit(params: dict) -> None:
    """Two stalls (one 16 ms, one of a single tick): the compiled plant (period by period through the drive's
    Python ride-through) and the compiled FOC tick (the resynchronisation) log what the Python engines do."""
    cfg = load("mock")
    stalls = {1.5: 0.016, 1.55: T}
    ref = _record(cfg, {**params, "engine": "python"}, stalls)
    fast = _record(dataclasses.replace(cfg, mock={**cfg.mock, "engine": "compiled"}), {**params, "engine": "compiled"},
                   stalls)
    assert len(ref["/rig"]["t"]) == round(1.62 / T) - 48 - 1  # the ticks the two stalls skipped
    for tp, cols in ref.items():
        for name, a in cols.items():
            if name not in ("compute_us", "latency_us", "overrun"):
                b = fast[tp][name]
                assert np.array_equal(a.view(np.int64), b.view(np.int64)), f"{tp}.{name}"


def test_a_replay_repeats_the_recorded_stalls_to_the_bit(tmp_path) -> None:
    """A replay (--replay-params) injects the recorded run's loop stalls at their ticks: its log is the
    recording's, field for field (timing aside), where without them it would leave the stall's gap out."""
    from bench.daq.reader import LogReader
    from bench.daq.replay import read_stalls
    from bench.runtime.loop import TIMING_FIELDS

    rec, rep = tmp_path / "rec.mcap", tmp_path / "rep.mcap"
    base = dict(scenario="hold", duration=1.62, realtime=False, progress=False, params={"engine": "python"})
    # (and one at the very first tick: a real-time loop that woke late for it logged from tick 1, which a replay
    # once missed)
    _, code = run(RunOptions(**base, log=rec, inject_stalls={0.0: T, 1.5: 0.008, 1.55: T}))
    assert code == 0
    assert read_stalls(str(rec)) == {0: 1, round(1.5 / T): round(0.008 / T), round(1.55 / T): 1}  # {first: count}
    _, code = run(RunOptions(**base, log=rep, replay_params=rec))
    assert code == 0
    a, b = LogReader(rec), LogReader(rep)
    for tp in ("/rig", "/ctrl", "/truth"):
        ra, rb = a.read(tp), b.read(tp)
        for name, x in ra.items():
            if name not in TIMING_FIELDS:
                y = rb[name]
                assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), f"{tp}.{name}"  # the bits, nan included


def test_the_emulated_drive_rides_through_a_sync_gap() -> None:
    """The emulated rig in lockstep (real drivers, CAN and serial on loopback): the host skips 16 ms of ticks;
    the emulated VLT gets no set-point for them and turns the last one at its OMEGA_U."""
    from mock_hw.emulators.testing import emulated_config

    s, code = run(RunOptions(rig=emulated_config("tcp"), scenario="hold", duration=1.6, realtime=False,
                             log_enabled=False, progress=False, inject_stalls={1.5: 0.016}))  # fmt: skip
    assert code == 0, s["trip_cause"]
    assert s["stalls"]["events"] == [[1.516, 16.0]]
    truth = s["record"].read("/truth")
    w = truth["omega_r"]
    assert math.isclose(float(w[-1]), 297.0, abs_tol=1.0) and float(np.min(w[-200:])) > 296.0


def test_the_drive_limits_the_current_while_it_rides_through_and_only_then() -> None:
    """A substitute period whose current heads above i_limit (it rose as over the last period) gives the zero
    vectors, the substitute turns on and comes back once the current is low; a fresh reference is never limited."""
    inv = _enabled(ride_through=0.01, i_trip=20.0, i_limit=13.5)
    u = 200.0 + 0j
    inv.set_voltage(u, 0.0)
    assert inv.latch(0j) == 0j  # (one-sample delay: the first period has no reference yet)
    assert inv.latch(11.0 + 0j) == u  # the fresh reference's period: not limited although 2*11 - 0 > 13.5
    assert inv.latch(12.0 + 0j) == u  # a substitute, heading to 13.0 A: applied
    assert inv.latch(13.0 + 0j) == 0j and inv.current_limited == 1  # heading to 14.0 A: zero vectors
    assert inv.latch(12.9 + 0j) == u and inv.current_limited == 1  # falling, heading to 12.8 A: applied again
    inv.set_voltage(u, 0.0)  # the PC is back: its reference is applied from the next period, never limited
    assert inv.latch(12.0 + 0j) == u and inv.current_limited == 1  # (the last substitute, heading to 11.1 A)
    assert inv.latch(13.4 + 0j) == u and inv.current_limited == 1 and not inv.status().fault  # heading to 14.8 A


@pytest.mark.parametrize("stall_ms", [2.0, 8.0, 16.0])
def test_a_stall_while_the_foc_forces_the_magnetising_current_rides_through(stall_ms: float) -> None:
    """A stall 0.4 ms into a run (the FOC forces i_sd up with the full voltage at standstill): the drive's current
    limit holds the current below the trip where the held forcing voltage ran it into the trip at 2 ms."""
    r = case("fig5.7", 0.0004, stall_ms, "ride-through")
    assert not r["tripped"], r
    assert r["i_peak_ride_through"] < 15.0 and r["i_peak_after"] < 15.0, r
    from mock_hw import plant

    real = plant.drive_settings
    plant.drive_settings = lambda limits: {**real(limits), "i_limit": math.inf}  # type: ignore[assignment]
    try:
        unlimited = case("fig5.7", 0.0004, stall_ms, "ride-through")
    finally:
        plant.drive_settings = real  # type: ignore[assignment]
    assert unlimited["tripped"] and "over-current" in unlimited["trip_cause"], unlimited


LPV_LAWS = tuple((0.2, part, "lpv") for part in ("speed_controller", "observer", "current_controller"))


def _phase_peak(stall_at: float | None, switches: tuple = LPV_LAWS) -> tuple[int, str | None, float]:
    """fig5.7 to 0.55 s with ``switches``, a 7 ms stall at ``stall_at``: (exit code, trip cause, the largest phase
    current the PC samples from 0.39 s on)."""
    s, code = run(RunOptions(scenario="fig5.7", duration=0.55, log_enabled=False, progress=False, switches=switches,
                             inject_stalls={} if stall_at is None else {stall_at: 0.007}))  # fmt: skip
    rig = s["record"].read("/rig")
    late = rig["t"] > 0.39
    return code, s["trip_cause"], float(np.max(np.abs(np.c_[rig["i_a"], rig["i_b"], rig["i_c"]])[late]))


def test_a_stall_at_the_speed_step_under_the_lpv_laws_rides_through_on_a_thin_margin() -> None:
    """fig5.7's speed step (0 -> 10 rad/s at 0.4 s) under the LPV speed law (6.4.3), observer and current law (6.2):
    the speed law asks for its torque bound at once and the current law forces i_sq up with ~140 V. A 7 ms stall
    1-3 ms later holds that voltage (the drive's limit stops the current at 13.5 A; the shaft overshoots to 30 rad/s),
    and once the loop runs again both laws reverse. These stalls tripped on over-current (15.0-16.2 A; once in CI,
    in real time) while the 600 Hz laws held their pre-stall output for up to 4 more ticks; every loop now updates at
    the first tick back, and they ride through, but within 3 % of the trip. The same stall under the PI laws, and the
    LPV laws without a stall, stay far below it."""
    for at in (0.402, 0.403):
        code, cause, peak = _phase_peak(at)
        assert code == 0 and cause is None and 12.0 < peak < 15.0, (at, cause, peak)
    code, _, peak = _phase_peak(None)
    assert code == 0 and peak < 9.0, peak
    code, _, peak = _phase_peak(0.402, switches=())
    assert code == 0 and peak < 7.0, peak
