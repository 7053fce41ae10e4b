"""CPython 3.11's float and complex arithmetic, spelled out for numba (shared by the compiled engines).

The compiled plant (`mock_hw.compiled`) and the compiled FOC tick (`bench.controllers.foc_compiled`)
reproduce their plain-Python references to the last bit by writing every operation as CPython
evaluates it. CPython 3.11 has no mixed float/complex arithmetic: a float operand becomes
``complex(x, 0.0)`` first, so ``f * z`` is the full complex product ``_Py_c_prod`` and ``z / f`` is
``_Py_c_quot`` with a zero imaginary divisor. The helpers take and return (re, im) pairs of floats.

`abs_` and `atan2_` follow Objects/complexobject.c and Modules/mathmodule.c, including the exceptions CPython
raises (OverflowError on overflow) and its own special cases; `fsq` is ``x ** 2`` as
``float_pow`` computes it, with the C library's ``pow`` (not ``x * x``: LLVM would fold a constant
exponent into the product, so callers pass the exponent 2.0 at run time).

`entry` calls a single-signature njit function without numba's dispatcher in front of it.

Importing this module imports numba: only the compiled engines import it. numba's on-disk cache
(``cache=True``) checks only the source file of the function it caches, not of the helpers compiled
into it: `bench.core.jit_cache` flushes every compiled module's cache entries when any source of the family
changed.
"""

from __future__ import annotations

import math

from numba import njit


@njit
def fmul(f, re, im):  # float * complex: complex(f, 0.0) * z (_Py_c_prod)
    return f * re - 0.0 * im, f * im + 0.0 * re


@njit
def cmul(ar, ai, br, bi):  # complex * complex: _Py_c_prod (complex * float: bi = 0.0)
    return ar * br - ai * bi, ar * bi + ai * br


@njit
def cquot(ar, ai, br, bi):  # complex / complex: _Py_c_quot (Smith's algorithm; complex / float: bi = 0.0)
    abs_br = -br if br < 0 else br
    abs_bi = -bi if bi < 0 else bi
    if abs_br >= abs_bi:
        if abs_br == 0.0:
            raise ZeroDivisionError("complex division by zero")
        ratio = bi / br
        denom = br + bi * ratio
        return (ar + ai * ratio) / denom, (ai - ar * ratio) / denom
    if abs_bi >= abs_br:
        ratio = br / bi
        denom = br * ratio + bi
        return (ar * ratio + ai) / denom, (ai * ratio - ar) / denom
    return math.nan, math.nan  # a NaN in the divisor


@njit
def abs_(re, im):  # abs(complex): _Py_c_abs, hypot; OverflowError if finite parts overflow
    if not (math.isfinite(re) and math.isfinite(im)):
        if math.isinf(re):
            return abs(re)
        if math.isinf(im):
            return abs(im)
        return math.nan
    r = math.hypot(re, im)
    if math.isinf(r):
        raise OverflowError("absolute value too large")
    return r


@njit
def atan2_(y, x):  # math.atan2: mathmodule.c's m_atan2 (its own special cases, then the C atan2)
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if math.isinf(y):
        if math.isinf(x):
            return math.copysign(0.25 * math.pi if x > 0 else 0.75 * math.pi, y)
        return math.copysign(0.5 * math.pi, y)
    if math.isinf(x) or y == 0.0:
        return math.copysign(0.0 if math.copysign(1.0, x) == 1.0 else math.pi, y)
    return math.atan2(y, x)


@njit
def fsq(x, two):  # x ** 2 (float_pow; ``two`` = 2.0, given at run time so that the C pow is called)
    if math.isnan(x):
        return x
    if math.isinf(x):
        return abs(x)
    if x == 0.0:
        return 0.0
    if x < 0.0:
        x = -x  # the exponent is even
    if x == 1.0:
        return 1.0
    r = math.pow(x, two)
    if math.isinf(r):
        raise OverflowError("(34, 'Numerical result out of range')")
    return r


def entry(dispatcher):  # noqa: ANN001, ANN201 - a numba dispatcher in, a callable out
    """The one compiled overload's own entry point, without the dispatcher in front of it.

    A dispatcher call first types every argument to pick an overload (~0.35 us a call here, a quarter of
    `advance`'s whole cost); these functions have a single explicit signature, so the choice is fixed and
    the entry point (which still converts each argument by that signature) is called directly. Falls back
    to the dispatcher where numba does not expose it.
    """
    try:
        (sig,) = dispatcher.signatures
        return dispatcher.overloads[sig].entry_point
    except (AttributeError, KeyError, ValueError):
        return dispatcher
