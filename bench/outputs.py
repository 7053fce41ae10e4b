"""Output files: checked before any work starts, never overwritten silently.

A run that would fail to write its log, summary or plot after minutes of work (a missing or
read-only folder, a path that is a directory) is refused at once with one line naming the option;
an existing file is kept unless the user passes ``--force``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from bench.errors import BadInput


def check_output(option: str, path: Path, force: bool) -> None:
    """Refuse, before anything runs, an output path that exists (without --force) or cannot be written."""
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
