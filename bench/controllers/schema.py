"""Controller parameters, declared once: default, unit, allowed range or choices, description, and
whether it may change while the rig runs.

A plugin declares ``schema = {"speed_Kp": Param(0.6, "speed PI gain", "N m s/rad", gt=0, le=100,
tunable=True), ...}``; `Controller` derives ``defaults`` from it and `validate` checks every value
given on the command line (``-p NAME=VALUE``) or, later, on-line. A value outside the range, of
the wrong type or not among the choices is refused with one line naming
``controller.<plugin>.<name>`` and what is allowed. Ranges are physical (a speed gain of 1e308 is
not a speed gain); they are wide enough for any tuning experiment on a 1.5 kW rig.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from bench.errors import BadInput, allowed, clip_repr, subnormal

__all__ = ["Param", "defaults_of", "prefixed", "schema_of_defaults", "validate"]


@dataclass(frozen=True)
class Param:
    """One parameter. Bounds: ``ge``/``le`` inclusive, ``gt``/``lt`` exclusive; the type is the default's."""

    default: Any
    doc: str
    unit: str = ""
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple[Any, ...] | None = None
    tunable: bool = False  # may change while the rig runs (applied at a tick boundary)

    @property
    def kind(self) -> str:
        d = self.default
        return "bool" if isinstance(d, bool) else "int" if isinstance(d, int) else \
            "float" if isinstance(d, float) else "str"  # fmt: skip

    def allowed(self) -> str:
        """What may be given, as the error message and `bench controllers` say it."""
        if self.choices is not None:
            return "one of " + allowed(self.choices)
        if self.kind == "bool":
            return "true or false"
        lo = f"({self.gt:g}" if self.gt is not None else f"[{self.ge:g}" if self.ge is not None else "(-inf"
        hi = f"{self.lt:g})" if self.lt is not None else f"{self.le:g}]" if self.le is not None else "inf)"
        what = {"int": "an integer", "float": "a number", "str": "a string"}[self.kind]
        return what if (lo, hi) == ("(-inf", "inf)") else f"{what} in {lo}, {hi}" + (f" {self.unit}" if self.unit else "")

    def check(self, field: str, value: Any) -> Any:
        """The value as the controller uses it, or `BadInput` naming ``field``."""
        kind = self.kind
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if isinstance(value, int) and value.bit_length() > 1000:  # 400 nines: no float holds it (overflows)
            raise BadInput(field, f"must be {self.allowed()}, got an integer of {len(str(abs(value)))} digits")
        ok = {
            "bool": isinstance(value, bool),
            "int": isinstance(value, int) and not isinstance(value, bool),
            "float": number and math.isfinite(value),
            "str": isinstance(value, str),
        }[kind]
        if ok and kind == "float":
            value = float(value)
            if subnormal(value):  # 1e-320: passes gt=0, yet zero to every equation
                raise BadInput(field, f"must be {self.allowed()}, not subnormal, got {value!r}")
        if ok and self.choices is not None:
            ok = value in self.choices
        if ok and kind in ("int", "float"):
            ok = ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                  and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))  # fmt: skip
        if not ok:
            raise BadInput(field, f"must be {self.allowed()}, got {clip_repr(value)}")
        return value


def defaults_of(schema: dict[str, Param]) -> dict[str, Any]:
    return {k: p.default for k, p in schema.items()}


def schema_of_defaults(defaults: dict[str, Any]) -> dict[str, Param]:
    """For a plugin that only lists ``defaults`` (the older interface): type checks, no ranges."""
    return {k: Param(v, "") for k, v in defaults.items()}


def prefixed(schema: dict[str, Param], prefix: str, what: str) -> dict[str, Param]:
    """A part's parameters as its host exposes them: ``jl`` + ``K1_re`` -> ``jl_K1_re``."""
    return {f"{prefix}_{k}": replace(p, doc=f"{what}: {p.doc}" if p.doc else what) for k, p in schema.items()}


def validate(prefix: str, schema: dict[str, Param], given: dict[str, Any]) -> dict[str, Any]:
    """Defaults overlaid with ``given``, each checked; unknown names raise `BadInput`."""
    out = defaults_of(schema)
    for key, value in given.items():
        if key not in schema:
            raise BadInput(f"{prefix}.{key}", f"unknown parameter; allowed: {allowed(sorted(schema))}")
        out[key] = schema[key].check(f"{prefix}.{key}", value)
    return out


def markdown(plugins: dict[str, Any]) -> str:
    """The controllers page of the docs: every plugin's parameters as a table (`bench controllers --markdown`)."""
    out = ["# Controllers and their parameters", "",
           "Generated by `bench controllers --markdown > docs/controllers.md` from the parameters each plugin",
           "declares (`bench.controllers.schema.Param`). Set one with `bench run --controller NAME -p KEY=VALUE`;",
           "**tunable** ones may change while the rig runs (applied at a tick boundary). Write your own plugin:",
           "see [Writing a controller plugin](plugins.md).", ""]  # fmt: skip
    for name, cls in plugins.items():
        out += [f"## `{name}`", "", cls.summary, "", "| parameter | default | allowed | tunable | description |",
                "|---|---|---|---|---|"]  # fmt: skip
        for key, p in cls.schema.items():
            out.append(f"| `{key}` | `{p.default!r}` | {p.allowed()} | {'yes' if p.tunable else ''} | {p.doc} |")
        out.append("")
    return "\n".join(out)
