"""A trip that follows a loop stall names it, and says whether the stall was within the drive's ride-through."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bench.hal import Measurement
from bench.core.supervisor import STALL_BLAME, STALL_NOTE, Limits, Supervisor

ROOT = Path(__file__).resolve().parents[1]
T = 1 / 3000


def _m(k: int, i_a: float = 0.0, enc: int = 7) -> Measurement:
    return Measurement(k * T, i_a, -i_a / 2, -i_a / 2, 0.0, 0.0, 0.0, enc, -1, 560.0, True, False, (0, 0, 0), (0, 0, 0))


def _run(ticks: list[int], over_at: int) -> str | None:
    sup = Supervisor(Limits(max_stall=0.05), 4096, 1 << 16, 2, T)
    sup.enable_cmd = True
    for k in ticks:
        sup.check_measurement(_m(k, 20.0 if k == over_at else 1.0))
    return sup.cause


def test_an_over_current_just_after_a_stall_names_the_stall() -> None:
    skip = 48  # ticks missed: 16 ms, below max_stall (50 ms): no stall trip of its own
    cause = _run(list(range(10)) + [10 + skip, 11 + skip], over_at=11 + skip)
    assert cause is not None and cause.startswith("over-current: phase |i| = 20.00 A > 15 A")
    assert cause.endswith("; 0.3 ms after a 16.0 ms loop stall (within the drive's 20 ms ride-through)"), cause
    cause = _run(list(range(10)) + [10 + 75, 11 + 75], over_at=11 + 75)  # 25 ms: longer than the budget
    assert cause is not None and cause.endswith("after a 25.0 ms loop stall (longer than the drive's 20 ms ride-through)")


def test_no_stall_named_without_one_or_when_it_is_long_past_or_too_short() -> None:
    assert _run(list(range(20)), over_at=15) == "over-current: phase |i| = 20.00 A > 15 A"
    gap = int(round(STALL_BLAME / T)) + 2  # the over-current comes after the blame window
    assert _run(list(range(5)) + [60 + k for k in range(gap + 1)], over_at=60 + gap) == \
        "over-current: phase |i| = 20.00 A > 15 A"  # fmt: skip
    short = round(STALL_NOTE / T) - 1  # ticks missed: a stall one tick shorter than STALL_NOTE
    assert _run(list(range(5)) + [5 + short, 6 + short], over_at=6 + short) == "over-current: phase |i| = 20.00 A > 15 A"


def test_a_requested_trip_and_the_stall_trip_itself_are_not_annotated() -> None:
    sup = Supervisor(Limits(max_stall=0.05), 4096, 1 << 16, 2, T)
    for k in range(5):
        sup.check_measurement(_m(k))
    sup.request_trip("interrupted (SIGINT)")
    sup.check_measurement(_m(40))
    assert sup.cause == "interrupted (SIGINT)"
    sup = Supervisor(Limits(max_stall=0.01), 4096, 1 << 16, 2, T)
    for k in list(range(5)) + [200]:
        sup.check_measurement(_m(k))
    assert sup.cause is not None and sup.cause.startswith("loop stall: 65.0 ms") and sup.cause.count("loop stall") == 1


_SLEEPY = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from bench.runtime.session import RunOptions, run
    from bench.workflows.commission.rotating import RotatingIdController as C
    orig, done = C.step, []
    def step(self, meas, w, i):
        if meas.t >= 1.5 and not done:
            done.append(meas.t)
            time.sleep(float(sys.argv[1]))
        return orig(self, meas, w, i)
    C.step = step
    summary, code = run(RunOptions(log=Path("run.mcap"), duration=2.5, realtime=True, progress=False,
                                   controller="rotating_id", scenario="demo"))
    sys.exit(code)
""")


def _sleepy_run(tmp_path: Path, stall: float) -> tuple[int, dict, str]:
    """A real process paced by the wall clock: the rotating test turns the motor at 150 rad/s and one controller
    tick sleeps ``stall`` seconds at 1.5 s (the mock rig: ride_through 50 ms, max_stall 50 ms)."""
    p = subprocess.run([sys.executable, "-c", _SLEEPY, str(stall)], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})  # fmt: skip
    return p.returncode, json.loads((tmp_path / "run.summary.json").read_text()), p.stderr


@pytest.mark.realtime
def test_a_real_time_run_at_speed_rides_through_a_stall(tmp_path: Path) -> None:
    """A 10 ms stall at speed (the drive turns the last reference at the field's frequency): the run goes on
    to its end, and the summary and the log (tick gaps) record the stall."""
    code, summary, err = _sleepy_run(tmp_path, 0.010)
    assert code == 0, (summary["trip_cause"], err)
    st = summary["stalls"]
    ours = [ms for t, ms in st["events"] if 1.5 <= t < 1.5 + 0.05]
    assert ours and 9.5 <= max(ours) <= 20.0, st  # the stall that was made (plus the OS's own)
    assert st["drive"]["ride_throughs"] == st["count"] and st["drive"]["missed"] >= 29, st
    from bench.daq import LogReader

    ticks = LogReader(tmp_path / "run.mcap").read("/rig")["tick"]
    assert round(max(ours) * 3) + 1 in set((ticks[1:] - ticks[:-1]).tolist()), "the stall is a gap in the log's ticks"


@pytest.mark.realtime
def test_a_real_time_stall_longer_than_the_ride_through_ends_safe_and_says_so(tmp_path: Path) -> None:
    """80 ms at speed: the drive coasts after its 50 ms budget with a set-point watchdog fault, and the PC's
    trip, past max_stall, is the stall trip itself."""
    code, summary, err = _sleepy_run(tmp_path, 0.08)
    assert code == 1, err
    cause = summary["trip_cause"]
    assert cause.startswith("loop stall: ") and cause.endswith("the drive coasts after its 50 ms ride-through"), cause
    assert 1.5 + 0.08 <= summary["trip_time"] < 1.5 + 0.08 + STALL_BLAME  # at the first tick after the stall
    assert summary["stalls"]["drive"]["longest_ms"] == pytest.approx(50.0 + 1e3 / 3000, abs=1e-3), summary["stalls"]
