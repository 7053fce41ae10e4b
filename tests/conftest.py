"""Shared test helpers."""

from __future__ import annotations

import fcntl
import os
import pty
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the compiled engines into numba's cache (or load them: ~1 s) before any test runs: on a fresh
    install that takes about a minute once, which would otherwise land in whichever test first starts a
    subprocess with a time limit (a real-time `bench run`, a sweep's workers)."""
    try:
        from bench.batch import warmup

        warmup.warm()  # the plant, the FOC tick and its parts, the batch loop; the marker runs then read
    except ImportError:  # (numba missing: the tests that need it say so)
        return


def _run_in_pty(argv: list[str], columns: int = 220) -> tuple[int, str]:
    """Run ``argv`` in the project root with a terminal (a pty) as its stdin, stdout and stderr, as a user at the
    rig does: returns its exit code and everything it wrote."""
    pid, fd = pty.fork()
    if pid == 0:  # the child
        os.chdir(ROOT)
        os.environ["COLUMNS"] = str(columns)
        os.execvp(argv[0], argv)
    out = b""
    while True:
        try:
            d = os.read(fd, 65536)
        except OSError:
            break
        if not d:
            break
        out += d
    _, st = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(st), out.decode(errors="replace")


@pytest.fixture
def run_in_pty() -> Callable[..., tuple[int, str]]:
    return _run_in_pty


# --- the machine, shared between tests that run at once ----------------------------------------------------------
# A test marked ``realtime`` runs a session paced by the wall clock (a 3 kHz loop with its log writer, live service
# or emulators). Beside another test on a 2-core machine its loop stalls past the rig's limit and trips. So every
# test takes the machine's lock, shared, and a real-time test takes it alone: it waits for the running tests of the
# other workers (pytest-xdist: ``-n 2`` in pyproject.toml's addopts) and of any other test run on this machine to
# end, and they start none until it has ended. A turnstile taken before the lock keeps a waiting real-time test
# from starving behind a stream of shared holders (flock has no queue of its own). The lock is per user, in the
# temporary folder.
MACHINE_LOCK = Path(tempfile.gettempdir()) / f"imbench-tests-{os.getuid()}.machine.lock"
_TURNSTILE = MACHINE_LOCK.with_suffix(".turnstile")
_held: dict[str, IO[str]] = {}


def _realtime(item: pytest.Item | None) -> bool:
    return item is not None and item.get_closest_marker("realtime") is not None


def _take(mode: int) -> None:
    lock = open(MACHINE_LOCK, "a")
    with open(_TURNSTILE, "a") as turnstile:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        fcntl.flock(lock, mode)  # (the turnstile is let go as its file closes)
    _held["alone" if mode == fcntl.LOCK_EX else "shared"] = lock


def _let_go() -> None:
    for f in _held.values():
        f.close()  # closing the file lets its flock go
    _held.clear()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Each test (its fixtures' set-up and teardown included) under the machine's lock: alone where it is marked
    ``realtime``, else shared. A real-time test keeps the machine for the next test where that is real-time too
    (a module fixture's session may run between them)."""
    alone = _realtime(item)
    if "alone" not in _held or not alone:
        _let_go()
        _take(fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
    try:
        yield
    finally:
        if not (alone and _realtime(nextitem)):
            _let_go()
