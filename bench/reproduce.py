"""Reproductions of thesis figures: `bench reproduce NAME [--out DIR]` writes NAME.png and NAME.json.

Each reproduction is a function ``(out_dir: Path) -> dict`` registered in `REPRODUCTIONS` with a
one-line description; it writes its PNG and JSON into ``out_dir`` and returns the numbers it
wrote. Modules that provide reproductions register them with `register`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from importlib import import_module
from pathlib import Path
from typing import Any

from bench.errors import BadInput, allowed

Reproduction = Callable[[Path], dict[str, Any]]
REPRODUCTIONS: dict[str, tuple[str, Reproduction]] = {}

# modules whose import registers reproductions (kept lazy: some pull in heavy dependencies)
PROVIDERS: tuple[str, ...] = (
    "bench.reproductions.kubota_analysis",
    "bench.reproductions.speed_estimation",
    "bench.reproductions.lpv_observer",
    "bench.reproductions.closed_loop",
    "bench.reproductions.lpv_current",
    "bench.reproductions.narx",
    "bench.reproductions.lpv_speed",
)


def register(name: str, description: str) -> Callable[[Reproduction], Reproduction]:
    def deco(fn: Reproduction) -> Reproduction:
        REPRODUCTIONS[name] = (description, fn)
        return fn

    return deco


def _load_providers() -> None:
    for mod in PROVIDERS:
        import_module(mod)


def available() -> dict[str, str]:
    _load_providers()
    return {name: desc for name, (desc, _) in sorted(REPRODUCTIONS.items())}


def reproduce(name: str, out_dir: Path) -> dict[str, Any]:
    _load_providers()
    if name not in REPRODUCTIONS:
        raise BadInput("reproduction", f"unknown reproduction {name!r}; allowed: {allowed(sorted(REPRODUCTIONS)) or '(none yet)'}")
    out_dir.mkdir(parents=True, exist_ok=True)
    result = REPRODUCTIONS[name][1](out_dir)
    (out_dir / f"{name}.json").write_text(json.dumps(result, indent=2, default=float))
    return result
