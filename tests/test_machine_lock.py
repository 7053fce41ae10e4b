"""The test runs' machine lock (tests/conftest.py): a test marked realtime holds the machine alone, any other test
shares it. Probed with a second open file description of the same lock, as another worker's or run's would be."""

from __future__ import annotations

import fcntl

import pytest

from conftest import MACHINE_LOCK


def _can_take(mode: int) -> bool:
    with open(MACHINE_LOCK, "a") as f:
        try:
            fcntl.flock(f, mode | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return True


@pytest.mark.realtime
def test_a_realtime_test_holds_the_machine_alone() -> None:
    assert not _can_take(fcntl.LOCK_SH)


def test_any_other_test_shares_the_machine() -> None:
    assert _can_take(fcntl.LOCK_SH) and not _can_take(fcntl.LOCK_EX)
