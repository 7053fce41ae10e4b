"""Output files: checked before any work starts, never overwritten silently.

A run that would fail to write its log, summary or plot after minutes of work (a missing or
read-only folder, a path that is a directory) is refused at once with one line naming the option;
an existing file is kept unless the user passes ``--force``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from bench.errors import BadInput


def check_name(option: str, path: Path) -> None:
    """Refuse a path that cannot name a file: empty, ``.``/``..``, a name or path longer than the file
    system takes (the limits of the nearest existing folder; 255 bytes a name, 4096 a path elsewhere)."""
    name = path.name
    if not str(path).strip() or name in ("", ".", ".."):
        raise BadInput(option, f"needs a file name, got {str(path)!r}")
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        name_max, path_max = os.pathconf(folder, "PC_NAME_MAX"), os.pathconf(folder, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    too_long = next((p for p in (path, *path.parents) if len(os.fsencode(p.name)) > name_max), None)
    if too_long is not None:
        raise BadInput(option, f"a file or folder name may have at most {name_max} bytes, "
                       f"{too_long.name[:20]}... has {len(os.fsencode(too_long.name))}")  # fmt: skip
    size = len(os.fsencode(path.absolute()))
    if size >= path_max:
        raise BadInput(option, f"the path may have at most {path_max - 1} bytes, got {size}")


def check_output(option: str, path: Path, force: bool) -> None:
    """Refuse, before anything runs, an output path that exists (without --force) or cannot be written."""
    check_name(option, path)
    if path.is_dir():
        raise BadInput(option, f"{path} is a directory; give a file path")
    if path.exists() and not force:
        raise BadInput(option, f"{path} exists; pass --force to overwrite it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".bench-probe-"):
            pass
    except OSError as exc:
        raise BadInput(option, f"cannot write in {path.parent}: {exc.strerror or exc}") from None


def free_path(path: Path) -> Path:
    """``path`` if nothing is there, else the first free ``stem-2.suffix``, ``stem-3.suffix``, ...: a derived
    file (a re-drawn plot) gets a new name instead of replacing one the user may be looking at."""
    n = 1
    candidate = path
    while candidate.exists() or candidate.is_symlink():
        n += 1
        candidate = path.with_name(f"{path.stem}-{n}{path.suffix}")
    return candidate


def new_folders(*paths: Path | None) -> list[Path]:
    """The folders among ``paths`` and their parents that do not exist yet, deepest first: what a run
    creates, and removes again (`remove_empty`) when it is refused before it wrote anything."""
    out: list[Path] = []
    for path in paths:
        if path is None:
            continue
        for p in (path, *path.parents):
            if p.exists():
                break
            if p not in out:
                out.append(p)
    return sorted(out, key=lambda p: len(p.parts), reverse=True)


def remove_empty(folders: list[Path]) -> None:
    """Remove those of ``folders`` (deepest first) that are empty; leave the rest."""
    for p in folders:
        try:
            p.rmdir()
        except OSError:
            pass
