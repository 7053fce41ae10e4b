"""Output files: checked before any work starts, never overwritten silently, never left torn.

A run that would fail to write its log, summary or plot after minutes of work (a missing or
read-only folder, a path that is a directory) is refused at once with one line naming the option;
an existing file is kept unless the user passes ``--force``. Files written whole at the end (the
summary, the plot, a sweep's table) go through `replacing`: a temporary file in the same folder,
renamed over the target only once complete, so a full disk or a crash leaves the old file or none,
never an empty or half-written one; `reserve_room` sets space aside at the start for a file that must
survive a disk the run fills (the summary). `written_note` says what a run left on disk.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def replacing(path: Path) -> Iterator[Path]:
    """``with replacing(p) as tmp: write tmp`` - ``p`` is replaced by ``tmp`` only if the block succeeds
    (flushed to disk first); otherwise ``tmp`` is removed and ``p`` is left as it was. ``tmp`` keeps the
    suffix (matplotlib picks the format by it) and gets the mode of an ordinary new file."""
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it 0600
        yield tmp
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def reserve_room(path: Path, size: int = 64 * 1024) -> Path | None:
    """Set ``size`` bytes of disk aside for ``path`` (a hidden file beside it, freed by `free_room` right
    before ``path`` is written), so that a disk filled meanwhile (by the log) still takes it. None if
    the disk has no room even now."""
    spare = path.with_name(f".{path.name}.reserved")
    try:
        with open(spare, "wb") as f:
            os.posix_fallocate(f.fileno(), 0, size)
        return spare
    except (OSError, AttributeError):  # no room, or no posix_fallocate here
        spare.unlink(missing_ok=True)
        return None


def free_room(spare: Path | None) -> None:
    """Free what `reserve_room` set aside."""
    if spare is not None:
        spare.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (`replacing`)."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def written_note(result: Mapping[str, Any]) -> str:
    """What a run's files came to, from its summary: ``log, summary, plot written``, or e.g.
    ``log (1789 rows lost), summary written; plot NOT written``. A key the result lacks is left out."""
    done, missing = [], []
    for key in ("log", "summary", "plot"):
        if key not in result:
            continue
        if not result[key]:
            missing.append(key)
        elif key == "log" and ((result.get("log_writer") or {}).get("dropped") or 0):
            done.append(f"log ({result['log_writer']['dropped']} rows lost)")
        else:
            done.append(key)
    parts = [f"{', '.join(done)} written"] if done else []
    parts += [f"{', '.join(missing)} NOT written"] if missing else []
    return "; ".join(parts) or "no files"


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
