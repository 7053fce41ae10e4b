"""The mock plant's kernels, written once: the compiled plant's compiled function and the plain Python function the
Python engine calls give the same bits on random inputs (docs/architecture.md, "Kernels written once").

The engines' whole trajectories are compared in tests/test_compiled_plant.py; here each kernel alone, over inputs
no scenario reaches (negative speeds, coasting at random states, the saturated knee, the encoder's index both ways).
"""

from __future__ import annotations

import math
import random

import pytest

from mock_hw import compiled as cm
from mock_hw import inverter, load, motor, sensors, thermal

N = 3000


def _c(r: random.Random, scale: float) -> complex:
    return complex(r.uniform(-scale, scale), r.uniform(-scale, scale))


def _same(a: object, b: object) -> bool:
    """Equal to the bit, NaN included: the kernels' outputs are tuples of floats, complexes and ints."""
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, complex) or isinstance(b, complex):
        a, b = complex(a), complex(b)
        return _same(a.real, b.real) and _same(a.imag, b.imag)
    if isinstance(a, float) or isinstance(b, float):
        return math.copysign(1.0, a) == math.copysign(1.0, b) and (a == b or (math.isnan(a) and math.isnan(b)))
    return a == b


def _motor_constants(r: random.Random) -> tuple[float, ...]:
    # a11, a12, a12w, a21, b1, kt, zpj, zpi, bv, mc, wei in the ranges of 0.37-11 kW motors (and beyond)
    return (-r.uniform(5, 400), r.uniform(1, 200), r.uniform(0.1, 2), r.uniform(1, 40), r.uniform(5, 300),
            r.uniform(0.1, 5), r.uniform(10, 500), r.choice([0.5, 1.0, 1 / 3]), r.uniform(0, 0.02),
            r.uniform(0, 0.5), r.choice([100.0, 1000.0]))  # fmt: skip


def _rk4_args(r: random.Random) -> tuple:
    a11, a12, a12w, a21, b1, kt, zpj, zpi, bv, mc, wei = _motor_constants(r)
    return (_c(r, 20), _c(r, 8), r.uniform(-400, 400), r.uniform(-10, 10), _c(r, 400), r.uniform(-30, 30),
            r.choice([1 / 3000, 1 / 6000, 1e-5]), r.random() < 0.2, a11, a12, a12w, a21, b1, kt, zpj, zpi, bv, mc,
            wei)  # fmt: skip


def _sat_args(r: random.Random) -> tuple:
    l_m0 = r.uniform(0.05, 0.6)
    return (_c(r, 1.5), _c(r, 1.5), r.uniform(-400, 400), r.uniform(-10, 10), _c(r, 400), r.uniform(-30, 30),
            1 / 3000, r.choice([1, 2, 3]), r.random() < 0.2, r.random() < 0.1, r.choice([0.0, r.uniform(0, 1.5)]),
            r.uniform(0.05, 0.5), r.uniform(10, 200), r.uniform(10, 200), r.uniform(0.1, 5), r.uniform(0.1, 5), 2.0,
            0.5, r.uniform(10, 500), r.uniform(0, 0.02), r.uniform(0, 0.5), 100.0, 1.0 / l_m0,
            1.0 / r.uniform(0.6, 1.3), r.choice([5.0, 7.0, r.uniform(1, 9)]))  # fmt: skip


CASES = {
    "rk4": (cm._rk4_kernel, motor.rk4, _rk4_args),
    "rk4_coast": (cm._rk4_coast_kernel, motor.rk4_coast,
                  lambda r: (lambda a: (a[1], a[2], a[3], a[5], a[6], a[7], a[11], a[14], a[15], a[16], a[17], a[18]))(
                      _rk4_args(r))),
    "sat_step": (cm._sat_step_kernel, motor.sat_step, _sat_args),
    "voltage_error": (cm._voltage_error, inverter.voltage_error,
                      lambda r: (r.uniform(0, 5), r.uniform(0, 2), r.uniform(0, 2), r.uniform(0, 2),
                                 r.choice([0.0, r.uniform(0, 1)]), r.uniform(-30, 30) * r.choice([1, 0]),
                                 r.uniform(-30, 30))),
    "lag_step": (cm._lag_step, load.lag_step,
                 lambda r: (r.uniform(-20, 20), r.uniform(-20, 20),
                            *load.lag_coefficients(r.uniform(1e-4, 1e-2), 1 / 3000))),
    "thermal_step": (cm._thermal_step, thermal.thermal_step,
                     lambda r: tuple(r.uniform(-1, 150) for _ in range(3)) + tuple(r.uniform(0, 1) for _ in range(8))
                     + (r.uniform(0, 3000), r.uniform(0, 3000))),
    "filter_step": (cm._filter_step, sensors.filter_step,
                    lambda r: (_c(r, 600), _c(r, 1e6), _c(r, 600)) + tuple(r.uniform(-1, 1) for _ in range(6))),
    "encoder_sample": (cm._encoder_sample, sensors.encoder_sample,
                       lambda r: (r.uniform(-60, 60), 4096 / (2 * math.pi), r.uniform(0, 6), 4096,
                                  r.choice([65536, 5000]), r.randint(-40000, 40000), r.randint(-10, 10),
                                  r.randint(-100, 100), r.random() < 0.1, r.randint(0, 4999), r.randint(-1, 4999))),
    "adc_read": (cm._adc_read, sensors.adc_read,
                 lambda r: (r.uniform(-40, 40), r.uniform(-40, 40), r.uniform(-40, 40), r.gauss(0, 1), r.gauss(0, 1),
                            r.gauss(0, 1), r.choice([0.0, 0.01]), 0.1, 0.101, 0.099, 0.001, -0.002, 0.0, 409.6, -2048,
                            2047, 1 / 409.6 / 0.1, 0.01, -0.02, 0.0)),
}  # fmt: skip


@pytest.mark.parametrize("name", list(CASES))
def test_the_compiled_kernel_is_the_python_function_to_the_bit(name):
    compiled, plain, draw = CASES[name]
    assert compiled.py_func is plain  # the compiled plant compiles this very function
    r = random.Random(name)
    for _ in range(N):
        args = draw(r)
        got, want = compiled(*args), plain(*args)
        assert _same(got, want), (name, args, got, want)


def test_the_saturation_kernel_reports_no_convergence_as_python_does():
    """`Saturation.solve` raises where Newton does not converge; the kernel says so with -1 (a NaN drive), compiled
    as in Python, and the compiled plant's main flux raises too."""
    sat = motor.Saturation(L_m=0.3)
    curve = (1 / sat.L_m0, 1 / sat.psi_sat, sat.exponent)
    for w, g in ((math.nan, 10.0), (5.0, math.nan)):
        assert motor.solve_main_flux(w, g, 0.0, *curve) == -1.0
    assert motor.solve_main_flux(5.0, 10.0, 0.0, *curve) > 0.0
    with pytest.raises(ArithmeticError):
        cm._sat_step_kernel(0.5 + 0j, 0.5 + 0j, 0.0, 0.0, complex(math.nan, 0.0), 0.0, 1 / 3000, 1, False, False, 0.0,
                            0.3, 100.0, 100.0, 1.0, 1.0, 2.0, 0.5, 100.0, 0.0, 0.0, 100.0, *curve)  # fmt: skip
    with pytest.raises(ArithmeticError, match="no convergence"):
        sat.solve(5.0, math.nan)
