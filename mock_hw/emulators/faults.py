"""Fault injection for the emulators: what goes wrong, when, for how long.

A `Fault` is scheduled in emulator ticks (SYNC count), so an injected fault hits the same sample
in every run (deterministic in lockstep). In a rig file (``[[emulator.faults]]``) times are in
seconds and converted with the loop period::

    [[emulator.faults]]
    kind = "drop"        # see KINDS
    at = 0.8             # [s] first affected sample
    duration = 0.002     # [s] how long (default: one sample)
    arg = 0              # kind-specific (jump: counts; delay: samples)

Serial stream (measurement front-end): ``drop`` (frames not sent), ``corrupt`` (one byte flipped,
CRC fails), ``delay`` (each frame sent ``arg`` samples late, default 1), ``duplicate`` (each
frame sent twice), ``stall`` (nothing sent; the stream resumes afterwards), ``disconnect`` (the
connection is closed at ``at``; the host must reconnect).
Encoder: ``encoder_stuck`` (counter frozen), ``encoder_jump`` (counter steps by ``arg`` counts,
default 1000, once). Inverter: ``inverter_fault`` (drive trips; latched until a fault reset),
``heartbeat_lost`` (no status frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bench.errors import BadInput, allowed

KINDS = ("drop", "corrupt", "delay", "duplicate", "stall", "disconnect", "encoder_stuck", "encoder_jump",
         "inverter_fault", "heartbeat_lost")  # fmt: skip


@dataclass(frozen=True)
class Fault:
    kind: str
    at: int  # first tick
    duration: int = 1  # ticks
    arg: int = 0

    def active(self, k: int) -> bool:
        return self.at <= k < self.at + self.duration


def parse_faults(items: Any, T_s: float, prefix: str = "emulator.faults") -> list[Fault]:
    """Validate ``[[emulator.faults]]`` tables (times in seconds) into tick-scheduled faults."""
    if not isinstance(items, list):
        raise BadInput(prefix, "must be an array of tables ([[emulator.faults]])")
    out = []
    for n, item in enumerate(items):
        name = f"{prefix}[{n}]"
        if not isinstance(item, dict):
            raise BadInput(name, "must be a table with kind, at, duration, arg")
        for key in item:
            if key not in ("kind", "at", "duration", "arg"):
                raise BadInput(f"{name}.{key}", "unknown field; allowed: kind, at, duration, arg")
        kind = item.get("kind")
        if kind not in KINDS:
            raise BadInput(f"{name}.kind", f"must be one of {allowed(KINDS)}, got {kind!r}")
        at, dur, arg = item.get("at", 0.0), item.get("duration", T_s), item.get("arg", 0)
        for key, v in (("at", at), ("duration", dur)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 3600:
                raise BadInput(f"{name}.{key}", f"must be a time in [0, 3600] s, got {v!r}")
        if isinstance(arg, bool) or not isinstance(arg, int):
            raise BadInput(f"{name}.arg", f"must be an integer, got {arg!r}")
        out.append(Fault(kind, int(round(at / T_s)), max(1, int(round(dur / T_s))), arg))
    return out
