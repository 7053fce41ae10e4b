"""Set-point margins: every speed reference and load-torque command inside the rig's limits, whatever its source.

A set-point reaches the loop from a scenario's own profile, a parameterised scenario's arguments
(``--scenario-arg``, a sweep's ``[scenario]`` values and ``"scenario.NAME"`` axes and ranges, the arguments'
defaults) or a live override (`bench.operate.requests.session_params`). One rule, `Margins`, bounds them all, `MARGIN`
inside the rig's own limits (docs/at-the-rig.md says why 20 %):

* a speed within (1 - MARGIN) x ``limits.omega_max``, the over-speed trip (a step's overshoot must not reach it);
* a load torque within (1 - MARGIN) x the load drive's ``torque_limit``, where the drive clips;
* a flux reference i_mR within (1 - MARGIN) x ``limits.I_max`` (room is left for torque current; overrides).

A value that is not a finite number, or is subnormal (1e-320), is refused too. Each refusal is a `BadInput`
naming the field and the allowed range, raised before anything runs. A scenario's own profile (its speed
reference, load and flux reference over the run) is held to the same bounds by `bench.core.scenarios.check_profile`.
"""

from __future__ import annotations

import math
import numbers
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bench.errors import BadInput, subnormal

if TYPE_CHECKING:
    from bench.core.config import RigConfig
    from bench.core.supervisor import Limits

__all__ = ["I_MR", "LOAD", "MARGIN", "Margins", "SPEED", "number"]

MARGIN = 0.2  # a set-point stays this fraction inside the rig's limit
SPEED, LOAD, I_MR = "speed", "load", "i_mR"  # the quantities bounded (`Margins.check`); arguments set the first two
_UNITS = {SPEED: "rad/s", LOAD: "N m", I_MR: "A"}


def number(field: str, value: Any) -> float:
    """``value`` as a float: a real number (not a bool), finite, not subnormal; else `BadInput` naming ``field``."""
    v = math.nan
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        try:
            v = float(value)
        except (OverflowError, ValueError):  # an integer of 400 digits
            pass
    if not math.isfinite(v) or subnormal(v):
        digits = isinstance(value, int) and not isinstance(value, bool) and not math.isfinite(v)
        shown = f"an integer of {len(str(abs(value)))} digits" if digits else repr(value)[:100]
        raise BadInput(field, f"must be a finite number (0 or at least {sys.float_info.min:.3g} in magnitude), "
                       f"got {shown}")  # fmt: skip
    return v


@dataclass(frozen=True)
class Margins:
    """The bounds of a rig's set-points: its over-speed trip ``omega_max`` [rad/s, electrical], its load drive's
    clip ``torque_limit`` [N m] (read from ``torque_field`` of the rig file) and ``I_max`` [A], each `MARGIN`
    inside."""

    omega_max: float
    torque_limit: float
    I_max: float
    torque_field: str = "load.torque_limit"

    @classmethod
    def of(cls, limits: Limits, torque_limit: float, torque_field: str = "load.torque_limit") -> Margins:
        return cls(limits.omega_max, torque_limit, limits.I_max, torque_field)

    @classmethod
    def of_rig(cls, cfg: RigConfig) -> Margins:
        """The margins of a validated rig file: the load drive's clip is ``[load] torque_limit`` on a driver rig,
        ``[mock.load] torque_limit`` on a mock one (what `bench.runtime.compose.build_rig` gives ``rig.load``)."""
        if cfg.driver == "drivers":
            return cls.of(cfg.limits, cfg.hw["load"]["torque_limit"], "load.torque_limit")
        from mock_hw.plant import LoadConfig

        load = cfg.mock.get("load", {})
        return cls.of(cfg.limits, float(load.get("torque_limit", LoadConfig.torque_limit)), "mock.load.torque_limit")

    @property
    def omega(self) -> float:
        """The largest speed set-point magnitude [rad/s]."""
        return (1.0 - MARGIN) * self.omega_max

    @property
    def torque(self) -> float:
        """The largest load-torque set-point magnitude [N m]."""
        return (1.0 - MARGIN) * self.torque_limit

    @property
    def i_mR(self) -> float:
        """The largest flux reference [A]."""
        return (1.0 - MARGIN) * self.I_max

    def bound(self, quantity: str) -> float:
        return {SPEED: self.omega, LOAD: self.torque, I_MR: self.i_mR}[quantity]

    def allowed(self, quantity: str) -> str:
        """``a number in [-320, 320] rad/s (0.8 x the rig's limits.omega_max = 400)``."""
        b = self.bound(quantity)
        limit, name = {SPEED: (self.omega_max, "limits.omega_max"), LOAD: (self.torque_limit, self.torque_field),
                       I_MR: (self.I_max, "limits.I_max")}[quantity]  # fmt: skip
        return f"a number in [{-b:g}, {b:g}] {_UNITS[quantity]} ({1.0 - MARGIN:g} x the rig's {name} = {limit:g})"

    def check(self, field: str, quantity: str, value: Any, got: str | None = None) -> float:
        """``value`` of a ``quantity`` (`SPEED`, `LOAD`, `I_MR`) as a float, or `BadInput` naming ``field`` and the
        allowed range (``got``: how the message shows what was given; default: the value)."""
        v = number(field, value)
        b = self.bound(quantity)
        if not -b <= v <= b:
            raise BadInput(field, f"must be {self.allowed(quantity)}, got {got or repr(value)[:100]}")
        return v
