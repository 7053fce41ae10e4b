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


class LinkError(BadInput):
    """A device cannot be reached at configure time (one line naming the rig-file field)."""


class DesignFailed(RuntimeError):
    """A design gave no verified controller: the input was fine, the numbers were not (exit 1, with the numbers)."""


MAX_ECHO = 80  # characters of a client's or user's text echoed back in a reply, a log entry or an error


def clip(text: object, n: int = MAX_ECHO) -> str:
    """Text someone gave (a name, a value, a note), as it is echoed back: at most ``n`` characters, then "…"."""
    s = text if isinstance(text, str) else str(text)
    return s if len(s) <= n else s[:n] + "\u2026"


def clip_repr(value: object, n: int = MAX_ECHO) -> str:
    """``repr(value)`` cut like `clip` (a long string is cut before its repr is made)."""
    if isinstance(value, (str, bytes)) and len(value) > n:
        return repr(value[:n]) + "\u2026"
    return clip(repr(value), n)


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
