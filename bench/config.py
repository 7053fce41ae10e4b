"""Rig files (TOML): which rig, its rate, its limits and the nominal motor model.

A rig file has these tables (all optional except ``[rig]``)::

    [rig]     name, driver ("mock"), rate_hz
    [limits]  I_max, I_trip, I_trip_phase, omega_max, u_dc_min, u_dc_max   (see bench.supervisor.Limits)
    [motor]   the nominal model controllers use: L_s, L_r, L_m, R_s, R_r, Z_p, J, B_visc, m_coulomb
    [mock]    settings of the mock plant (see mock_hw.plant.MockConfig); [mock.motor] overrides the
              *true* machine, e.g. R_r = 4.95 for a hot rotor

`bench run --rig NAME` looks for ``NAME`` as a path, then ``rigs/NAME.toml`` in the working
directory, then in the source tree. Every error names the offending field in one line.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from bench.errors import BadInput, allowed
from bench.params import MotorParams
from bench.supervisor import Limits

DRIVERS = ("mock",)
RIGS_DIR = Path(__file__).resolve().parents[1] / "rigs"
_SECTIONS = ("rig", "limits", "motor", "mock")


@dataclass(frozen=True)
class RigConfig:
    name: str
    driver: str
    rate_hz: float
    limits: Limits
    motor: MotorParams
    mock: dict[str, Any] = field(default_factory=dict)
    path: str | None = None

    @property
    def T_s(self) -> float:
        return 1.0 / self.rate_hz

    def as_dict(self) -> dict[str, Any]:
        return {"rig": {"name": self.name, "driver": self.driver, "rate_hz": self.rate_hz},
                "limits": self.limits.as_dict(), "motor": self.motor.as_dict(), "mock": self.mock,
                "path": self.path}  # fmt: skip


def _numbers(section: str, table: Any, cls: type) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise BadInput(section, "must be a table")
    names = [f.name for f in fields(cls)]
    out: dict[str, Any] = {}
    for key, value in table.items():
        if key not in names:
            raise BadInput(f"{section}.{key}", f"unknown field; allowed: {allowed(names)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise BadInput(f"{section}.{key}", f"must be a finite number, got {value!r}")
        out[key] = value
    return out


def parse(data: dict[str, Any], path: str | None = None) -> RigConfig:
    """Validate a rig-file dictionary."""
    for key in data:
        if key not in _SECTIONS:
            raise BadInput(key, f"unknown table; allowed: {allowed(_SECTIONS)}")
    rig = data.get("rig")
    if not isinstance(rig, dict):
        raise BadInput("rig", "missing [rig] table with name, driver, rate_hz")
    for key in rig:
        if key not in ("name", "driver", "rate_hz"):
            raise BadInput(f"rig.{key}", "unknown field; allowed: name, driver, rate_hz")
    name = rig.get("name", "unnamed")
    driver = rig.get("driver", "mock")
    if driver not in DRIVERS:
        raise BadInput("rig.driver", f"unknown driver {driver!r}; allowed: {allowed(DRIVERS)}")
    rate = rig.get("rate_hz", 3000.0)
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (100.0 <= rate <= 50_000.0):
        raise BadInput("rig.rate_hz", f"must be a number in 100..50000, got {rate!r}")

    lim = Limits(**_numbers("limits", data.get("limits", {}), Limits))
    for key, value in lim.as_dict().items():
        if value <= 0:
            raise BadInput(f"limits.{key}", f"must be > 0, got {value}")
    if lim.I_max >= lim.I_trip:
        raise BadInput("limits.I_max", f"must be below limits.I_trip ({lim.I_trip}), got {lim.I_max}")
    if lim.u_dc_min >= lim.u_dc_max:
        raise BadInput("limits.u_dc_min", "must be below limits.u_dc_max")

    motor_fields = _numbers("motor", data.get("motor", {}), MotorParams)
    if "Z_p" in motor_fields and motor_fields["Z_p"] != int(motor_fields["Z_p"]):
        raise BadInput("motor.Z_p", f"must be an integer, got {motor_fields['Z_p']}")
    motor = MotorParams(**motor_fields)
    try:
        motor.validate()
    except ValueError as exc:
        field_name, _, problem = str(exc).partition(" ")
        raise BadInput(field_name, problem) from None
    mock = data.get("mock", {})
    if not isinstance(mock, dict):
        raise BadInput("mock", "must be a table")
    return RigConfig(str(name), driver, float(rate), lim, motor, mock, path)


def resolve(name_or_path: str) -> Path:
    p = Path(name_or_path)
    candidates = [p, Path("rigs") / f"{name_or_path}.toml", RIGS_DIR / f"{name_or_path}.toml"]
    for c in candidates:
        if c.is_file():
            return c
    known = sorted(f.stem for f in RIGS_DIR.glob("*.toml")) if RIGS_DIR.is_dir() else []
    raise BadInput("rig", f"no rig file {name_or_path!r}; give a path or one of: {allowed(known)}")


def load(name_or_path: str) -> RigConfig:
    path = resolve(name_or_path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(str(path), f"not valid TOML: {exc}") from None
    return parse(data, str(path))
