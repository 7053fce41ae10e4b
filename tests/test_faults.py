"""Faults at the (mock) rig: the supervisor trips, the rig is safe within one tick, the log is whole.

Covers issue 2 section 8: controller exception, NaN, over-current, over-speed, Ctrl-C, and the
one-line error with exit code 2 for bad input.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bench.core import scenarios
from bench.core.config import load as load_rig
from bench.controllers.base import Controller
from bench.daq import LogReader, LogWriter, Topic
from bench.runtime.loop import TimedLoop, log_topics
from bench.runtime.compose import build_rig, make_controller
from bench.core.supervisor import Limits, Supervisor

ROOT = Path(__file__).resolve().parents[1]


class Faulty(Controller):
    """Wraps the FOC; from tick ``at`` on misbehaves in the way ``mode`` says."""

    name = "faulty"
    summary = "test controller"
    defaults = {"at": 3000, "mode": "raise"}

    def __init__(self, ctx, inner, **params):
        super().__init__(ctx, **params)
        self.inner, self.k = inner, 0
        self.fields = inner.fields

    def reset(self):
        self.inner.reset()

    def step(self, meas, omega_ref, i_mR_ref):
        self.k += 1
        u = self.inner.step(meas, omega_ref, i_mR_ref)
        if self.k > self.p["at"]:
            mode = self.p["mode"]
            if mode == "raise":
                raise RuntimeError("boom")
            if mode == "nan":
                return complex(math.nan, 0.0)
            if mode == "overvoltage":  # drives the current up until the over-current trip
                return 300.0 + 0j
        return u

    def internals(self):
        return self.inner.internals()


def run_loop(tmp_path: Path, mode: str | None, limits: Limits | None = None, scenario: str = "demo",
             duration: float = 1.5) -> tuple[object, LogReader, object]:  # fmt: skip
    cfg = load_rig("mock")
    rig = build_rig(cfg, seed=1)
    ctrl = make_controller(cfg, rig, "foc", {})
    if mode is not None:
        ctrl = Faulty(ctrl.ctx, ctrl, at=int(0.6 * 3000), mode=mode)
    lim = limits or cfg.limits
    sup = Supervisor(lim, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    path = tmp_path / "fault.mcap"
    topics = [Topic(n, s, f) for n, s, f in log_topics(rig, ctrl)]
    with LogWriter(path, topics, metadata={"run": {"test": mode}}) as log:
        with rig:
            res = TimedLoop(rig, ctrl, scenarios.get(scenario), sup, T_s=cfg.T_s, duration=duration, log=log).run()
    return res, LogReader(path), rig


def assert_safe_within_one_tick(reader: LogReader) -> int:
    loop = cmd = meas = reader.read("/rig")
    tripped = loop["tripped"].astype(bool)
    assert tripped.any()
    k = int(np.argmax(tripped))
    assert not tripped[:k].any() and tripped[k:].all()  # latched
    assert not cmd["enable"][k:].any()  # the trip tick itself already writes the safe command
    assert np.all(cmd["m_l_ref"][k:] == 0.0)
    assert cmd["enable"][:k].all()  # and not before
    assert not meas["inv_enabled"][k + 1:].any()  # the inverter reports disabled from the next sample
    assert np.all(np.diff(loop["tick"]) == 1)  # no tick missing up to and after the trip
    return k


@pytest.mark.parametrize("mode, cause", [("raise", "controller exception: RuntimeError: boom"),
                                         ("nan", "controller output not finite")])  # fmt: skip
def test_controller_failure_trips_to_safe_state(tmp_path, mode, cause):
    res, r, rig = run_loop(tmp_path, mode)
    assert res.trip_cause.startswith(cause)
    k = assert_safe_within_one_tick(r)
    assert r.read("/rig")["t"][k] == pytest.approx(res.trip_t)
    assert k == int(0.6 * 3000)  # the first faulty tick
    assert r.summary()["topics"]["/rig"]["messages"] == res.ticks


def test_over_current_trips_and_currents_decay(tmp_path):
    res, r, rig = run_loop(tmp_path, "overvoltage")
    assert res.trip_cause.startswith("over-current")
    k = assert_safe_within_one_tick(r)
    truth = r.read("/truth")
    i_s = np.hypot(truth["i_s_re"], truth["i_s_im"])
    assert i_s[k] > 14.0  # tripped near the 15 A limit, not earlier
    assert i_s[-1] < 0.05 * i_s[k]  # coasting: stator current gone after the post-trip ticks


def test_over_speed_trips(tmp_path):
    res, r, rig = run_loop(tmp_path, None, limits=Limits(omega_max=60.0))  # demo goes to 100 rad/s
    assert res.trip_cause.startswith("over-speed")
    k = assert_safe_within_one_tick(r)
    assert r.read("/truth")["omega_r"][k] == pytest.approx(60.0, abs=8.0)


def test_no_trip_on_a_normal_run(tmp_path):
    res, r, rig = run_loop(tmp_path, None, duration=1.0)
    assert res.trip_cause is None
    assert not r.read("/rig")["tripped"].any()


def _bench(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=120, **kw)  # fmt: skip


@pytest.mark.parametrize(
    "args, field",
    [
        (["run", "--scenario", "nope"], "scenario"),
        (["run", "--controller", "nope"], "controller"),
        (["run", "--rig", "nope"], "rig"),
        (["run", "--duration", "abc"], "--duration"),
        (["run", "--duration", "-1"], "duration"),
        (["run", "-p", "speed_Kp=fast"], "controller.foc.speed_Kp"),
        (["run", "-p", "novalue"], "--param"),
        (["run", "--bogus"], "--bogus"),
    ],
)
def test_bad_input_is_one_line_exit_2(args, field):
    p = _bench(*args)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench: error:"), p.stderr
    assert field in lines[0]
    assert "Traceback" not in p.stderr


def test_bad_rig_file_is_one_line_exit_2(tmp_path):
    rig = tmp_path / "bad.toml"
    rig.write_text('[rig]\nname = "x"\n[limits]\nI_trip = "high"\n')
    p = _bench("run", "--rig", str(rig))
    assert p.returncode == 2
    assert p.stderr.strip() == "bench: error: limits.I_trip: must be a finite number, got 'high'"


def test_tripped_run_exits_1_and_keeps_log(tmp_path):
    log = tmp_path / "trip.mcap"
    p = _bench("run", "--rig", "mock", "--inject-fault", "over-speed", "--log", str(log))  # trip lowered to 50 rad/s
    assert p.returncode == 1, p.stderr
    assert "TRIPPED" in p.stderr and "over-speed: |omega_r| = " in p.stderr and "> 50 rad/s" in p.stderr
    summary = json.loads(Path(json.loads(p.stdout)["summary"]).read_text())
    assert summary["fault_injection"]["omega_max"] == 50.0 and summary["fault_injection"]["rig_omega_max"] == 400.0
    assert "bench: fault injection: over-speed: the over-speed trip lowered from 400 to 50 rad/s" in p.stderr
    r = LogReader(log)
    assert r.metadata()["run"]["scenario"] == "demo"
    assert_safe_within_one_tick(r)


@pytest.mark.realtime
def test_ctrl_c_makes_rig_safe_and_closes_log(tmp_path):
    log = tmp_path / "int.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "bench", "run", "--realtime", "--duration", "60", "--log",
                             str(log)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    time.sleep(4.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    summary = json.loads((tmp_path / "int.summary.json").read_text())
    assert proc.returncode == 130, (summary["trip_cause"], summary.get("stalls"), err)
    r = LogReader(log)
    s = r.summary()
    n = s["topics"]["/rig"]["messages"]
    assert n > 1000  # ran in real time for a while, all of it logged
    loop = r.read("/rig")
    assert np.all(np.diff(loop["tick"]) >= 1)
    assert summary["trip_cause"] == "interrupted (Ctrl-C)"
    assert summary["ticks"] == n
    assert "interrupted" in err
