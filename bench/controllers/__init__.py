"""Controller plugins and their registry.

Plugins are found in two places: the built-in table below (so a source checkout works without
installation) and the ``imbench.controllers`` entry-point group (so other packages can add their
own). `bench controllers` lists them.
"""

from __future__ import annotations

from functools import cache
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import PurePath
from typing import Any

from bench.controllers.base import Controller, ControllerContext
from bench.errors import BadInput, allowed

ENTRY_POINT_GROUP = "imbench.controllers"

_BUILTIN = {
    "foc": "bench.controllers.foc:FocController",
    "relay_tune": "bench.controllers.relay:RelayTuneController",
    "excitation": "bench.controllers.excitation:ExcitationController",
    "standstill_id": "bench.workflows.commission.standstill:StandstillIdController",
    "rotating_id": "bench.workflows.commission.rotating:RotatingIdController",
}


def _load(target: str) -> type[Controller]:
    module, _, attr = target.partition(":")
    return getattr(import_module(module), attr)


def available() -> dict[str, type[Controller]]:
    """All registered controller classes by name (a new dict each call)."""
    return dict(_registry())


@cache
def _registry() -> dict[str, type[Controller]]:
    # once per process: scanning the installed packages' entry points takes ~9 ms, and a session (every
    # sweep case) asks several times; a plugin installed while a process runs shows in the next one
    found: dict[str, type[Controller]] = {n: _load(t) for n, t in _BUILTIN.items()}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in found:
            found[ep.name] = ep.load()
    return found


def create(name: str, ctx: ControllerContext, params: dict[str, Any] | None = None) -> Controller:
    """Instantiate controller ``name``; unknown names and bad parameters raise `BadInput`."""
    table = available()
    if name not in table:
        raise BadInput("controller", f"unknown controller {name!r}; allowed: {allowed(sorted(table))}")
    return table[name](ctx, **(params or {}))


def changed_params(name: str, params: dict[str, Any]) -> dict[str, str]:
    """What distinguishes a run of plugin ``name``: the parameters that differ from its defaults, as short
    text (an artifact path as its file name: ``runs/sc`` -> ``sc``). Unknown plugins: every parameter."""
    cls = available().get(name)
    defaults = {k: p.default for k, p in getattr(cls, "schema", {}).items()}
    out: dict[str, str] = {}
    for key, value in params.items():
        if key in defaults and value == defaults[key]:
            continue
        text = f"{value:g}" if isinstance(value, float) else str(value)
        if isinstance(value, str) and ("/" in value or "\\" in value):
            text = PurePath(value.rstrip("/\\")).name or value
        out[key] = text
    return out


__all__ = ["Controller", "ControllerContext", "available", "changed_params", "create", "ENTRY_POINT_GROUP"]
