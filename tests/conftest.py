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
    try:
        from bench.batch import Run, simulate  # the plant, the FOC tick and its parts, the batch loop
        from bench.config import load
    except ImportError:  # (numba missing: the tests that need it say so)
        return
    simulate([Run(load("mock"))], "fig5.7", 0.01)


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


STALL_TRIP = "loop stall (the drive held the last command)"  # the tail the supervisor gives a trip after a stall


def _run_in_pty_at_speed(argv: list[str], columns: int = 220) -> tuple[int, str]:
    """`_run_in_pty` for a real-time `bench run` at speed: a run that tripped just after an OS stall of the loop
    (the supervisor says so; see `_tripped_before`) is not what the test is about, so it runs once more (the log
    overwritten); any other outcome, and the second run's, is returned as it is."""
    code, text = _run_in_pty(argv, columns)
    if code == 1 and STALL_TRIP in text:
        code, text = _run_in_pty([*argv, "--force"], columns)
    return code, text


@pytest.fixture
def run_in_pty_at_speed() -> Callable[..., tuple[int, str]]:
    return _run_in_pty_at_speed


def _tripped_before(summary: dict, sent_ns: int) -> str | None:
    """Why a real-time run ended on its own, through a loop stall, before a signal sent at ``sent_ns``
    (``time.time_ns()``); None if it did not.

    On a loaded 2-core machine an OS stall of the loop holds a stale stator-frame voltage; at speed, 4-16 ms of it
    over-currents the motor: a true trip (the supervisor names the stall in its cause), but one that comes before
    the fault a test sends, so that run never received it. Tests of a signal's handling repeat their set-up once
    on this (as the fault matrix does); any other early end is a failure."""
    t_sent = (sent_ns - summary["start_epoch_ns"]) / 1e9  # the loop's time when the signal was sent
    cause, t_trip = summary.get("trip_cause") or "", summary.get("trip_time")
    if "loop stall" in cause and t_trip is not None and t_trip < t_sent:
        return f"{cause} at {t_trip:.3f} s, before the signal at {t_sent:.3f} s"
    return None


@pytest.fixture
def tripped_before() -> Callable[[dict, int], str | None]:
    return _tripped_before
