"""Replacing a rig file the user keeps, safely: `bench identify --write`, `bench commission`, `bench calibrate`.

The command reads the file once when it starts (`Snapshot`); at the end `replace_file` locks the file (`flock`,
`LOCK_WAIT`), checks that it still holds what was read (else refused: "rig file changed since this run read it"),
and then, inside `bench.core.shutdown.commit_section` (signals deferred): the new text into a temporary file beside it,
fsync; the old bytes into ``<file>.<UTC stamp>.bak``, fsync; the rename over the file - the commit point -; fsync
of the folder. A signal before the commit point leaves the file byte for byte and no temporary file or backup;
one from the commit section on lets the command finish. A symbolic link is written through: its target is
replaced in the target's folder (the backup beside the target), the link stays a link.

What goes into the file is the command's own business (`bench.workflows.commission.rigfile.motor_text`,
`bench.core.config.write_offsets`); every writer parses its new text back as a rig file before it gets here.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.errors import BadInput
from bench.core.shutdown import commit_section, pause_for_test

# A second writer of the same file waits this long for the lock, then is refused naming the holder. The lock is
# held only from the final check to the end of the commit (milliseconds; a slow disk's fsync, a second or two):
# waiting briefly lets two commands that finish together both be told the truth (the later one is then refused
# because the file changed); a holder for longer is stuck (stopped with Ctrl-Z, a hung disk), and a command
# whose rig is already safe must not hang on it.
LOCK_WAIT = 5.0  # [s]


RIGS_DIR = Path(__file__).resolve().parents[2] / "rigs"  # the rig files shipped with imbench (rigs/NAME.toml)
# the rig files shipped in imbench's rigs/ folder (tests/test_calibrate_write.py holds this to the source tree's):
# a user's own file may sit beside them (docs/at-the-rig.md: cp rigs/lab-example.toml rigs/mylab.toml)
SHIPPED = ("emulated", "lab-example", "mock", "mock-hot-rotor", "mock-real", "mock-warm", "mock-warm-fast")


def check_writable(path: Path, field: str) -> None:
    """Refuse (one line) before any test runs: a rig file that cannot be written with its backup beside it
    (a symbolic link: its target, in the target's folder), or one of the rig files shipped with imbench
    (`SHIPPED` in `RIGS_DIR`: they are the source tree's)."""

    target = path.resolve()
    if target.parent == RIGS_DIR.resolve() and target.suffix == ".toml" and target.stem in SHIPPED:
        raise BadInput(field, f"{path} is a rig file shipped with imbench; copy it and give the copy "
                       f"(cp {path} runs/lab.toml)")  # fmt: skip
    if not (os.access(target, os.W_OK) and os.access(target.parent, os.W_OK)):
        where = f" (the target of the link {path})" if path.is_symlink() else ""
        raise BadInput(field, f"cannot write {target}{where} (and its backup next to it)")


@dataclass(frozen=True)
class Snapshot:
    """A rig file as this run read it: ``path`` as given (maybe a symbolic link), ``target`` the file it
    names (links resolved), ``data`` its bytes."""

    path: Path
    target: Path
    data: bytes

    @classmethod
    def read(cls, path: str | Path) -> "Snapshot":
        """``path`` as it is now (`BadInput` naming it if it cannot be read)."""
        p = Path(path)
        target = p.resolve()
        try:
            return cls(p, target, target.read_bytes())
        except OSError as exc:
            raise BadInput(str(path), f"cannot read: {exc.strerror or exc}") from None

    @property
    def text(self) -> str:
        return self.data.decode("utf-8")


def utc_stamp() -> str:
    """Now, as the backups' names and the written values' comments carry it: ``20250131-142501`` (UTC)."""
    return time.strftime("%Y%m%d-%H%M%S", time.gmtime())


def replace_file(snap: Snapshot, new: str, stamp: str | None = None, field: str = "--write") -> dict[str, Any]:
    """Replace ``snap``'s file by ``new`` as the module docstring says (the backup named with ``stamp``, default
    `utc_stamp`); returns ``rig_file`` (as given), ``target`` (the file replaced, where written through a link),
    ``backup``. `BadInput` (one line, nothing written): the file changed since
    ``snap`` was read, another writer holds it longer than `LOCK_WAIT`, or it cannot be written."""
    stamp = stamp or utc_stamp()
    where = snap.path
    target = snap.path.resolve()
    if target != snap.target:
        raise BadInput(field, f"not written: rig file changed since this run read it ({where} now names {target}, "
                       f"not {snap.target})")  # fmt: skip
    with _locked(target, field):
        try:
            now = target.read_bytes()
            st = os.stat(target)
        except OSError as exc:
            raise BadInput(field, f"not written: cannot read {target}: {exc.strerror or exc}") from None
        if now != snap.data:
            raise BadInput(field, f"not written: rig file changed since this run read it ({target}); run again on "
                           "the file as it is now")  # fmt: skip
        pause_for_test("rigfile-locked")
        tmp: Path | None = None
        backup: Path | None = None
        with commit_section(str(where)) as section:
            try:
                tmp = _write_new(target, new.encode("utf-8"), st)
                backup = _backup(target, snap.data, stamp, st)
                pause_for_test("rigfile-commit")
                os.replace(tmp, target)  # the commit point
            except BaseException as exc:  # nothing in place: the file as it was, no temporary file, no backup
                for f in (tmp, backup):
                    if f is not None:
                        with contextlib.suppress(OSError):
                            f.unlink()
                if isinstance(exc, OSError):  # a full disk, a read-only folder, ...
                    raise BadInput(field, f"not written: {target}: {exc.strerror or exc}; the rig file is as it "
                                   "was") from None  # fmt: skip
                raise
            section.commit()
            synced = _fsync_dir(target.parent)
    pause_for_test("rigfile-committed")
    out: dict[str, Any] = {"rig_file": str(where), "backup": str(backup)}
    if where.is_symlink():
        out["target"] = str(target)  # written through the link
    if not synced:
        out["warning"] = f"the folder {target.parent} could not be synced: the new file is in place, its name may " \
                         "not survive a power cut"  # fmt: skip
    return out


@contextlib.contextmanager
def _locked(target: Path, field: str) -> Iterator[None]:
    """An exclusive `fcntl.flock` on ``target`` itself (no lock file is left beside it): waits up to `LOCK_WAIT`,
    then refuses naming the holder. The lock belongs to the file's inode: one replaced while this waited is
    opened and locked again, so two writers never both hold "the" file."""
    end = time.monotonic() + LOCK_WAIT
    while True:
        try:
            fd = os.open(target, os.O_RDONLY | os.O_CLOEXEC)
        except OSError as exc:
            raise BadInput(field, f"not written: cannot open {target}: {exc.strerror or exc}") from None
        try:
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= end:
                        raise BadInput(field, f"not written: {target} is being written by {_holder(fd)} for more than "
                                       f"{LOCK_WAIT:g} s; the rig file is as it was") from None  # fmt: skip
                    time.sleep(0.02)
            same = _same_file(fd, target)
        except BaseException:
            os.close(fd)
            raise
        if same:
            break
        os.close(fd)  # replaced while this waited: lock the file that is there now
    try:
        yield
    finally:
        os.close(fd)  # releases the lock


def _same_file(fd: int, target: Path) -> bool:
    a = os.fstat(fd)
    try:
        b = os.stat(target)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _holder(fd: int) -> str:
    """Who holds the flock on ``fd``'s file: ``PID n (command line)`` from /proc/locks where readable."""
    ino = os.fstat(fd).st_ino
    try:
        for line in Path("/proc/locks").read_text().splitlines():
            f = line.split()
            if "->" not in f and len(f) >= 6 and f[1] == "FLOCK" and f[5].rsplit(":", 1)[-1] == str(ino):
                pid = int(f[4])
                if pid == os.getpid():
                    continue
                try:
                    cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                except OSError:
                    cmd = "?"
                cmd = " ".join(cmd.split())  # one line, whatever the arguments hold
                return f"PID {pid} ({cmd[:117] + '...' if len(cmd) > 120 else cmd})"
    except (OSError, ValueError):
        pass
    return "another process"


def _write_new(target: Path, data: bytes, st: os.stat_result) -> Path:
    """``data`` in a new temporary file beside ``target`` with its mode (and owner, where allowed), synced."""
    fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, st.st_mode & 0o7777)
        if (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
            with contextlib.suppress(OSError):
                os.fchown(fd, st.st_uid, st.st_gid)
    except BaseException:
        os.close(fd)
        os.unlink(name)
        raise
    _fill(fd, Path(name), data)
    return Path(name)


def _backup(target: Path, data: bytes, stamp: str, st: os.stat_result) -> Path:
    """The bytes the run read, as ``<file>.<stamp>.bak`` beside ``target`` (``-2``, ``-3``, ... if that name is
    taken: a backup is never overwritten), with the file's mode and times, synced."""
    for n in range(1, 1000):
        path = target.with_name(f"{target.name}.{stamp}{'' if n == 1 else f'-{n}'}.bak")
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, st.st_mode & 0o7777)
            break
        except FileExistsError:
            continue
    else:
        raise FileExistsError(f"no free backup name beside {target}")
    _fill(fd, path, data)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    return path


def _fill(fd: int, path: Path, data: bytes) -> None:
    """Write ``data`` to the new file ``fd`` (at ``path``), sync and close it; on any failure it goes again."""
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        os.unlink(path)
        raise
    os.close(fd)


def _fsync_dir(folder: Path) -> bool:
    """fsync ``folder`` (the rename in it reaches the disk); False where that fails."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        os.fsync(fd)
        return True
    except OSError:
        return False
    finally:
        os.close(fd)
