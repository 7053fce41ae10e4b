"""The FOC's kernels, written once: the compiled FOC tick compiles the very functions the Python classes call, and
compiled and plain give the same bits on random inputs, special values included (docs/architecture.md, "Kernels
written once").

Whole sessions are compared in tests/test_compiled_foc.py; here each kernel alone, over inputs no scenario reaches:
negative and non-finite limits, the integrators far outside their bounds, magnitudes that overflow.
"""

from __future__ import annotations

import cmath
import math
import random

import pytest

from bench.core import encoder
from bench.controllers import foc, foc_compiled as fc, observers, observers_compiled as oc, speed_estimators

N = 3000
SPECIAL = (0.0, -0.0, math.inf, -math.inf, math.nan, 1e308, -1e-310)


def _same(a: object, b: object, nan_sign: bool = True) -> bool:
    """Equal to the bit, NaN included (its sign too, unless not ``nan_sign``): tuples of floats, complexes, ints and
    bools."""
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y, nan_sign) for x, y in zip(a, b))
    if isinstance(a, complex) or isinstance(b, complex):
        a, b = complex(a), complex(b)
        return _same(a.real, b.real, nan_sign) and _same(a.imag, b.imag, nan_sign)
    if isinstance(a, float) or isinstance(b, float):
        if math.isnan(a) and math.isnan(b) and not nan_sign:
            return True
        return math.copysign(1.0, a) == math.copysign(1.0, b) and (a == b or (math.isnan(a) and math.isnan(b)))
    return a == b and type(a) is type(b)


def _overflowing(args: tuple) -> bool:
    """An infinite or overflowing value, or two NaNs, among the arguments. Where an infinity meets another one or a
    NaN in one operation (inf - inf, inf * 0, a complex product or quotient), or two NaNs meet, which NaN comes out
    depends on the order of the operands, which LLVM may swap (IEEE leaves the sign of a NaN open): only there is a
    NaN's sign not compared. One NaN input's own sign is (a torn sample: the sessions' non-finite inputs in
    tests/test_compiled_foc.py and tests/test_compiled_observers.py hold them to the bit)."""
    parts = [p for a in args for v in (a if isinstance(a, tuple) else (a,)) if isinstance(v, (float, complex))
             for p in (complex(v).real, complex(v).imag)]  # fmt: skip
    return any(abs(p) > 1e300 for p in parts) or sum(p != p for p in parts) > 1


def _outcome(f, *args: object) -> object:  # noqa: ANN001
    """The result, or the exception's type and message (CPython's messages are part of the behaviour: a trip names
    the exception)."""
    # CPython 3.11's abs(complex) leaves errno as it was for a NaN part and raises OverflowError if it was ERANGE
    # (_Py_c_abs returns NaN without clearing it): a drawn overflow would raise again on the next NaN. A math
    # function clears errno first, as the loop's own math between two ticks does.
    math.sqrt(1.0)
    try:
        return f(*args)
    except (ArithmeticError, ValueError) as exc:
        return f"{type(exc).__name__}: {exc}"


def _f(r: random.Random, scale: float) -> float:
    return r.choice(SPECIAL) if r.random() < 0.03 else r.uniform(-scale, scale)


def _c(r: random.Random, scale: float) -> complex:
    return complex(_f(r, scale), _f(r, scale))


def _current_pi_args(r: random.Random) -> tuple:
    args = [_c(r, 20), _c(r, 20), _f(r, 400), _f(r, 5), r.choice([_f(r, 400), r.uniform(0, 400)]), _c(r, 600),
            r.uniform(0.1, 50), r.uniform(0, 5), r.uniform(0, 0.1), r.uniform(0, 0.5), r.uniform(0, 5)]
    u = r.random()
    if u < 0.02:  # |u| overflows: CPython's OverflowError
        args[5] = complex(1.5e308, 1.5e308)
    elif u < 0.04:  # no error, no decoupling, a negative limit: u_max / |u| divides by zero
        args[0:6] = [1 + 1j, 1 + 1j, 0.0, 0.0, -1.0, 0j]
    return tuple(args)


CASES = {
    "current_pi": (fc._current_pi, foc.current_pi, _current_pi_args),
    "speed_pi": (fc._speed_pi, foc.speed_pi,
                 lambda r: (_f(r, 400), _f(r, 400), _f(r, 5), _f(r, 15), _f(r, 30), r.uniform(0.01, 5),
                            r.uniform(0, 1), r.uniform(0.1, 5), r.uniform(1, 20), 2.0)),
    "flux_p": (fc._flux_p, foc.flux_p, lambda r: (r.uniform(0.5, 50), r.uniform(1, 20), _f(r, 5), _f(r, 5))),
    "field_weakening": (fc._field_weakening, foc.field_weakening,
                        lambda r: (r.uniform(0.2, 1.0), r.random() < 0.5, _c(r, 600) * r.choice([1, 1e306]),
                                   _f(r, 600), r.uniform(0, 1), r.uniform(0.5, 1), r.uniform(0.1, 0.9))),
    "field_frame": (fc._field_frame, foc.field_frame,
                    lambda r: (_c(r, 5) * r.choice([1.0, 0.01]), _f(r, 5), r.random() < 0.5, _c(r, 1))),
    "stator_voltage": (fc._stator_voltage, foc.stator_voltage,
                       lambda r: (_c(r, 600), _c(r, 1), _f(r, 400), r.choice([0.0, 1 / 6000, r.uniform(0, 1e-3)]))),
    "current_model_step": (fc._current_model_step, observers.current_model_step,
                           # (omega_r finite: cmath.exp's special values are CPython's table, numba's NaN signs
                           # differ there; docs/architecture.md)
                           lambda r: (_c(r, 5), _c(r, 20), _c(r, 20), r.uniform(-400, 400), r.uniform(1, 50),
                                      r.choice([1 / 3000, 1 / 6000]))),
    "encoder_speed_step": (fc._encoder_speed_step, encoder.encoder_speed_step,
                           lambda r: (r.randint(0, 65535), r.randint(0, 65535), r.random() < 0.9, 65536, 32768,
                                      _f(r, 100), _f(r, 400), 2 * math.pi / 4096, 3000 * 2 * math.pi / 4096,
                                      r.uniform(0, 1), 1 / 3000, r.uniform(0, 1e-4), r.uniform(0, 0.01),
                                      r.random() < 0.5, r.uniform(0, 10), r.uniform(0, 10), r.random() < 0.9)),
    "voltage_model_step": (oc._voltage_model_step, observers.voltage_model_step,
                           lambda r: (_c(r, 2), _c(r, 20), _c(r, 20), _c(r, 600), r.uniform(0, 5), r.uniform(0.9, 1),
                                      1 / 3000, r.uniform(0.5, 2), r.uniform(0, 0.5))),
    "lpv_observer_step": (oc._lpv_observer_step, observers.lpv_observer_step,
                          # (the coefficients are an artifact's: finite)
                          lambda r: (_c(r, 20), _c(r, 600), _f(r, 600), _c(r, 600), r.random() < 0.5, 1 / 400,
                                     _c(r, 2), _c(r, 2), *(tuple(complex(r.uniform(-1, 1), r.uniform(-1, 1))
                                                                 for _ in range(n)) for n in (3, 3, 5, 4, 4, 4, 2)))),
    "kubota_step": (oc._kubota_step, observers.kubota_step,
                    lambda r: (_c(r, 20), _c(r, 600), _f(r, 400), _c(r, 20), _c(r, 20), _c(r, 5), _f(r, 400),
                               _f(r, 400), r.random() < 0.7, r.uniform(1.0, 2.0), r.uniform(0, 0.1), r.uniform(0, 2),
                               r.uniform(5, 50), 1 / 3000, r.uniform(0.5, 5), r.uniform(0.2, 0.6),
                               r.uniform(0.5, 5), *(lambda L_m, L_s, L_r: (L_m**2, L_r * (L_m**2 - L_s * L_r),
                                                                           L_r**2))(0.4, 0.42, 0.43))),
    "rotor_equation_speed": (oc._rotor_equation_speed, speed_estimators.rotor_equation_speed,
                             lambda r: (_c(r, 5), _c(r, 20), _c(r, 5), r.uniform(0, 1), 3000.0, r.uniform(1, 50))),
}  # fmt: skip


@pytest.mark.parametrize("name", list(CASES))
def test_the_compiled_kernel_is_the_python_function_to_the_bit(name):
    compiled, plain, draw = CASES[name]
    assert compiled.py_func is plain  # the compiled FOC tick compiles this very function
    r = random.Random(name)
    raised = 0
    for _ in range(N):
        args = draw(r)
        got, want = _outcome(compiled, *args), _outcome(plain, *args)
        raised += isinstance(want, str)
        same = (got == want) if isinstance(want, str) else _same(got, want, not _overflowing(args))
        assert same, (name, args, got, want)
    if name in ("current_pi", "field_weakening"):  # the errors CPython raises were drawn, and numba raised them too
        assert raised > 5, raised


def test_the_current_pi_limits_and_winds_back():
    """What the current PI's kernel does, by the thesis' law: below the limit u = K_p e + x + u_ff (4.13)(4.14) and
    x grows by k_i e; above it |u| = u_max, along u, and x back-calculated so that the next output starts there."""
    K_p, k_i, Ls_p, Lm_p, Rr_p = 20.0, 2.0, 0.03, 0.45, 2.5
    i_ref, i_sr, w, i_mR = 2.5 + 3j, 2.4 + 2.8j, 300.0, 2.5
    ff = foc.decoupling(i_sr, w, i_mR, Ls_p, Lm_p, Rr_p)
    assert ff == complex(-w * Ls_p * 2.8 + Rr_p * (2.4 - i_mR), w * Ls_p * 2.4 + Lm_p * w * i_mR)
    u, x, sat = foc.current_pi(i_ref, i_sr, w, i_mR, 1e3, 1 + 1j, K_p, k_i, Ls_p, Lm_p, Rr_p)
    assert not sat and u == pytest.approx(K_p * (0.1 + 0.2j) + (1 + 1j) + ff) and x == pytest.approx(1.2 + 1.4j)
    u_lim, x_lim, sat = foc.current_pi(i_ref, i_sr, w, i_mR, 100.0, 1 + 1j, K_p, k_i, Ls_p, Lm_p, Rr_p)
    assert sat and abs(u_lim) == pytest.approx(100.0) and u_lim / abs(u_lim) == pytest.approx(u / abs(u))
    assert x_lim == pytest.approx(1 + 1j + k_i * ((i_ref - i_sr) + (u_lim - u) / K_p))


def test_the_rotation_is_cpythons_cmath_rect():
    """`kernel_math.crect` (the output's turn, `stator_voltage`) is CPython's cmath.rect for r = 1: the same bits on
    finite angles, signed zeros included, the same ValueError for an infinite one, NaN for a NaN one."""
    from bench.controllers.kernel_math import crect

    r = random.Random(3)
    angles = [0.0, -0.0, 1e-300, -5e-324, math.pi, 1e6, -1e300] + [r.uniform(-10, 10) for _ in range(3000)]
    for a in angles:
        assert _same(crect(1.0, a), cmath.rect(1.0, a)), a
    for a in (math.inf, -math.inf):
        assert _outcome(crect, 1.0, a) == _outcome(cmath.rect, 1.0, a) == "ValueError: math domain error"
    assert _same(crect(1.0, math.nan), cmath.rect(1.0, math.nan))
