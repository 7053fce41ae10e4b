"""A trip that follows a loop stall names it: the held stator-frame voltage, not the motor, is the cause."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bench.hal import Measurement
from bench.supervisor import STALL_BLAME, STALL_NOTE, Limits, Supervisor

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
    assert cause.endswith("; 0.3 ms after a 16.0 ms loop stall (the drive held the last command)"), cause


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


@pytest.mark.parametrize("stall", [0.03])
def test_a_real_time_run_at_speed_over_currents_after_a_stall_and_says_so(tmp_path: Path, stall: float) -> None:
    """A real process, paced by the wall clock: the rotating test turns the motor at speed, one controller tick
    sleeps 30 ms (below the mock rig's max_stall of 50 ms, so no stall trip): the stale voltage over-currents
    the motor, and the summary names the stall."""
    script = textwrap.dedent(f"""
        import sys, time
        from pathlib import Path
        from bench.session import RunOptions, run
        from bench.commission.rotating import RotatingIdController as C
        orig, done = C.step, []
        def step(self, meas, w, i):
            if meas.t >= 1.5 and not done:
                done.append(meas.t)
                time.sleep({stall})
            return orig(self, meas, w, i)
        C.step = step
        summary, code = run(RunOptions(log=Path("run.mcap"), duration=2.5, realtime=True, progress=False,
                                       controller="rotating_id", scenario="demo"))
        sys.exit(code)
    """)
    for attempt in (1, 2):  # an OS stall that tripped the run before ours (a loaded machine): once more
        p = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                           env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})  # fmt: skip
        assert p.returncode == 1, p.stderr
        summary = json.loads((tmp_path / "run.summary.json").read_text())
        cause = summary["trip_cause"]
        if summary["trip_time"] >= 1.5 or "loop stall" not in cause or attempt == 2:
            break
    assert "loop stall (the drive held the last command)" in cause and 1.5 <= summary["trip_time"] < 1.5 + STALL_BLAME
    length = float(cause.split(" ms loop stall")[0].rsplit(" ", 1)[1])
    assert stall * 1e3 - 1 <= length < stall * 1e3 + 20, cause  # the stall that was made (plus the OS's own)
