"""Reproductions of thesis figures: `bench reproduce NAME [--out DIR]` writes NAME.png and NAME.json.

Each reproduction is a function ``(out_dir: Path) -> dict`` registered in `REPRODUCTIONS` with a
one-line description; it writes its PNG and JSON into ``out_dir`` and returns the numbers it
wrote. Modules that provide reproductions register them with `register`.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from importlib import import_module
from pathlib import Path
from typing import Any

from bench.errors import BadInput, allowed
from bench.core.outputs import check_output

Reproduction = Callable[[Path], dict[str, Any]]
REPRODUCTIONS: dict[str, tuple[str, Reproduction]] = {}

# modules whose import registers reproductions (kept lazy: some pull in heavy dependencies)
PROVIDERS: tuple[str, ...] = (
    "bench.workflows.reproductions.kubota_analysis",
    "bench.workflows.reproductions.speed_estimation",
    "bench.workflows.reproductions.lpv_observer",
    "bench.workflows.reproductions.closed_loop",
    "bench.workflows.reproductions.lpv_current",
    "bench.workflows.reproductions.narx",
    "bench.workflows.reproductions.lpv_speed",
    "bench.workflows.reproductions.switching",
)


def register(name: str, description: str) -> Callable[[Reproduction], Reproduction]:
    def deco(fn: Reproduction) -> Reproduction:
        REPRODUCTIONS[name] = (description, fn)
        return fn

    return deco


def _load_providers() -> None:
    for mod in PROVIDERS:
        import_module(mod)


def _natural(name: str) -> list[Any]:
    """fig4.6 before fig4.10: numbers compare as numbers."""
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name)]


def available() -> dict[str, str]:
    _load_providers()
    return {name: REPRODUCTIONS[name][0] for name in sorted(REPRODUCTIONS, key=_natural)}


def reproduce(name: str, out_dir: Path, force: bool = False) -> tuple[dict[str, Any], list[Path]]:
    """Run reproduction ``name`` into ``out_dir``; returns (its numbers, the files it wrote).

    A folder that already holds ``NAME.json`` (an earlier reproduction) is refused without ``force``.
    """
    _load_providers()
    if name not in REPRODUCTIONS:
        raise BadInput("reproduction", f"unknown reproduction {name!r}; allowed: "
                       f"{allowed(sorted(REPRODUCTIONS, key=_natural)) or '(none yet)'}")  # fmt: skip
    check_output("--out", out_dir / f"{name}.json", force)
    before = {p: p.stat().st_mtime_ns for p in out_dir.iterdir()} if out_dir.exists() else {}
    result = REPRODUCTIONS[name][1](out_dir)
    (out_dir / f"{name}.json").write_text(json.dumps(result, indent=2, default=float))
    written = sorted(p for p in out_dir.iterdir() if p.is_file() and before.get(p) != p.stat().st_mtime_ns)
    return result, written
