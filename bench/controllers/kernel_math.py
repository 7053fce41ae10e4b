"""CPython's float errors, kept by the kernels numba compiles (docs/architecture.md, "Kernels written once").

A kernel is plain Python that the Python engine calls as it is and the compiled engine compiles with numba. numba's
arithmetic is CPython 3.11's on finite values, but where a finite result overflows CPython raises and numba returns
inf: these helpers raise as CPython does, in both. `bench.controllers.foc_compiled` registers them for numba
(``register_jitable``), so that the controllers' modules do not import numba (231 ms to import the FOC, 322 ms with).
"""

from __future__ import annotations

import math


def square(x: float, two: float) -> float:
    """x ** two, ``two`` = 2.0 given at run time (LLVM would fold a constant exponent into x * x, which differs from
    the C pow that CPython's float ** calls in about 1 of 1000 squares), with CPython's OverflowError where a finite x
    overflows."""
    r = x**two
    if math.isinf(r) and math.isfinite(x):
        raise OverflowError("(34, 'Numerical result out of range')")
    return r


def abs_checked(z: complex) -> float:
    """abs(z), with CPython's OverflowError where the parts are finite and the magnitude is not."""
    m = abs(z)
    if math.isinf(m) and math.isfinite(z.real) and math.isfinite(z.imag):
        raise OverflowError("absolute value too large")
    return m
