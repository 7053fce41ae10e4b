"""Controller parameters: declared once with unit, range and description; checked; tunable ones change
at a tick boundary and act on the running controller."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.core.config import load as load_rig
from bench.controllers import available
from bench.errors import BadInput
from bench.runtime.compose import build_rig, make_controller

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(available()))
def test_every_parameter_is_declared_with_a_description_and_a_bound_or_choices(name):
    cls = available()[name]
    assert cls.schema and set(cls.defaults) == set(cls.schema)
    for key, p in cls.schema.items():
        assert p.doc, (name, key)
        if p.kind in ("int", "float") and p.choices is None:
            assert (p.ge is not None or p.gt is not None) and (p.le is not None or p.lt is not None), (name, key)
        p.check(key, p.default)  # the default is allowed


def _foc(**params):
    cfg = load_rig("mock")
    return make_controller(cfg, build_rig(cfg, 0), "foc", params)


@pytest.mark.parametrize("key, value, words", [
    ("speed_Kp", 1e308, "(0, 100]"), ("speed_Kp", 0.0, "(0, 100]"), ("speed_Ti", -1.0, "(0, 10]"),
    ("speed_divisor", 0, "[1, 100]"), ("speed_divisor", 2.5, "an integer"), ("observer", "nope", "one of"),
    ("lpv_current_rate", 1000.0, "one of 600.0, 3000.0"), ("jl_K1_re", float("nan"), "a number"),
    ("kubota_adapt", 0.5, "one of 0.0, 1.0"), ("u_margin", 1.5, "(0, 1]"),
])  # fmt: skip
def test_out_of_range_values_are_refused_naming_the_field(key, value, words):
    with pytest.raises(BadInput) as exc:
        _foc(**{key: value})
    assert exc.value.field == f"controller.foc.{key}" and words in exc.value.problem


def test_a_tunable_gain_changes_the_running_controller_and_others_are_refused():
    c = _foc()
    old = c.set_param("speed_Kp", 1.2)
    assert old == 0.6 and c.p["speed_Kp"] == 1.2
    assert c.speed.K_p == 1.2 and c.speed.k_i == pytest.approx(1.2 * c.ctx.T_s / c.p["speed_Ti"])
    c.set_param("current_wc", 500.0)
    assert c.current.K_p == pytest.approx(c.ctx.motor.Ls_p * 500.0)
    c.set_param("flux_Km", 2.0)
    assert c.flux.K_m == 2.0
    with pytest.raises(BadInput, match="cannot change while running"):
        c.set_param("voltage_source", "measured")
    with pytest.raises(BadInput, match=r"\(0, 100\]"):
        c.set_param("speed_Kp", -3.0)
    assert c.p["speed_Kp"] == 1.2 and c.speed.K_p == 1.2  # a refused change changes nothing
    with pytest.raises(BadInput, match="unknown parameter"):
        c.set_param("bogus", 1.0)


def test_a_gain_change_does_not_make_the_output_jump():
    """The integrators carry over: the speed PI's torque is continuous across a K_p change at zero error."""
    from bench.controllers.foc import SpeedPI

    pi = SpeedPI(0.6, 0.04, 1.0, 10.0, 1 / 3000)
    for _ in range(300):
        pi.update(10.0, 9.0, 2.0, 2.0)
    before = pi.update(10.0, 10.0, 2.0, 2.0)  # zero error: the output is the integrator
    pi.set_gains(2.0, 0.01)
    assert pi.update(10.0, 10.0, 2.0, 2.0) == pytest.approx(before)


def test_lpv_parts_refuse_pi_gain_changes():
    c = _foc(current_controller="lpv")
    with pytest.raises(BadInput, match="not the PI"):
        c.set_param("current_wc", 500.0)


def test_bench_controllers_prints_units_ranges_and_tunable_marks():
    p = subprocess.run([sys.executable, "-m", "bench", "controllers", "foc"], capture_output=True, text=True, cwd=ROOT,
                       timeout=60)  # fmt: skip
    line = next(ln for ln in p.stdout.splitlines() if ln.strip().startswith("speed_Kp"))
    assert "*" in line and "(0, 100] N m s/rad" in line and "speed PI gain" in line
    j = json.loads(subprocess.run([sys.executable, "-m", "bench", "controllers", "--json"], capture_output=True,
                                  text=True, cwd=ROOT, timeout=60).stdout)  # fmt: skip
    assert j["foc"]["parameters"]["current_wc"]["unit"] == "rad/s" and j["foc"]["parameters"]["current_wc"]["tunable"]
    assert not j["foc"]["parameters"]["voltage_source"]["tunable"] and j["foc"]["parameters"]["observer"]["tunable"]


@pytest.mark.parametrize("name", sorted(available()))
def test_every_tunable_parameter_can_be_applied_while_running(name):
    """A parameter marked tunable must be changeable on a fresh controller of that plugin (or refused for a
    reason of the configuration, e.g. a PI gain when that loop is LPV - not 'cannot apply')."""
    cfg = load_rig("mock")
    ctrl = make_controller(cfg, build_rig(cfg, 0), name, {})
    for key, p in ctrl.schema.items():
        if p.tunable:
            try:
                ctrl.set_param(key, p.default)
            except BadInput as exc:
                assert "cannot apply" not in exc.problem, (name, key)
                assert any(why in exc.problem for why in ("not a PI", "adaptation is off", "field weakening is off")), (
                    name, key, exc.problem)
