"""CPython's float and cmath behaviour, kept by the kernels numba compiles (docs/architecture.md, "Kernels written
once").

A kernel is plain Python that the Python engine calls as it is and the compiled engine compiles with numba. numba's
arithmetic is CPython 3.11's on finite values, but where a finite result overflows CPython raises and numba returns
inf: these helpers raise as CPython does, in both. numba's cmath functions are not CPython's either: on a
non-finite argument they are not its special-value tables (other NaN signs, other values: cosh(nan + 0j) is
nan + 0j in CPython, nan + nanj in numba), and on finite ones they lack its scaled branches near overflow and for
subnormals. `cexp`, `csqrt`, `ccosh` and `csinh` here are CPython's algorithms for a finite argument, with the C
library's exp, cos, sin, cosh, sinh, sqrt and hypot as CPython calls them, and NaN + NaN j for a non-finite one.
`bench.controllers.observers_compiled` registers them for numba (``register_jitable``), so that the controllers'
modules do not import numba (231 ms to import the FOC, 322 ms with).
"""

from __future__ import annotations

import math

NAN = complex(math.nan, math.nan)  # (both parts without the sign bit)


def square(x: float, two: float) -> float:
    """x ** two, ``two`` = 2.0 given at run time (LLVM would fold a constant exponent into x * x, which differs from
    the C pow that CPython's float ** calls in about 1 of 1000 squares), with CPython's OverflowError where a finite x
    overflows."""
    r = x**two
    if math.isinf(r) and math.isfinite(x):
        raise OverflowError("(34, 'Numerical result out of range')")
    return r


def atan2(y: float, x: float) -> float:
    """math.atan2 as CPython computes it (mathmodule.c's m_atan2: its own special cases, then the C atan2), which
    numba's is not on infinities and zeros."""
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if math.isinf(y):
        if math.isinf(x):
            return math.copysign(0.25 * math.pi if x > 0 else 0.75 * math.pi, y)
        return math.copysign(0.5 * math.pi, y)
    if math.isinf(x) or y == 0.0:
        return math.copysign(0.0 if math.copysign(1.0, x) == 1.0 else math.pi, y)
    return math.atan2(y, x)


def abs_checked(z: complex) -> float:
    """abs(z), with CPython's OverflowError where the parts are finite and the magnitude is not."""
    m = abs(z)
    if math.isinf(m) and math.isfinite(z.real) and math.isfinite(z.imag):
        raise OverflowError("absolute value too large")
    return m


def csquare(z: complex) -> complex:
    """z ** 2 as CPython's complex power computes it (c_powu: 1 * (z * z)), with its OverflowError where a part of
    the result is infinite."""
    r = 1.0 * (z * z)
    if math.isinf(r.real) or math.isinf(r.imag):
        raise OverflowError("complex exponentiation")
    return r


def finite(z: complex) -> bool:
    """Both parts finite."""
    return math.isfinite(z.real) and math.isfinite(z.imag)


E = math.e  # Py_MATH_E
LOG_LARGE_DOUBLE = math.log(1.7976931348623157e308 / 4.0)  # CM_LOG_LARGE_DOUBLE = log(DBL_MAX / 4)


def cexp(z: complex) -> complex:
    """cmath.exp: CPython's algorithm (cmath_exp_impl) on a finite argument, with its OverflowError; NaN + NaN j
    otherwise. Written out because numba's differs near overflow (it has no scaled branch)."""
    if not finite(z):
        return NAN
    re, im = z.real, z.imag
    if re > LOG_LARGE_DOUBLE:
        lv = math.exp(re - 1.0)
        r = complex(lv * math.cos(im) * E, lv * math.sin(im) * E)
    else:
        lv = math.exp(re)
        r = complex(lv * math.cos(im), lv * math.sin(im))
    if math.isinf(r.real) or math.isinf(r.imag):
        raise OverflowError("math range error")
    return r


def hyperbolic(z: complex, sinh: bool) -> complex:
    """cmath.cosh (``sinh`` False) or cmath.sinh: CPython's algorithms (cmath_cosh_impl, cmath_sinh_impl) on a
    finite argument, with their OverflowError; NaN + NaN j otherwise. The two differ only in where cosh and sinh
    of the real part go."""
    if not finite(z):
        return NAN
    re, im = z.real, z.imag
    big = abs(re) > LOG_LARGE_DOUBLE
    x = re - math.copysign(1.0, re) if big else re
    ch, sh = math.cosh(x), math.sinh(x)
    a, b = (sh, ch) if sinh else (ch, sh)
    if big:
        r = complex(math.cos(im) * a * E, math.sin(im) * b * E)
    else:
        r = complex(math.cos(im) * a, math.sin(im) * b)
    if math.isinf(r.real) or math.isinf(r.imag):
        raise OverflowError("math range error")
    return r


def ccosh(z: complex) -> complex:
    """cmath.cosh as CPython computes it (`hyperbolic`)."""
    return hyperbolic(z, False)


def csinh(z: complex) -> complex:
    """cmath.sinh as CPython computes it (`hyperbolic`)."""
    return hyperbolic(z, True)


SCALE_UP, SCALE_DOWN = 53, -27  # CM_SCALE_UP = 2 * (DBL_MANT_DIG / 2) + 1, CM_SCALE_DOWN = -(CM_SCALE_UP + 1) / 2
DBL_MIN = 2.2250738585072014e-308


def csqrt(z: complex) -> complex:
    """cmath.sqrt: CPython's algorithm (Modules/cmathmodule.c, cmath_sqrt_impl) on a finite argument, NaN + NaN j
    otherwise. Written out because numba's differs on subnormal arguments; ``abs`` of a complex number is the C
    library's hypot, as cmath's, in both engines (math.hypot is not: CPython has its own)."""
    if not finite(z):
        return NAN
    re, im = z.real, z.imag
    if re == 0.0 and im == 0.0:
        return complex(0.0, im)
    ax, ay = abs(re), abs(im)
    if ax < DBL_MIN and ay < DBL_MIN:  # hypot(ax, ay) subnormal
        ax = math.ldexp(ax, SCALE_UP)
        s = math.ldexp(math.sqrt(ax + abs(complex(ax, math.ldexp(ay, SCALE_UP)))), SCALE_DOWN)
    else:
        ax /= 8.0
        s = 2.0 * math.sqrt(ax + abs(complex(ax, ay / 8.0)))
    d = ay / (2.0 * s)
    if re >= 0.0:
        return complex(s, math.copysign(d, im))
    return complex(d, math.copysign(s, im))



def crect(r: float, phi: float) -> complex:
    """cmath.rect for a finite, nonzero r (cmath_rect_impl): CPython's ValueError for an infinite angle, NaN + NaN j
    for a NaN one, and r + (r phi) j at phi = 0."""
    if not math.isfinite(phi):
        if math.isinf(phi):
            raise ValueError("math domain error")
        return NAN
    if phi == 0.0:
        return complex(r, r * phi)
    return complex(r * math.cos(phi), r * math.sin(phi))
