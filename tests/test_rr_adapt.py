"""The on-line R_r estimate (`bench.controllers.rr_adapt`, ``-p rr_adapt=mras``) on the mock rig, against the truth.

Lockstep loops on the mock plant: an R_r step at half load, at the rated point (through the current loop's voltage
limit: the field weakening) and over the operating envelope (slow), a rotor that warms 46 % (rigs/mock-warm-fast.toml,
scenario warmup), the unobservable stretches (no load at rated speed, load at standstill), the bounds, a 5 % L_m
error in the nominal model, what the estimate buys (flux and torque errors against the truth, with and without),
and a live reset through `bench set` on a real session.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bench.controllers import ControllerContext, create
from bench.controllers.rr_adapt import GATE_FREQ, GATE_LOAD, GATE_VLIM
from bench.errors import BadInput
from bench.hal import Command
from bench.params import MotorParams
from mock_hw.plant import MockConfig, make_mock_rig

ROOT = Path(__file__).resolve().parents[1]
T = 1.0 / 3000.0
R_R = MotorParams().R_r
RATED_SPEED = 297.4  # [rad/s electrical] 1420 rpm, Z_p = 2 (thesis 3.7)


def ramp_to(w: float, t0: float = 0.4, t_ramp: float = 0.5):
    return lambda t: 0.0 if t < t0 else w * min(1.0, (t - t0) / t_ramp)


def loop(duration: float, speed, load, params: dict, *, mock: dict | None = None, events=(),
         nominal: MotorParams | None = None, i_mR_ref: float = 2.5) -> dict[str, np.ndarray]:  # fmt: skip
    """FOC on the mock plant, tick by tick as the session's loop does (read, step, write); ``events``:
    (t, f(plant)) applied before the tick at t. Every tick's truth and estimates."""
    rig = make_mock_rig(MockConfig.from_dict(mock or {}), dt=T)
    plant = rig.truth
    ctx = ControllerContext(T, nominal or MotorParams(), 10.0, 4096, 1 << 16, 400.0)
    ctrl = create("foc", ctx, params)
    k_t = ctx.motor.torque_constant
    n = int(round(duration / T))
    ev = sorted(events, key=lambda e: e[0])
    out = {k: np.empty(n) for k in ("t", "rr_true", "rr_hat", "gate", "me", "me_hat", "w", "fw")}
    im, im_hat = np.empty(n, complex), np.empty(n, complex)
    j = 0
    with rig:
        for k in range(n):
            t = k * T
            while j < len(ev) and t >= ev[j][0]:
                ev[j][1](plant)
                j += 1
            u = ctrl.step(rig.read(t), speed(t), i_mR_ref)
            rig.write(Command(u, True, load(t)))
            m = plant.motor
            rr = ctrl.rr
            out["t"][k], out["rr_true"][k], out["w"][k], out["me"][k] = t, m.params.R_r, m.omega_r, m.m_e
            out["rr_hat"][k] = rr.R_r if rr is not None else ctx.motor.R_r
            out["gate"][k] = rr.gate if rr is not None else -1
            out["fw"][k] = ctrl.fw.factor if ctrl.fw is not None else 1.0  # the field weakening's factor
            out["me_hat"][k] = k_t * ctrl.i_mR_hat * ctrl.i_sr.imag  # (4.6), the controller's own estimate
            im[k], im_hat[k] = m.i_m, ctrl.i_m_hat
    out["im"], out["im_hat"] = im, im_hat
    return out


def set_true_R_r(R_r: float):
    return lambda plant: plant.motor.set_resistances(plant.motor.params.R_s, R_r)


# --- (a) an R_r step ------------------------------------------------------------------------------------------
T_STEP = 3.0  # [s] the true R_r steps +20 % here (a rotor that warmed), after 2 s at the operating point


def step_of_20_percent(speed: float, load: float, params: dict | None = None) -> dict:
    """+20 % true R_r at `T_STEP`, at ``speed`` (a 0.5 s ramp) and ``load`` (from 1 s), 7 s in all: the record of
    `loop`, the estimate's relative error ``e``, the time ``t_settle`` after the step from which it stays within 3 %
    (inf: it never does), the largest overshoot, and the speed's largest deviation after the step and at the end."""
    d = loop(7.0, ramp_to(speed), lambda t: 0.0 if t < 1.0 else load, {"rr_adapt": "mras", **(params or {})},
             events=[(T_STEP, set_true_R_r(1.2 * R_R))])  # fmt: skip
    assert np.all(np.isfinite(d["rr_hat"]))
    e = d["e"] = d["rr_hat"] / d["rr_true"] - 1.0
    before = (d["t"] > 2.5) & (d["t"] < T_STEP)
    assert np.max(np.abs(e[before])) < 0.01  # converged on the cold rotor first (it starts at nominal = truth)
    after = d["after"] = d["t"] >= T_STEP
    outside = np.flatnonzero(after & (np.abs(e) > 0.03))
    d["t_settle"] = (math.inf if outside[-1] == e.size - 1 else d["t"][outside[-1]] - T_STEP) if outside.size else 0.0
    d["overshoot"] = np.max(d["rr_hat"][after]) / (1.2 * R_R) - 1.0
    d["speed_dev"] = np.max(np.abs(d["w"][after] - speed))
    d["speed_end"] = d["w"][-1] - speed
    return d


@pytest.mark.parametrize("speed, load", [(60.0, 5.0), (-150.0, -5.0), (100.0, -5.0)],
                         ids=["0.2-rated-speed", "reverse", "generating"])  # fmt: skip
def test_step_of_20_percent_settles_within_3_percent_in_2_s_without_overshoot(speed, load):
    """+20 % R_r at t = 3 s, at 0.5 rated load (5 N m of 10) and 0.2 rated speed or more (motoring either way, and
    generating): within 3 % of the truth in at most 2 s, overshoot at most 5 %."""
    d = step_of_20_percent(speed, load)
    assert d["t_settle"] <= 2.0, d["t_settle"]
    assert d["overshoot"] <= 0.05
    assert np.all(d["gate"][d["t"] > 1.5] == 0)  # observable all along: never frozen


def _assert_settles_through_the_limit(d: dict, speed: float) -> None:
    """The step's checks at a point where the current loop may reach its voltage limit: the estimate within 3 % in at
    most 2 s, overshoot at most 5 %, the gate open again (the limit left for good), up to rated speed the field
    weakening released at the end (above it, it stays: the motor needs it there), and the speed held (within 5 rad/s
    after the step, 0.5 at the end)."""
    assert d["t_settle"] <= 2.0, d["t_settle"]
    assert d["overshoot"] <= 0.05, d["overshoot"]
    late = d["t"] > T_STEP + 2.0
    assert np.all(d["gate"][late] == 0), np.unique(d["gate"][late])
    if abs(speed) <= RATED_SPEED:
        assert d["fw"][-1] > 0.98, d["fw"][-1]
    else:
        assert d["fw"][-1] < 0.95, d["fw"][-1]  # (the point is in the field-weakening range indeed)
    assert d["speed_dev"] < 5.0 and abs(d["speed_end"]) < 0.5, (d["speed_dev"], d["speed_end"])


@pytest.mark.parametrize("load", [10.0, 7.0], ids=["rated-torque", "7Nm"])
def test_step_at_the_rated_point_leaves_the_voltage_limit_and_settles(load):
    """The rated point, 297.4 rad/s (1420 rpm) at the rated 10 N m and at 7 N m: the +20 % step over-excites the motor
    (the stale estimate's slip is too small), the current loop reaches its voltage limit and the estimate's gate
    closes (bit 4); the field weakening lowers the flux until the loop leaves the limit, the gate opens, the estimate
    settles within 3 % in at most 2 s, and the flux reference is back at its full value."""
    d = step_of_20_percent(RATED_SPEED, load)
    vlim = (d["gate"].astype(int) & GATE_VLIM) != 0
    assert np.any(vlim[d["after"]]), "the step reaches the voltage limit (else this test proves nothing)"
    assert np.min(d["fw"]) < 0.99, "and the field weakening acts"
    _assert_settles_through_the_limit(d, RATED_SPEED)


def test_without_field_weakening_the_rated_point_step_freezes_at_the_voltage_limit():
    """The same step at rated speed and torque with the field weakening off: the current loop stays at its voltage
    limit, the gate stays shut (bit 4) to the end, the estimate stays about 17 % low, the speed sags (what the field
    weakening removes)."""
    d = step_of_20_percent(RATED_SPEED, 10.0, {"field_weakening": "off"})
    late = d["t"] > T_STEP + 1.0
    assert np.all((d["gate"][late].astype(int) & GATE_VLIM) != 0)
    assert d["t_settle"] == math.inf and d["e"][-1] < -0.15, d["e"][-1]
    assert d["speed_end"] < -20.0, d["speed_end"]


ENVELOPE = [(w, m) for w in (30.0, 100.0, 200.0, RATED_SPEED) for m in (2.0, 5.0, 7.0, 10.0)] + [
    (-RATED_SPEED, -10.0), (RATED_SPEED, -10.0), (340.0, 7.0)]  # reverse, generating, field-weakening range


@pytest.mark.slow
@pytest.mark.parametrize("speed, load", ENVELOPE, ids=[f"{w:g}rad/s-{m:g}Nm" for w, m in ENVELOPE])
def test_step_across_the_operating_envelope(speed, load):
    """The +20 % step on a grid of speeds (0.1 of rated to rated, 1.14 x rated) and loads (0.2 of rated torque to
    rated), reversing and generating at the rated point: the estimate within 3 % in at most 2 s everywhere, the voltage
    limit (where reached) left for good, the speed held."""
    _assert_settles_through_the_limit(step_of_20_percent(speed, load), speed)


def test_without_adaptation_the_same_step_leaves_the_flux_off():
    """The same step with rr_adapt off: the estimate is the nominal R_r, 17 % low, and the flux angle is off by
    degrees (what the adaptation removes; the step test above would fail with it off)."""
    d = loop(5.0, ramp_to(60.0), lambda t: 0.0 if t < 1.0 else 5.0, {}, events=[(3.0, set_true_R_r(1.2 * R_R))])
    late = d["t"] > 4.5
    assert np.all(d["rr_hat"] == R_R) and np.all(d["gate"] == -1)
    ang = np.degrees(np.abs(np.angle(d["im_hat"][late] / d["im"][late])))
    assert np.median(ang) > 2.0, np.median(ang)


# --- (b), (d) the thermal ramp, with and without ------------------------------------------------------------
@pytest.fixture(scope="module")
def warmup() -> dict[str, dict]:
    """Scenario warmup on rigs/mock-warm-fast.toml through a session (its summary.json numbers), both ways."""
    from bench.runtime.session import RunOptions, run

    out = {}
    for rr in ("mras", "off"):
        summary, code = run(RunOptions(rig="mock-warm-fast", scenario="warmup", params={"rr_adapt": rr},
                                       log_enabled=False, progress=False))  # fmt: skip
        assert code == 0, summary["trip_cause"]
        out[rr] = summary
    return out


def test_thermal_ramp_is_tracked_within_2_percent(warmup):
    """R_r rises 46 % as the rotor warms (compressed thermal time, tau_r = 9 s); while observable the estimate
    stays within 2 % of the truth (p95 from summary.json, and the largest error from the record)."""
    s = warmup["mras"]
    ctrl, truth = s["record"].read("/ctrl"), s["record"].read("/truth")
    assert np.max(truth["r_r"]) / R_R > 1.4  # the ramp happened
    assert np.all(np.isfinite(ctrl["rr_hat"]))
    est = s["estimation_errors"]
    assert est["rr_p95_rel_adapting"] <= 0.02 and est["rr_adapting_frac"] > 0.9, est
    t = s["record"].read("/rig")["t"]
    adapting = (t > 1.5) & (ctrl["rr_gate"] == 0)  # 0.5 s after the load is on
    e = ctrl["rr_hat"][adapting] / truth["r_r"][adapting] - 1.0
    assert np.max(np.abs(e)) <= 0.02, np.max(np.abs(e))


def test_adaptation_makes_torque_and_flux_errors_small_over_the_thermal_profile(warmup):
    """The point of it: p95 errors against the truth, flux magnitude and torque (the controller's (4.6)), at most
    2 % with the estimate; the same run without it is far off (so this test fails if the estimate does nothing)."""
    on, off = warmup["mras"]["estimation_errors"], warmup["off"]["estimation_errors"]
    for key in ("flux_mag_p95_rel", "torque_p95_rel"):
        assert on[key] <= 0.02, (key, on[key])
        assert off[key] > 4 * on[key] and off[key] > 0.05, (key, on[key], off[key])
    assert on["flux_angle_p95_deg"] < 1.0 and off["flux_angle_p95_deg"] > 5.0
    assert "rr_p95_rel" not in off  # no estimate, no R_r score


# --- (c) gating and bounds --------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["no load at rated speed", "loaded at standstill"])
def test_unobservable_stretches_freeze_the_estimate(case):
    """True R_r 1.3x, the estimate starting at nominal: where R_r is not observable the estimate holds (drift
    < 1 % over 10 s), stays finite, and rr_gate says why."""
    if case == "no load at rated speed":
        speed, load, bit = ramp_to(RATED_SPEED, t_ramp=1.0), (lambda t: 0.0), GATE_LOAD
    else:
        speed, load, bit = (lambda t: 0.0), (lambda t: 0.0 if t < 0.6 else 7.0), GATE_FREQ
    d = loop(12.5, speed, load, {"rr_adapt": "mras"}, mock={"motor": {"R_r": 1.3 * R_R}})
    assert np.all(np.isfinite(d["rr_hat"]))
    hold = d["t"] >= 2.5
    assert np.all(d["gate"][hold].astype(int) & bit), case
    drift = abs(d["rr_hat"][-1] / d["rr_hat"][hold][0] - 1.0)
    assert drift < 0.01, drift
    assert abs(d["w"][-1] - speed(12.5)) < 2.0  # the drive did what the case says


@pytest.mark.parametrize("factor, bound", [(4.0, 2.5), (0.35, 0.5)])
def test_the_estimate_stays_inside_its_bounds(factor, bound):
    """A true R_r outside 0.5-2.5x nominal: the estimate stops at the bound, finite, and the drive runs on."""
    d = loop(4.0, ramp_to(100.0), lambda t: 0.0 if t < 1.0 else 5.0, {"rr_adapt": "mras"},
             mock={"motor": {"R_r": factor * R_R}})  # fmt: skip
    assert np.all(np.isfinite(d["rr_hat"]))
    assert np.min(d["rr_hat"]) >= 0.5 * R_R and np.max(d["rr_hat"]) <= 2.5 * R_R
    assert d["rr_hat"][-1] == pytest.approx(bound * R_R)


# --- (f) a wrong L_m in the nominal model ------------------------------------------------------------------------
@pytest.mark.parametrize("lm", [0.95, 1.05])
def test_5_percent_L_m_error_leaves_the_estimate_within_5_percent(lm):
    """The nominal L_m 5 % off (the leakage inductances kept: L_s = L_r = L_m + 11 mH), true R_r 1.3x: the
    steady-state estimate is within 5 % of the truth."""
    m = MotorParams()
    leak = m.L_s - m.L_m
    nominal = m.with_(L_m=lm * m.L_m, L_s=lm * m.L_m + leak, L_r=lm * m.L_m + leak)
    d = loop(5.0, ramp_to(100.0), lambda t: 0.0 if t < 1.0 else 7.0, {"rr_adapt": "mras"}, nominal=nominal,
             mock={"motor": {"R_r": 1.3 * R_R}})  # fmt: skip
    late = d["t"] > 4.0
    e = d["rr_hat"][late] / d["rr_true"][late] - 1.0
    assert np.max(np.abs(e)) <= 0.05, np.max(np.abs(e))


# --- configuration ------------------------------------------------------------------------------------------------
def _ctx() -> ControllerContext:
    return ControllerContext(T, MotorParams(), 10.0, 4096, 1 << 16, 400.0)


def test_configurations_refused_with_one_line_and_engines():
    """Sensorless refused; the compiled engine runs the estimate (bit for bit: tests/test_compiled_foc.py), with the
    current model or another observer in a tail region of its buffer, auto too; auto falls back to python where the
    rest of the configuration is not compiled (a rig's [inverter_error] compensation)."""
    with pytest.raises(BadInput, match="controller.foc.rr_adapt: needs the encoder speed"):
        create("foc", _ctx(), {"rr_adapt": "mras", "speed_source": "estimate", "speed_estimator": "kubota"})
    pytest.importorskip("numba")
    for engine in ("compiled", "auto"):
        c = create("foc", _ctx(), {"rr_adapt": "mras", "engine": engine})
        assert c._kernel is not None and c.rr is not None and c.fields[-2:] == ("rr_hat", "rr_gate")
        assert len(c.internals()) == len(c.fields)
    c = create("foc", _ctx(), {"rr_adapt": "mras", "engine": "auto", "observer": "jl"})
    assert c._kernel is not None and c.fields[-2:] == ("rr_hat", "rr_gate") and len(c.internals()) == len(c.fields)
    from dataclasses import replace

    from bench.core.inverter_error import InverterError

    c = create("foc", replace(_ctx(), inverter_error=InverterError((0.5, 2.0), (3.0, 4.0))),
               {"rr_adapt": "mras", "engine": "auto"})  # fmt: skip
    assert c._kernel is None and c.rr is not None and c.fields[-2:] == ("rr_hat", "rr_gate")


def test_off_adds_nothing_and_its_tunables_are_refused_while_running():
    c = create("foc", _ctx(), {})
    assert c.rr is None and "rr_hat" not in c.fields
    with pytest.raises(BadInput, match="R_r adaptation is off"):
        c.set_param("rr_init", 1.0)


def test_every_part_that_uses_R_r_gets_the_estimate():
    """Current model, JL, Kubota (observer and speed estimator), the rotor-equation speed, the slip, the PI's R'_r."""
    for params in ({"observer": "jl", "speed_estimator": "rotor_equation"},
                   {"observer": "kubota", "kubota_adapt": 0.0, "speed_estimator": "kubota"},
                   {"speed_estimator": "kubota"}):  # fmt: skip
        c = create("foc", _ctx(), {"rr_adapt": "mras", **params})
        c.set_param("rr_init", 1.5)
        R = 1.5 * R_R
        b = R / c.ctx.motor.L_r
        assert c.rr.R_r == pytest.approx(R) and c._inv_Tr == pytest.approx(b)
        assert c.current.Rr_p == pytest.approx((c.ctx.motor.L_m / c.ctx.motor.L_r) ** 2 * R)
        assert c.rr.b == pytest.approx(b)  # its own current model
        if params.get("observer") == "kubota":
            assert c.observer.motor.R_r == pytest.approx(R)  # A_sc (3.41), and so its gain
        else:
            assert c.observer._b == pytest.approx(b)  # (4.15), JL's current-model part
        if params["speed_estimator"] == "kubota":
            assert c.estimator.obs.motor.R_r == pytest.approx(R)
        else:
            assert c.estimator._inv_Tr == pytest.approx(b)  # (4.19)


# --- (e) a live reset through `bench set` -------------------------------------------------------------------------
def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=60)  # fmt: skip


@pytest.mark.parametrize("engine", ["python", pytest.param("compiled", marks=pytest.mark.slow)])  # the engines'
# equality in every estimator state and retune: tests/test_compiled_foc.py (fast)
@pytest.mark.realtime
def test_live_reset_of_the_estimate_with_bench_set(tmp_path, engine):
    """A real session (real time, hot rotor 1.5x, scenario warmup) with its live server: the estimate climbs to
    the hot R_r; `bench set rr_init=1` puts it back on the nominal value at a tick boundary, and it climbs again.
    Both controller engines (the compiled one: the estimate in the numba tick, the reset through its buffer)."""
    from bench.daq import LogReader

    if engine == "compiled":
        pytest.importorskip("numba")
    log = tmp_path / "live.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--duration", "20",
                          "--rig", "mock-hot-rotor", "--scenario", "warmup", "-p", "rr_adapt=mras", "-p",
                          f"engine={engine}", "--log", str(log), "--live", "--live-port", "0"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        line = p.stderr.readline()
        assert line.startswith("bench: live: ws://127.0.0.1:"), line
        port = line.split("ws://127.0.0.1:")[1].split()[0]
        time.sleep(4.0)  # loaded from 1 s: the estimate reaches the hot rotor's R_r within about 2 s
        ok = _bench("set", "rr_init=1", "--port", port)
        assert ok.returncode == 0 and "rr_init: 1.0 -> 1.0 at tick" in ok.stdout, (ok.stdout, ok.stderr)
        time.sleep(3.0)
        stop = _bench("stop", "--port", port)
        assert stop.returncode == 0, stop.stderr
        p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0
    r = LogReader(log)
    (ev,) = [e for e in r.events() if e.get("name") == "rr_init"]
    ctrl, rig = r.read_ticks("/ctrl", "/rig")
    tick = rig["tick"]
    i = int(np.searchsorted(tick, ev["tick"]))  # the first tick that ran with the change applied
    hot = 1.5 * R_R
    assert abs(ctrl["rr_hat"][i - 1] / hot - 1.0) < 0.03  # converged before the reset
    assert abs(ctrl["rr_hat"][i] / R_R - 1.0) < 0.002  # reset to nominal (one tick of adaptation since)
    (stop,) = [e for e in r.events() if e["kind"] == "stop"]
    j = int(np.searchsorted(tick, stop["tick"])) - 1  # before the operator stop ramps the drive down
    assert abs(ctrl["rr_hat"][j] / hot - 1.0) < 0.03  # and back on the hot rotor
    summary = json.loads((tmp_path / "live.summary.json").read_text())
    assert summary["operator"]["applied"] >= 2 and math.isfinite(summary["estimation_errors"]["rr_final_rel"])


@pytest.mark.realtime
def test_terminal_panel_shows_the_estimate(tmp_path, run_in_pty):
    """A real-time run with stderr a terminal (a pty): the panel line carries R_r and whether it adapts, the
    values the log holds."""
    import re

    from bench.daq import LogReader

    code, text = run_in_pty([sys.executable, "-m", "bench", "run", "--realtime", "--duration", "3", "--rig",
                             "mock-hot-rotor", "--scenario", "warmup", "-p", "rr_adapt=mras", "--log",
                             str(tmp_path / "tty.mcap")])  # fmt: skip
    assert code == 0, text[-2000:]
    rows = [(float(t), float(r), s) for t, r, s in
            re.findall(r"t +([\d.]+) s .*? R_r +([\d.]+) \u03a9 (adapting|frozen)", text)]  # fmt: skip
    assert len(rows) >= 3, text[-2000:]
    assert all(s == "frozen" for t, _, s in rows if t < 0.4)  # magnetising: standstill, no flux yet
    late = [(r, s) for t, r, s in rows if t > 2.2]
    assert late and all(s == "adapting" and abs(r / (1.5 * R_R) - 1) < 0.05 for r, s in late), late
    logged = LogReader(tmp_path / "tty.mcap").read("/ctrl")["rr_hat"]
    assert all(np.min(np.abs(logged - r)) <= 0.006 for _, r, _ in rows)  # the logged values (2 decimals)


def test_non_finite_inputs_never_reach_the_estimate():
    """NaN or inf in the current, voltage or speed (a torn measurement): flagged, the estimate keeps its value,
    and the estimator's own model restarts rather than carrying NaN into later ticks."""
    from bench.controllers.rr_adapt import GATE_BAD, GATE_FLUX, RrMRAS

    rr = RrMRAS(MotorParams(), T, 3.0, 20.0, 0.8, 1.2)
    k = 0

    def update(*args):  # one tick later each call
        nonlocal k
        k += 1
        return rr.update(k * T, *args)

    ok = (2.5 + 2j, 100 + 50j, 100.0, 110.0, 2.0, 2.5, False)
    for _ in range(300):
        update(*ok)
    b = rr.b
    for bad in ((complex(math.nan, 0), *ok[1:]), (ok[0], complex(0, math.inf), *ok[2:]), (*ok[:2], math.nan, *ok[3:]),
                (*ok[:4], math.inf, *ok[5:]), (*ok[:5], 0.0, False)):  # fmt: skip
        assert update(*bad) is False and rr.gate == (GATE_FLUX if bad[5] == 0.0 else GATE_BAD), (bad, rr.gate)
        assert math.isfinite(rr.b) and math.isfinite(rr.i_m.real) and math.isfinite(rr.i_m.imag)
    assert rr.b == b
    restart = math.ceil(5 * MotorParams().T_r / T)  # the own model restarted from zero flux: it waits that long
    assert not any(update(*ok) for _ in range(restart - 5))
    assert any(update(*ok) for _ in range(300))
    b = rr.b
    k += 7  # ticks skipped by a late real-time loop: not used, flagged
    assert update(*ok) is False and rr.gate == GATE_BAD and rr.b == b
    assert math.isfinite(rr.b) and 0.5 * rr.b_nom <= rr.b <= 2.5 * rr.b_nom


def test_relay_tune_takes_the_estimate_too():
    """relay_tune is the FOC with a relay for a speed PI: the same parameters, the estimate included."""
    c = create("relay_tune", _ctx(), {"rr_adapt": "mras"})
    assert c.rr is not None and c.fields[-2:] == ("rr_hat", "rr_gate")


def test_atlas_rr_table_and_splice(tmp_path):
    """The R_r atlas' table from sweep rows (off / mras per R_r factor), spliced once however often it is run."""
    from bench.workflows.reproductions import atlas_rr

    table = []
    for scn in atlas_rr.SCENARIOS:
        for f in (0.5, 1.0):
            for mode in ("off", "mras"):
                table.append({"scenario": scn, "plant.R_r": f, "params.rr_adapt": mode, "status": "ok",
                              "est_flux_angle_p95_deg": 10.0 * abs(1 - f) + (0.1 if mode == "mras" else 1.0),
                              "est_rr_final_rel": -0.0004 if mode == "mras" else None})  # fmt: skip
    md = atlas_rr.markdown(atlas_rr.rows_of(table))
    assert md.count("| 0.5 | 6.00 / 5.10 |") == 2 and "| -0.04 % | – |" in md
    page = tmp_path / "atlas.md"
    page.write_text("# atlas\n")
    atlas_rr.splice(page, md)
    atlas_rr.splice(page, md)
    text = page.read_text()
    assert text.count(atlas_rr.BEGIN) == 1 and text.count(atlas_rr.END) == 1 and text.startswith("# atlas\n")
