"""Helpers for tests and benchmarks: emulated rig configs on free ports, and in-process sessions."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import tomlkit

from bench.core.config import RIGS_DIR, RigConfig, parse

EMULATED = RIGS_DIR / "emulated.toml"


def emulated_data(interface: str = "virtual", **tables: dict[str, Any]) -> dict[str, Any]:
    """rigs/emulated.toml as a dict, on free ports (port 0), emulators started in-process.

    ``interface``: "virtual" (fastest, one process) or "tcp" (the shipped default). ``tables``
    update the tables of the file, e.g. ``limits={"stale_ticks": 5}``.
    """
    data = tomllib.loads(EMULATED.read_text())
    data["can"]["interface"] = interface
    data["can"]["channel"] = "127.0.0.1:0" if interface == "tcp" else f"imbench-test-{id(data)}"
    data["serial"]["port"] = "socket://127.0.0.1:0"
    data["modbus"]["port"] = 0
    data["emulator"]["autostart"] = "always"
    # lockstep tests have no deadline: a generous frame timeout keeps a busy CI machine from
    # reading as a stale link (a dropped frame still shows up, only 0.25 s later)
    data["serial"]["timeout"] = 0.25
    for name, table in tables.items():
        data.setdefault(name, {}).update(table)
    return data


def emulated_config(interface: str = "virtual", **tables: dict[str, Any]) -> RigConfig:
    return parse(emulated_data(interface, **tables), str(EMULATED))


def write_rig(path: Path, data: dict[str, Any]) -> Path:
    """Write a rig dict as TOML (tomlkit: every table, array of tables, inf and nan)."""
    path.write_text(tomlkit.dumps(data))
    return path


def with_limits(cfg: RigConfig, **limits: Any) -> RigConfig:
    return replace(cfg, limits=replace(cfg.limits, **limits))
