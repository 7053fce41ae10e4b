"""Shared test helpers."""

from __future__ import annotations

import os
import pty
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the compiled engines into numba's cache (or load them: ~1 s) before any test runs: on a fresh
    install that takes about a minute once, which would otherwise land in whichever test first starts a
    subprocess with a time limit (a real-time `bench run`, a sweep's workers)."""
    from bench import jit_warm

    try:
        jit_warm.warm()  # the plant, the FOC tick and its parts, the batch loop; the marker runs then read
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


