"""Helpers for tests and benchmarks: emulated rig configs on free ports, and in-process sessions."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

from bench.config import RIGS_DIR, RigConfig, parse

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
    """Write a rig dict as TOML (flat tables and [[emulator.faults]] only; enough for tests)."""
    lines: list[str] = []

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\\\", "\\\\\\\\").replace('"', '\\\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    def table(prefix: str, t: dict[str, Any]) -> None:
        subs = {k: v for k, v in t.items() if isinstance(v, dict)}
        arrays = {k: v for k, v in t.items() if isinstance(v, list) and v and all(isinstance(x, dict) for x in v)}
        lines.append(f"[{prefix}]")
        for k, v in t.items():
            if k not in subs and k not in arrays:
                lines.append(f"{k} = {val(v)}")
        for k, v in subs.items():
            table(f"{prefix}.{k}", v)
        for k, items in arrays.items():
            for item in items:
                lines.append(f"[[{prefix}.{k}]]")
                lines.extend(f"{a} = {val(b)}" for a, b in item.items())

    for name, t in data.items():
        table(name, t)
    path.write_text("\n".join(lines) + "\n")
    return path


def with_limits(cfg: RigConfig, **limits: Any) -> RigConfig:
    return replace(cfg, limits=replace(cfg.limits, **limits))
