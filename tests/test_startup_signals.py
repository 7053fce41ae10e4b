"""A signal at any moment of a run's start-up: the exit code says which signal, and once the options are read a
summary says that nothing ran and what start-up was doing (or, from the first tick on, the run's own summary)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_sigterm_at_moments_of_start_up(tmp_path: Path) -> None:
    """SIGTERM at 12 moments from 0.1 s to 4 s after the start of `bench run --rig emulated` (in-process emulators:
    a start-up of a few seconds). Before the run has its options: one line, no files (in the first ~30 ms the
    Python interpreter itself has not started the program: the default action, no line). After: the summary, in
    the run's folder, either says "nothing ran" with the stage, or is a run that ticked and was interrupted."""
    seen = {"no files": 0, "nothing ran": 0, "ran": 0}
    for i, delay in enumerate([0.1 + 0.35 * n for n in range(12)]):
        out = tmp_path / f"m{i}"
        p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--rig", "emulated", "--duration", "3",
                              "--out", str(out), "--no-progress"], cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)  # fmt: skip
        time.sleep(delay)
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=120)
        summaries = list(out.glob("*/summary.json"))
        if p.returncode == 0:  # the run was over before the signal
            continue
        if p.returncode == -signal.SIGTERM:  # the interpreter had not reached the program's first line yet
            assert err == "" and not summaries, (delay, err)
            continue
        assert p.returncode == 143, (delay, err)
        if not summaries:  # while importing, or in the command before the run's options are read
            assert err.strip().splitlines()[-1] == "bench: interrupted (SIGTERM) while starting: nothing ran", \
                (delay, err)  # fmt: skip
            seen["no files"] += 1
            continue
        s = json.loads(summaries[0].read_text())
        assert s["exit_code"] == 143
        if s["ticks"] == 0:
            assert s["trip_cause"].startswith("interrupted (SIGTERM) during start-up (") and \
                s["trip_cause"].endswith("): nothing ran"), s["trip_cause"]  # fmt: skip
            seen["nothing ran"] += 1
        else:
            assert s["trip_cause"] == "interrupted (SIGTERM)", s["trip_cause"]
            seen["ran"] += 1
    assert seen["nothing ran"] >= 1, seen  # the moments reached the start-up after the options
