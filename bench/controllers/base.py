"""The controller plugin interface.

A controller turns one `Measurement` and the references into a stator-voltage reference. It sees
only what a real rig delivers through the HAL plus a `ControllerContext` (sample period, the
*nominal* motor model, limits, encoder geometry); never the mock plant's ground truth.

Writing a plugin::

    class MyController(Controller):
        name = "mine"
        summary = "one line shown by `bench controllers`"
        defaults = {"gain": 1.0}                  # every tunable parameter, SI units
        fields = ("e",)                           # internals logged each tick

        def __init__(self, ctx, **params):
            super().__init__(ctx, **params)       # validates params against `defaults`
        def reset(self): ...
        def step(self, meas, omega_ref, i_mR_ref) -> complex: ...
        def internals(self) -> tuple[float, ...]: ...

and register it under the entry-point group ``imbench.controllers`` (see pyproject.toml).
Sub-parts that run slower than the base rate use an integer ``divisor`` of it (600 Hz = 3 kHz / 5).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

from bench.errors import BadInput, allowed
from bench.hal import Measurement
from bench.params import MotorParams


@dataclass(frozen=True, slots=True)
class ControllerContext:
    T_s: float  # base sample period [s]
    motor: MotorParams  # nominal model the controller may use
    I_max: float  # stator-current amplitude the controller may ask for [A]
    counts_per_rev: int  # encoder counts per mechanical revolution (4 x lines)
    enc_modulus: int  # encoder counter modulus


def validate_params(prefix: str, defaults: dict[str, Any], given: dict[str, Any]) -> dict[str, Any]:
    """Merge ``given`` over ``defaults``; unknown names or wrong types raise `BadInput`."""
    out = dict(defaults)
    for key, value in given.items():
        if key not in defaults:
            raise BadInput(f"{prefix}.{key}", f"unknown parameter; allowed: {allowed(sorted(defaults))}")
        ref = defaults[key]
        if isinstance(ref, bool):
            if not isinstance(value, bool):
                raise BadInput(f"{prefix}.{key}", f"must be true or false, got {value!r}")
        elif isinstance(ref, int):
            if isinstance(value, bool) or not isinstance(value, int):
                raise BadInput(f"{prefix}.{key}", f"must be an integer, got {value!r}")
        elif isinstance(ref, float):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise BadInput(f"{prefix}.{key}", f"must be a finite number, got {value!r}")
            value = float(value)
        elif isinstance(ref, str):
            if not isinstance(value, str):
                raise BadInput(f"{prefix}.{key}", f"must be a string, got {value!r}")
        out[key] = value
    return out


class Controller(ABC):
    """Base class of controller plugins (see the module docstring)."""

    name: ClassVar[str]
    summary: ClassVar[str]
    defaults: ClassVar[dict[str, Any]] = {}
    fields: tuple[str, ...] = ()

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        self.ctx = ctx
        self.p = validate_params(f"controller.{self.name}", self.defaults, params)

    @abstractmethod
    def reset(self) -> None:
        """Return to the initial state (zero integrators, zero flux estimate)."""

    @abstractmethod
    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        """One base-rate tick: return the stator-fixed voltage reference u_s_ref [V]."""

    @abstractmethod
    def internals(self) -> tuple[float, ...]:
        """Values of `fields` after the last step (estimates, references), for the log."""

    def params(self) -> dict[str, Any]:
        return dict(self.p)
