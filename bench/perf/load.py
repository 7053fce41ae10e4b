"""Real-time runs beside CPU-bound processes: how often does the machine's load end a run?

``bench perf load``: N real-time `bench run` processes of a scenario (default: the rated point, ``hold``, 10 s) one
after another, each with ``hogs`` CPU-bound processes (plain Python busy loops at the user's normal priority, as a
compile or a test suite would be) running beside it for its whole life. Per run: exit code, trip cause, deadline
misses, the loop stalls the drive rode through (count, longest) and the run's scheduling; in all: trips, the stall
lengths' distribution. The yardstick (one plain-Python RK4 motor step) is measured in the same run, before the hogs.

``emulator="process"`` (a driver rig): each run gets a `bench emulate` of its own, started before it in a process of
its own, as the devices of a real rig are, instead of the emulators `bench run` starts in its process (one GIL with
the loop: an emulator thread preempted by another process while it holds the GIL stalls the loop behind it).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.errors import BadInput
from bench.perf.live import yardstick_us
from bench.core.config import load

ROOT = Path(__file__).resolve().parents[2]


def _hog(stop: Any) -> None:  # a CPU-bound process: a busy loop until told to stop
    x = 0
    while not stop.value:
        for _ in range(100_000):
            x += 1


def _start_emulator(rig: str, seed: int) -> subprocess.Popen:
    """`bench emulate` for one run; returns once it serves (its first line on stdout)."""
    p = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", rig, "--seed", str(seed)],
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)  # fmt: skip
    if not (p.stdout and p.stdout.readline().startswith('{"emulating"')):
        p.kill()
        raise RuntimeError(f"bench emulate --rig {rig} did not start (exit {p.wait()})")
    return p


def _stop_emulator(p: subprocess.Popen) -> None:
    p.send_signal(signal.SIGINT)
    try:
        p.wait(10)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


def run(runs: int = 20, hogs: int = 2, rig: str = "mock", scenario: str = "hold", duration: float = 10.0,
        emulator: str = "in-process") -> dict[str, Any]:  # fmt: skip
    """The runs, with the hogs beside each; progress on stderr."""
    if emulator == "process" and load(rig).driver != "drivers":
        raise BadInput("--emulator", f"'process' needs a driver rig (e.g. --rig emulated); {rig!r} has none")

    ys = yardstick_us()
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    ctx = mp.get_context("spawn")
    for i in range(runs):
        stop = ctx.RawValue("b", 0)
        procs = [ctx.Process(target=_hog, args=(stop,), daemon=True) for _ in range(hogs)]
        for p in procs:
            p.start()
        emu = _start_emulator(rig, i) if emulator == "process" else None
        with tempfile.TemporaryDirectory() as tmp:
            p = subprocess.run([sys.executable, "-m", "bench", "run", "--realtime", "--rig", rig, "--scenario", scenario,
                                "--duration", str(duration), "--seed", str(i), "--out", tmp, "--no-progress"],
                               capture_output=True, text=True, cwd=ROOT, timeout=600)  # fmt: skip
            if emu is not None:
                _stop_emulator(emu)
            stop.value = 1
            for q in procs:
                q.join(5)
            summary = json.loads(next(Path(tmp).glob("*/summary.json")).read_text())
        st = summary.get("stalls") or {}
        rows.append({"run": i, "exit_code": p.returncode, "trip_cause": summary.get("trip_cause"),
                     "deadline_misses": summary.get("deadline_misses"), "skipped_ticks": summary.get("skipped_ticks"),
                     "ticks": summary.get("ticks"), "stalls": st.get("count"), "longest_stall_ms": st.get("longest_ms"),
                     "sched_fifo": (summary.get("realtime_setup") or {}).get("sched_fifo"),
                     "engines": summary.get("engines")})  # fmt: skip
        done = i + 1
        eta = (time.perf_counter() - t0) / done * (runs - done)
        print(f"\rload runs {done}/{runs} (trips so far {sum(r['exit_code'] != 0 for r in rows)}), ETA {eta:4.0f} s",
              end="", file=sys.stderr, flush=True)  # fmt: skip
    print(file=sys.stderr)
    longest = sorted(r["longest_stall_ms"] or 0.0 for r in rows)
    return {"benchmark": "load", "rig": rig, "emulator": emulator if rig != "mock" else None, "scenario": scenario, "duration_s": duration, "hogs": hogs,
            "runs": runs, "trips": sum(r["exit_code"] != 0 for r in rows),
            "stalls_total": sum(r["stalls"] or 0 for r in rows),
            "longest_stall_ms": {"median": longest[len(longest) // 2] if longest else None,
                                 "max": longest[-1] if longest else None},
            "yardstick_us": ys, "rows": rows, "wall_s": round(time.perf_counter() - t0, 1)}  # fmt: skip
