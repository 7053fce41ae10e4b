"""The mock plant's mismatch keys of a sweep file, and how each changes a rig's ``[mock]`` table.

Machine keys are *factors* on the base rig's true machine (``[mock.motor]``; without it the
thesis machine (3.57), which is also the controllers' nominal ``[motor]``): ``R_r = 1.5`` is a rotor
50 % hotter than the controller assumes. The other keys are absolute values in the mock's own
units. Every key maps onto a field of `mock_hw.plant.MockConfig`; the rig file's validation
(`bench.core.config.parse`) checks the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from bench.params import MotorParams
from bench.errors import BadInput, allowed


@dataclass(frozen=True)
class PlantKey:
    """One mismatch key: kind ``factor`` (x the true machine) or ``abs``; integer keys are rounded."""

    kind: str
    unit: str
    doc: str
    lo: float
    hi: float
    integer: bool = False


KEYS: dict[str, PlantKey] = {
    "R_s": PlantKey("factor", "x", "stator resistance", 0.05, 20.0),
    "R_r": PlantKey("factor", "x", "rotor resistance", 0.05, 20.0),
    "L_m": PlantKey("factor", "x", "magnetising inductance (leakage inductances L_s - L_m, L_r - L_m kept)", 0.05, 1.9),
    "leakage": PlantKey("factor", "x", "both leakage inductances L_s - L_m and L_r - L_m (L_m kept)", 0.05, 20.0),
    "J": PlantKey("factor", "x", "inertia", 0.05, 20.0),
    "B_visc": PlantKey("factor", "x", "viscous friction", 0.0, 100.0),
    "m_coulomb": PlantKey("factor", "x", "Coulomb friction", 0.0, 100.0),
    "current_noise": PlantKey("abs", "V rms at the ADC", "current-sensor noise (mock.currents.noise_std; 0.5 V/A)", 0.0, 1.0),
    "voltage_noise": PlantKey("abs", "V rms at the ADC", "voltage-sensor noise (mock.voltages.noise_std)", 0.0, 1.0),
    "current_offset": PlantKey("abs", "V at the ADC", "uncalibrated offset of the phase-a current ADC", -5.0, 5.0),
    "voltage_offset": PlantKey("abs", "V at the ADC", "uncalibrated offset of the phase-a voltage ADC", -5.0, 5.0),
    "encoder_lines": PlantKey("abs", "lines/rev", "encoder resolution (x4 decoding)", 16, 16384, integer=True),
    "dead_time": PlantKey("abs", "s", "inverter dead time, uncompensated (mock.inverter.dead_time)", 0.0, 2e-5),
}  # fmt: skip


def check(field: str, key: str, value: Any) -> float | int:
    """The value of one key, or `BadInput` naming ``field``."""
    if key not in KEYS:
        raise BadInput(field, f"unknown plant key {key!r}; allowed: {allowed(KEYS)}")
    k = KEYS[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise BadInput(field, f"must be a number, got {value!r}")
    if k.integer and value != int(value):
        raise BadInput(field, f"must be an integer, got {value!r}")
    if not k.lo <= value <= k.hi:
        raise BadInput(field, f"must be in [{k.lo:g}, {k.hi:g}] {k.unit}, got {value!r}")
    return int(value) if k.integer else float(value)


def base_values(mock: dict[str, Any]) -> dict[str, float | int]:
    """Every key's value on the base rig (factors 1)."""
    from mock_hw.plant import MockConfig

    c = MockConfig.from_dict(mock)
    return {n: (1.0 if k.kind == "factor" else 0.0) for n, k in KEYS.items()} | {
        "current_noise": c.currents.noise_std, "voltage_noise": c.voltages.noise_std,
        "current_offset": c.currents.offset[0], "voltage_offset": c.voltages.offset[0],
        "encoder_lines": c.encoder.lines, "dead_time": c.inverter.dead_time,
    }  # fmt: skip


def apply(mock: dict[str, Any], plant: dict[str, float | int]) -> dict[str, Any]:
    """A new ``[mock]`` table: ``mock`` with the plant keys applied (``mock`` itself is not changed)."""
    from mock_hw.plant import MockConfig

    out = {k: dict(v) if isinstance(v, dict) else v for k, v in mock.items()}
    if not plant:
        return out
    base = MockConfig.from_dict(mock)
    m: MotorParams = base.motor.params
    f = {k: float(plant.get(k, 1.0)) for k in ("R_s", "R_r", "L_m", "leakage", "J", "B_visc", "m_coulomb")}
    motor = {"R_s": m.R_s * f["R_s"], "R_r": m.R_r * f["R_r"], "J": m.J * f["J"], "B_visc": m.B_visc * f["B_visc"],
             "m_coulomb": m.m_coulomb * f["m_coulomb"]}  # fmt: skip
    if f["L_m"] != 1.0 or f["leakage"] != 1.0:  # (untouched otherwise: L_m + (L_s - L_m) need not be L_s exactly)
        L_m = m.L_m * f["L_m"]
        motor.update(L_m=L_m, L_s=L_m + (m.L_s - m.L_m) * f["leakage"], L_r=L_m + (m.L_r - m.L_m) * f["leakage"])
    out["motor"] = {**out.get("motor", {}), **{k: v for k, v in motor.items() if v != getattr(m, k)}}
    if not out["motor"]:
        del out["motor"]

    def set_(table: str, name: str, value: Any) -> None:
        out[table] = {**out.get(table, {}), name: value}

    if "current_noise" in plant:
        set_("currents", "noise_std", float(plant["current_noise"]))
    if "voltage_noise" in plant:
        set_("voltages", "noise_std", float(plant["voltage_noise"]))
    if "current_offset" in plant:
        set_("currents", "offset", [float(plant["current_offset"]), *base.currents.offset[1:]])
    if "voltage_offset" in plant:
        set_("voltages", "offset", [float(plant["voltage_offset"]), *base.voltages.offset[1:]])
    if "encoder_lines" in plant:
        set_("encoder", "lines", int(plant["encoder_lines"]))
    if "dead_time" in plant:
        set_("inverter", "dead_time", float(plant["dead_time"]))
    return out
