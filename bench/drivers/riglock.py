"""One session per rig: an OS lock on every device a driver rig opens.

A session holds one `fcntl.flock` per device (CAN interface + channel, serial port, Modbus TCP host:port
or RTU serial port) on a file in this user's runtime folder (`runtime_dir`), from before anything is sent
on any link until the rig is closed; the kernel releases it when the process dies, whatever killed it.
The holder writes its pid, command line and the time it took the lock into the file, so a second session
is refused in one line that names it (`BadInput`, exit 2) - before it has sent a byte.

Devices that live inside one process (python-can's ``virtual`` bus, pyserial's ``loop://``) and
``port = 0`` (an in-process emulator's free port, locked once it is bound) need no lock. The lock is per
user: sessions of other users are kept off by the devices' own permissions (and `bench emulate` serves one
controller at a time).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shlex
import stat
import sys
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

from bench.errors import BadInput

RUNTIME_ENV = "IMBENCH_RUNTIME_DIR"  # overrides the folder (tests); every process of a rig must see the same


def runtime_dir() -> Path:
    """This user's folder for rig locks and emulator session secrets: /tmp/imbench-UID, mode 0700.

    One fixed path per user rather than $XDG_RUNTIME_DIR, which cron, ``su`` and some ssh sessions do not
    set: two sessions that looked in different folders would both get "their" lock. A folder that is not
    a real directory owned by this user with no access for others is refused (someone else made it).
    """
    env = os.environ.get(RUNTIME_ENV)
    path = Path(env) if env else Path("/tmp") / f"imbench-{os.getuid()}"
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        raise BadInput(str(path), f"cannot make the runtime folder (rig locks, emulator secrets): "
                       f"{exc.strerror or exc}") from None  # fmt: skip
    st = os.lstat(path)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o077:
        what = "not a directory" if not stat.S_ISDIR(st.st_mode) else (
            f"owned by uid {st.st_uid}, not {os.getuid()}" if st.st_uid != os.getuid()
            else f"mode {stat.S_IMODE(st.st_mode):04o}, open to others")  # fmt: skip
        raise BadInput(str(path), f"the runtime folder (rig locks, emulator secrets) is {what}; it must be a "
                       f"folder of yours with mode 0700: remove it, or set {RUNTIME_ENV}")  # fmt: skip
    return path


def process_start(pid: int) -> int | None:
    """The start time of process ``pid`` in clock ticks after boot (/proc), None if it is gone or a zombie."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return None
    rest = raw[raw.rindex(b")") + 2:].split()  # after "pid (comm) ": state is field 3, starttime field 22
    return None if rest[0] == b"Z" else int(rest[19])


def process_alive(pid: int, start: int | None = None) -> bool:
    """True if ``pid`` runs (not a zombie) and, given ``start``, is the process that started then (not a reuse)."""
    if pid <= 0:
        return False
    now = process_start(pid)
    if now is None:
        if Path("/proc/self/stat").exists():
            return False
        try:  # no /proc: the pid alone
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    return start is None or now == start


def command_line() -> str:
    """This process's command line as typed (from /proc, else sys.argv)."""
    try:
        args = Path("/proc/self/cmdline").read_bytes().rstrip(b"\0").split(b"\0")
        return shlex.join(a.decode(errors="replace") for a in args)
    except OSError:
        return shlex.join([sys.executable, *sys.argv])


def device_keys(hw: dict[str, dict[str, Any]]) -> dict[str, str]:
    """The devices a driver rig opens, as lock keys -> the rig-file field that names each."""
    keys: dict[str, str] = {}

    def device(path: str) -> str:
        return "dev:" + os.path.realpath(path)  # /dev/serial/by-id/... and /dev/ttyUSB0 are one device

    can = hw["can"]
    if can["interface"] == "tcp":
        from bench.wire.tcpcan import parse_channel

        host, port = parse_channel(can["channel"])
        if port:
            keys[f"tcp:{host}:{port}"] = "can.channel"
    elif can["interface"] != "virtual":  # the virtual bus lives in one process
        keys[f"can:{can['interface']}:{can['channel']}"] = "can.channel"
    url = str(hw["serial"]["port"])
    if url.startswith("socket://"):
        host, _, port = url[len("socket://"):].partition(":")
        port = port.split("?")[0]
        if port not in ("", "0"):
            keys.setdefault(f"tcp:{'127.0.0.1' if host == 'localhost' else host}:{int(port)}", "serial.port")
    elif url.startswith("/"):
        keys.setdefault(device(url), "serial.port")
    elif "://" in url and not url.startswith("loop://"):  # rfc2217://, spy://, ...: the URL
        keys.setdefault(f"url:{url}", "serial.port")
    mb = hw["modbus"]
    if mb["transport"] == "tcp":
        if mb["port"]:
            host = "127.0.0.1" if mb["host"] == "localhost" else mb["host"]
            keys.setdefault(f"tcp:{host}:{mb['port']}", "modbus.port")
    else:
        keys.setdefault(device(mb["serial_port"]), "modbus.serial_port")
    return keys


class RigLock:
    """The locks of one session on a rig's devices: `acquire` (all or none), `release` (also at exit)."""

    def __init__(self, hw: dict[str, dict[str, Any]], rig: str = "") -> None:
        self.rig = rig
        self.keys = device_keys(hw)
        self._held: dict[str, tuple[int, Path]] = {}  # key -> (fd, lock file)

    def add(self, hw: dict[str, dict[str, Any]]) -> None:
        """More devices (an in-process emulator's bound ports); taken at the next `acquire`."""
        for k, v in device_keys(hw).items():
            self.keys.setdefault(k, v)

    def acquire(self) -> None:
        """Take every device's lock not yet held; `BadInput` naming the holder if one is taken (nothing kept)."""
        missing = [key for key in self.keys if key not in self._held]
        if not missing:
            return
        folder = runtime_dir()
        try:
            for key in missing:
                self._held[key] = self._lock(folder / f"rig-{quote(key, safe='')}.lock", key, self.keys[key])
        except BaseException:
            for key in missing:
                self._drop(key)
            raise

    def _lock(self, path: Path, key: str, fld: str) -> tuple[int, Path]:
        while True:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                    raise BadInput(fld, f"cannot lock {path}: {exc.strerror or exc}") from None
                raise BadInput(fld, f"{key.split(':', 1)[1]} is in use by another session: {holder(path)}; "
                               "one session per rig: wait for it to end, or stop it") from None  # fmt: skip
            try:
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except OSError:
                same = False
            if same:  # else the holder removed the file between our open and flock (its release): again
                break
            os.close(fd)
        info = {"pid": os.getpid(), "start": process_start(os.getpid()), "command": command_line(),
                "since": time.strftime("%Y-%m-%d %H:%M:%S"), "rig": self.rig, "device": key}  # fmt: skip
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        return fd, path

    def _drop(self, key: str) -> None:
        held = self._held.pop(key, None)
        if held is not None:
            fd, path = held
            with contextlib.suppress(OSError):
                path.unlink()  # while still locked: whoever opened it meanwhile sees it gone and opens anew
            os.close(fd)  # the lock goes with the last descriptor

    def release(self) -> None:
        for key in list(self._held):
            self._drop(key)


def holder(path: Path, wait: float = 0.5) -> str:
    """Who holds the lock of ``path``, as the holder wrote it ("pid N (command), since T")."""
    end = time.monotonic() + wait
    while True:
        try:
            info = json.loads(path.read_text())
            pid = int(info["pid"])
            if process_alive(pid, info.get("start")):
                cmd = " ".join("".join(c if c.isprintable() else " " for c in str(info.get("command", "?"))).split())
                cmd = cmd if len(cmd) <= 160 else cmd[:157] + "..."
                return f"pid {pid} (`{cmd}`), since {info.get('since', '?')}"
        except (OSError, ValueError, KeyError, TypeError):
            pass
        if time.monotonic() >= end:  # the holder is still writing its name (or is not imbench)
            return "a process that did not say who it is"
        time.sleep(0.02)
