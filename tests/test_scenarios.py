"""Scenarios and load profiles reproduce the thesis' experiment descriptions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.core import load_profiles as lp
from bench.core import scenarios
from bench.errors import BadInput
from bench.core.scenarios import T_MAGNETISE


def test_speed_dependent_load_of_6_4_1():
    f = lp.speed_dependent_641()
    for w in (-300.0, -10.0, 0.0, 5.0, 250.0):
        assert f(0.0, w) == pytest.approx(8 * (1 - 2 / (1 + math.exp(0.01 * w))))
    assert f(0.0, 1e6) == pytest.approx(8.0)  # no overflow far out


def test_sign_dependent_load_always_brakes():
    f = lp.sign_dependent(lp.constant(3.0))
    assert f(0, 5.0) == 3.0 and f(0, -5.0) == -3.0 and f(0, 0.0) == 0.0


def test_fig5_7_profile():
    s = scenarios.get("fig5.7")
    t = T_MAGNETISE + np.array([0.1, 0.4, 0.7, 1.1])
    assert [s.speed_ref(x) for x in t] == [10.0] * 4
    assert [s.load(x, 10.0) for x in t] == [0.0, 3.0, 0.0, 3.0]  # switches every 1/3 s
    assert s.speed_ref(0.1) == 0.0 and s.load(0.1, 0.0) == 0.0  # magnetising lead-in


def test_fig5_8_profile():
    s = scenarios.get("fig5.8")
    levels = [s.speed_ref(T_MAGNETISE + 0.6 * i + 0.3) for i in range(41)]
    assert levels[0] == -150 and levels[20] == 150 and levels[-1] == -150
    assert all(abs(b - a) == 15 for a, b in zip(levels, levels[1:]))
    assert s.load(T_MAGNETISE + 0.15, -60.0) == -3.0  # 3 sign(omega) in the second 0.1 s
    assert s.load(T_MAGNETISE + 0.05, -60.0) == 0.0
    assert s.duration == pytest.approx(T_MAGNETISE + 41 * 0.6)


def test_unknown_scenario_lists_allowed():
    with pytest.raises(BadInput, match="scenario: unknown scenario 'x'; allowed: demo, fig5.7, fig5.8"):
        scenarios.get("x")
