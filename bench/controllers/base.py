"""The controller plugin interface.

A controller turns one `Measurement` and the references into a stator-voltage reference. It sees
only what a real rig delivers through the HAL plus a `ControllerContext` (sample period, the
*nominal* motor model, limits, encoder geometry); never the mock plant's ground truth.

Writing a plugin::

    class MyController(Controller):
        name = "mine"
        summary = "one line shown by `bench controllers`"
        schema = {"gain": Param(1.0, "loop gain", "V/A", gt=0, le=1e3, tunable=True)}  # SI units
        fields = ("e",)                           # internals logged each tick (on /ctrl)

        def __init__(self, ctx, **params):
            super().__init__(ctx, **params)       # validates params against `schema` -> self.p
        def reset(self): ...
        def step(self, meas, omega_ref, i_mR_ref) -> complex: ...
        def internals(self) -> tuple[float, ...]: ...
        def retune(self, name): ...              # apply a tunable parameter changed while running

and register it under the entry-point group ``imbench.controllers`` (see pyproject.toml; a whole plugin
package: docs/plugins.md and examples/controller-plugin).
Sub-parts that run slower than the base rate use an integer ``divisor`` of it (600 Hz = 3 kHz / 5).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

from bench.controllers.schema import Param, defaults_of, schema_of_defaults, validate
from bench.errors import BadInput, allowed
from bench.hal import Measurement
from bench.core.inverter_error import InverterError
from bench.params import MotorParams


@dataclass(frozen=True, slots=True)
class ControllerContext:
    T_s: float  # base sample period [s]
    motor: MotorParams  # nominal model the controller may use
    I_max: float  # stator-current amplitude the controller may ask for [A]
    counts_per_rev: int  # encoder counts per mechanical revolution (4 x lines)
    enc_modulus: int  # encoder counter modulus
    omega_max: float | None = None  # the rig's over-speed limit, electrical [rad/s] (None: unknown)
    inverter_error: InverterError | None = None  # the rig's [inverter_error] table (None: none given)


class Controller(ABC):
    """Base class of controller plugins (see the module docstring)."""

    name: ClassVar[str]
    summary: ClassVar[str]
    schema: ClassVar[dict[str, Param]] = {}  # every parameter, declared once (bench.controllers.schema)
    defaults: ClassVar[dict[str, Any]] = {}  # derived from `schema` (a plugin may still give only this)
    fields: tuple[str, ...] = ()
    topic: ClassVar[str] = "/ctrl"  # the MCAP topic `fields` are logged on (bench.daq.reader.INTERNALS_TOPICS)
    # the electrical frequency [rad/s] at which the drive may turn the last reference through a loop stall
    # (bench.hal.Command.omega_u): a field-oriented controller gives its field's; 0 holds the reference
    omega_u: float = 0.0

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if "schema" in cls.__dict__:
            cls.defaults = defaults_of(cls.schema)
        elif "defaults" in cls.__dict__:  # the older interface: types checked, no ranges
            cls.schema = schema_of_defaults(cls.defaults)

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        self.ctx = ctx
        self.p = validate(f"controller.{self.name}", self.schema, params)

    def set_param(self, name: str, value: Any) -> Any:
        """Change one parameter while running (call it between ticks); returns the old value.

        Only parameters declared ``tunable`` may change; the value is checked like at start, and
        `retune` applies it. Anything else raises `BadInput` and changes nothing.
        """
        field = f"controller.{self.name}.{name}"
        spec = self.schema.get(name)
        if spec is None:
            raise BadInput(field, f"unknown parameter; allowed: {allowed(sorted(self.schema))}")
        if not spec.tunable:
            tunable = sorted(k for k, p in self.schema.items() if p.tunable)
            raise BadInput(field, f"cannot change while running; tunable: {allowed(tunable) or '(none)'}")
        value = spec.check(field, value)
        old, self.p[name] = self.p[name], value
        try:
            self.retune(name)
        except BaseException:
            self.p[name] = old
            raise
        return old

    def retune(self, name: str) -> None:
        """Apply ``self.p[name]`` (a tunable parameter just changed) to the running parts."""
        raise BadInput(f"controller.{self.name}.{name}", "declared tunable but this controller cannot apply it")

    @abstractmethod
    def reset(self) -> None:
        """Return to the initial state (zero integrators, zero flux estimate)."""

    @abstractmethod
    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        """One base-rate tick: return the stator-fixed voltage reference u_s_ref [V]."""

    @abstractmethod
    def internals(self) -> tuple[float, ...]:
        """Values of `fields` after the last step (estimates, references), for the log."""

    def take_over_from(self, other: Controller) -> None:
        """Take over a running controller's state, between two ticks (a whole-controller switch: `bench switch
        controller=NAME`), so that this one's first command continues the other's. A plugin that can override
        this; the default refuses (BadInput), and the other keeps running."""
        raise BadInput("controller", f"{self.name} cannot take over from a running {other.name} (it has no hand-over)")

    def params(self) -> dict[str, Any]:
        return dict(self.p)
