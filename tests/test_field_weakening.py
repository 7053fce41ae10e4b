"""The FOC's voltage-feedback field weakening (`bench.controllers.foc.FieldWeakening`, ``-p field_weakening``) and the
summary's voltage-limit report (`bench.runtime.metrics.voltage_limit`, `voltage_limit_warning`) on the mock rig.

Untouched where the current loop never reaches its voltage limit (the same logs to the bit), the speed above rated
reached with less flux, the summary's numbers and its one-line warning when a run ends at the limit (the rated
point on a hot rotor with the field weakening off, and with its floor too high), bad input refused.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.controllers import ControllerContext, create
from bench.errors import BadInput
from bench.runtime.loop import TIMING_FIELDS
from bench.runtime.metrics import voltage_limit, voltage_limit_warning
from bench.params import MotorParams
from bench.runtime.session import RunOptions, run

ROOT = Path(__file__).resolve().parents[1]
T = 1.0 / 3000.0


def session(scenario: str, params: dict, rig: str = "mock", duration: float | None = None, **args: float) -> tuple:
    """(summary, every topic's fields) of one in-memory lockstep session."""
    summary, code = run(RunOptions(rig=rig, scenario=scenario, params=params, duration=duration, scenario_args=args,
                                   log_enabled=False, progress=False))  # fmt: skip
    assert code == 0, summary["trip_cause"]
    rec = summary.pop("record")
    return summary, {tp: rec.read(tp) for tp in rec.topics()}


def test_a_run_that_never_reaches_the_limit_is_the_same_to_the_bit():
    """Scenario demo (speed reversals at 100 rad/s with load steps: far from the voltage limit) with the field weakening
    on and off: every logged value the same to the bit; the factor is exactly 1 throughout."""
    (_, on), (_, off) = session("demo", {"field_weakening": "on"}, duration=2.0), session("demo", {}, duration=2.0)
    assert not np.any(on["/ctrl"]["u_sat"]), "the case is meant to stay off the limit"
    assert np.all(on["/ctrl"].pop("fw") == 1.0) and "fw" not in off["/ctrl"]
    for topic, fields in off.items():
        for f, x in fields.items():
            if f not in TIMING_FIELDS:
                assert np.array_equal(x.view(np.uint64) if x.dtype == np.float64 else x,
                                      on[topic][f].view(np.uint64) if x.dtype == np.float64 else on[topic][f]), f


@pytest.mark.parametrize("fw", ["on", "off"])
def test_above_rated_speed_the_flux_gives_way_to_the_voltage(fw):
    """320 rad/s (1.08 x rated, the mock rig's set-point margin) at the rated 10 N m: with the field weakening the
    speed is reached, the loop holds |u_sr| at fw_u = 0.98 of its limit with the flux reference about 6 % lower and
    is off the limit in steady state; without it the current loop sits at the limit and the speed stays more than
    10 rad/s short."""
    s, log = session("load-step", {"field_weakening": fw}, duration=3.0, speed=320.0, load=10.0)
    ctrl, rig, truth = log["/ctrl"], log["/rig"], log["/truth"]
    late = rig["t"] > 2.0
    v = np.hypot(ctrl["u_sd"], ctrl["u_sq"]) / (rig["u_dc"] * 0.95 / np.sqrt(3.0))  # of the limit, u_margin 0.95
    if fw == "on":
        assert abs(np.mean(truth["omega_r"][late]) - 320.0) < 0.5
        assert not np.any(ctrl["u_sat"][late]) and abs(np.mean(v[late]) - 0.98) < 0.003, np.mean(v[late])
        assert 0.9 < np.mean(ctrl["fw"][late]) < 0.97 and np.std(ctrl["fw"][late]) < 0.002  # steady, not hunting
        assert s["voltage_limit"]["at_end_s"] == 0.0 and not s["warnings"]
    else:
        assert np.all(ctrl["u_sat"][late]) and np.mean(truth["omega_r"][late]) < 310.0


def test_voltage_limit_numbers_from_a_log():
    """Share of the time at the limit, the longest stretch, the stretch at the end, the factor and the gate's time."""
    t = np.arange(20) * 0.1
    sat = np.zeros(20)
    sat[[3, 4, 5, 10, 17, 18, 19]] = 1.0
    fw = np.linspace(1.0, 0.6, 20)
    gate = np.where(sat > 0, 4 + 2, 0).astype(float)
    vl = voltage_limit(t, {"u_sat": sat, "fw": fw, "rr_gate": gate}, t_from=0.25)
    assert vl["at_limit_frac"] == pytest.approx(7 / 17) and vl["longest_s"] == pytest.approx(0.3)
    assert vl["at_end_s"] == pytest.approx(0.3) and vl["fw_min"] == fw[-1] == vl["fw_end"]
    assert vl["rr_frozen_by_limit_s"] == pytest.approx(0.7)
    assert voltage_limit(t, {"u_sat": sat}, 0.0, trip_t=0.95)["at_end_s"] == 0.0  # a trip at 0.95 s: off at the end
    assert voltage_limit(t, {"u_sat": sat}, 0.0, trip_t=1.05)["at_end_s"] == pytest.approx(0.1)
    assert voltage_limit_warning(vl, {"fw_min": 0.5}) is None  # 0.3 s at the end: not yet a warning
    vl["at_end_s"] = 2.0
    msg = voltage_limit_warning(vl, {"u_margin": 0.95, "fw_min": 0.6})
    assert "for its last 2.00 s" in msg and "floor fw_min = 0.6" in msg and "rr_gate 4" in msg
    assert "still lowering" in voltage_limit_warning(vl, {"fw_min": 0.5})
    assert "field weakening is off" in voltage_limit_warning({"at_end_s": 1.0}, {})


@pytest.mark.parametrize("params, why", [({"field_weakening": "off"}, "field weakening is off"),
                                         ({"fw_min": 0.97}, "at its floor fw_min = 0.97")])  # fmt: skip
def test_a_run_that_ends_at_the_limit_says_which_limit(tmp_path, params, why):
    """The rated point held on a hot rotor (R_r 1.5 x) with the R_r estimate and the field weakening off, or allowed
    only 3 %: `bench run` ends at the voltage limit with the estimate frozen (rr_gate 4); its stderr and summary.json
    say so in one line, naming the limit and what keeps the drive there; exit 0 (a finding, not a fault)."""
    out = tmp_path / "run"
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--lockstep", "--no-progress", "--rig", "mock-hot-rotor",
                        "--scenario", "hold", "--duration", "2.5", "-p", "rr_adapt=mras",
                        *[a for k, v in params.items() for a in ("-p", f"{k}={v}")], "--log", str(out / "r.mcap")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    (line,) = [ln for ln in p.stderr.splitlines() if "voltage limit" in ln]
    assert line.startswith("bench: warning: the run ended at the current loop's voltage limit") and why in line, line
    assert "rr_gate 4" in line
    s = json.loads((out / "r.summary.json").read_text())
    assert line.removeprefix("bench: warning: ") in s["warnings"]
    vl = s["voltage_limit"]
    assert vl["at_end_s"] > 1.0 and vl["rr_frozen_by_limit_s"] > 1.0, vl
    assert s["estimation_errors"]["rr_final_rel"] < -0.05  # frozen short of the hot rotor's R_r


def test_the_rated_point_on_a_hot_rotor_ends_off_the_limit_with_the_defaults():
    """The same run with the defaults: the field weakening gets the loop off the limit within 0.1 s, the estimate
    reaches the hot rotor's R_r, no warning."""
    s, _ = session("hold", {"rr_adapt": "mras"}, rig="mock-hot-rotor", duration=3.0)
    vl = s["voltage_limit"]
    assert vl["at_end_s"] == 0.0 and vl["longest_s"] < 0.1 and vl["fw_min"] < 0.95 and not s["warnings"], vl
    assert abs(s["estimation_errors"]["rr_final_rel"]) < 0.01


def test_bad_field_weakening_parameters_are_refused():
    ctx = ControllerContext(T, MotorParams(), 10.0, 4096, 1 << 16, 400.0)
    with pytest.raises(BadInput, match=r"controller.foc.fw_u: must be a number in \(0.5, 1\)"):
        create("foc", ctx, {"field_weakening": "on", "fw_u": 1.0})
    with pytest.raises(BadInput, match="controller.foc.field_weakening: must be one of"):
        create("foc", ctx, {"field_weakening": "yes"})
    c = create("foc", ctx, {})
    assert c.fw is None and "fw" not in c.fields  # auto without the R_r estimate: off
    with pytest.raises(BadInput, match="field weakening is off"):
        c.set_param("fw_gain", 50.0)
    c = create("foc", ctx, {"field_weakening": "on"})
    c.set_param("fw_gain", 50.0)
    assert c.fw.k == pytest.approx(50.0 * T)
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--lockstep", "-p", "fw_min=0", "--no-progress"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "controller.foc.fw_min" in p.stderr, p.stderr
