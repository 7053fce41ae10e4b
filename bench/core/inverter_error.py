"""The inverter's voltage error per phase as a function of the phase current (rig file ``[inverter_error]``).

The error is what the bridge loses against its reference, e(i) = u_ref - u, per phase, at phase current i::

    [inverter_error]
    current = [1.0, 2.0, 3.0, 4.0]     # [A], ascending, positive
    error = [17.5, 18.1, 18.2, 18.3]   # [V], the error at +current; odd: e(-i) = -e(i)

Applied by linear interpolation between the points, constant beyond the last point, and through zero
with a straight line from (0, 0) to the first point. `bench identify --write` derives it from the DC
levels of the standstill test (`from_levels`); the FOC subtracts it from its voltage reference before
the flux observers see it (``inverter_comp``, `bench.controllers.foc`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any

from bench.errors import BadInput, finite_number

SECTION = "inverter_error"


@dataclass(frozen=True)
class InverterError:
    current: tuple[float, ...]  # [A], ascending, > 0
    error: tuple[float, ...]  # [V] at +current

    def phase(self, i: float) -> float:
        """The error [V] at phase current ``i`` [A] (module docstring)."""
        c, e = self.current, self.error
        x = -i if i < 0.0 else i
        if x >= c[-1]:
            y = e[-1]
        elif x <= c[0]:
            y = e[0] * x / c[0]
        else:
            k = bisect.bisect_right(c, x)
            y = e[k - 1] + (e[k] - e[k - 1]) * (x - c[k - 1]) / (c[k] - c[k - 1])
        return -y if i < 0.0 else y

    def vector(self, i_a: float, i_b: float, i_c: float) -> complex:
        """The error space vector (3.17) of the three phase errors [V] (the common mode drops out)."""
        e_a, e_b, e_c = self.phase(i_a), self.phase(i_b), self.phase(i_c)
        return complex((2.0 * e_a - e_b - e_c) / 3.0, (e_b - e_c) / math.sqrt(3.0))

    def as_dict(self) -> dict[str, list[float]]:
        return {"current": list(self.current), "error": list(self.error)}


def parse(table: Any) -> InverterError:
    """Validate a rig file's ``[inverter_error]`` table (`BadInput` naming the field)."""
    if not isinstance(table, dict):
        raise BadInput(SECTION, "must be a table with current = [A...] and error = [V...]")
    for key in table:
        if key not in ("current", "error"):
            raise BadInput(f"{SECTION}.{key}", "unknown field; allowed: current, error")
    out = {}
    for key, lo in (("current", 0.0), ("error", -1000.0)):
        v = table.get(key)
        if not isinstance(v, list) or not v or not all(finite_number(x) and lo <= x <= 1000.0 for x in v):
            what = "positive numbers up to 1000 A" if key == "current" else "numbers in [-1000, 1000] V"
            raise BadInput(f"{SECTION}.{key}", f"must be a non-empty list of {what}, got {v!r}")
        out[key] = tuple(float(x) for x in v)
    c = out["current"]
    if c[0] <= 0.0 or any(b <= a for a, b in zip(c, c[1:])):
        raise BadInput(f"{SECTION}.current", f"must be positive and strictly ascending, got {list(c)}")
    if len(out["error"]) != len(c):
        raise BadInput(f"{SECTION}.error", f"must have one value per current ({len(c)}), got {len(out['error'])}")
    return InverterError(c, out["error"])


def from_levels(levels: list[dict[str, Any]], key: str) -> InverterError:
    """The per-phase table from the standstill test's DC levels (`bench.workflows.commission.identify.analyse`): each
    level's α-axis error ``key`` ("e_inv_measured" or "e_inv_from_slope") at its α current, the two polarities
    of a level averaged into an odd curve. A DC current i along phase a has i_b = i_c = -i/2, so the α error
    is (2/3)(e(i) + e(i/2)) (3.17): 4/3 e(i) where the error is flat between i/2 and i, as it is when the
    lowest level is a few knee widths above zero; the table holds 3/4 of the α error."""
    pos: dict[float, tuple[float, float]] = {}
    neg: dict[float, tuple[float, float]] = {}
    for lv in levels:
        (pos if lv["i_ref"] > 0 else neg)[abs(lv["i_ref"])] = (lv["i"], lv[key])
    cur, err = [], []
    for a in sorted(pos):
        if a in neg:
            (ip, ep), (in_, en) = pos[a], neg[a]
            i, e = (ip - in_) / 2.0, (ep - en) / 2.0
        else:
            i, e = pos[a]
        cur.append(float(f"{i:.4g}"))
        err.append(float(f"{0.75 * e:.4g}"))
    return parse({"current": cur, "error": err})
