"""Errors for bad user input: each carries the field it is about and what is allowed.

The CLI turns a `BadInput` into a single line on stderr and exit code 2, never a traceback; a `DesignFailed`
(a synthesis that is infeasible, or whose controller could not be constructed or verified) into one line and
exit code 1.
"""

from __future__ import annotations

import math
import sys


class BadInput(ValueError):
    """Invalid user input (rig file, scenario, controller, parameter)."""

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class DesignFailed(RuntimeError):
    """A design gave no verified controller: the input was fine, the numbers were not (exit 1, with the numbers)."""


def allowed(values: object) -> str:
    """Format a list of allowed values for an error message."""
    return ", ".join(str(v) for v in values)


def finite_number(v: object) -> bool:
    """An int or float (not a bool) that is finite and fits a float: an integer of 400 digits is not
    (``math.isfinite`` raises OverflowError on it, ``float()`` too)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    return v.bit_length() <= 1000 if isinstance(v, int) else math.isfinite(v)


def subnormal(v: float) -> bool:
    """A float that is not 0 yet smaller in magnitude than the smallest normal one (1e-320): a typo, never a
    set-point or a parameter (zero to every equation, and slow on many CPUs)."""
    return v != 0.0 and abs(v) < sys.float_info.min
