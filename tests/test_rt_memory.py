"""bench.runtime.rt_memory: best-effort memory locking for the real-time loop (in a subprocess: it changes the
process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SCRIPT = """
import json, resource
from bench.runtime import rt_memory
a = rt_memory.lock_memory()
before = rt_memory.faults()
buf = bytearray(64 << 20)  # a large allocation after MCL_FUTURE: present (and counted) when made
made = rt_memory.faults()
buf[::4096] = b"\\x01" * len(buf[::4096])  # touching it then faults no more
touched = rt_memory.faults()
rt_memory.unlock_memory(a)
print(json.dumps({"applied": a, "fault_on_alloc": made[0] - before[0], "fault_on_touch": touched[0] - made[0],
                  "locked_after": rt_memory._vm_kb("VmLck")}))
"""


def _run() -> dict:
    p = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True)
    return json.loads(p.stdout)


def test_lock_memory_reports_what_it_applied_and_never_raises():
    out = _run()
    a = out["applied"]
    assert set(a) == {"mlockall", "locked_mb", "malloc_kept", "why"}
    if a["mlockall"]:
        assert a["locked_mb"] > 10 and a["why"] == ""  # the interpreter, numpy, ...: all of it
        assert out["fault_on_touch"] < 16  # the 16 384 pages of the new buffer were faulted in when made
        assert out["locked_after"] == 0  # unlock_memory undid it
    else:
        assert a["why"]  # says why (no privilege, a finite ulimit -l)


@pytest.mark.skipif(os.geteuid() != 0, reason="mlockall of the whole process needs root here")
def test_lock_memory_as_root_locks():
    assert _run()["applied"]["mlockall"]


ORDER = """
import json
from bench.runtime import loop, rt_memory
from bench.hal import Rig
from bench.runtime.session import RunOptions, run
seen = []
lock, activate = rt_memory.lock_memory, Rig.activate
rt_memory.lock_memory = lambda: (seen.append("lock memory"), lock())[1]
Rig.activate = lambda self: (seen.append("activate the rig"), activate(self))[1]
tick = loop.TimedLoop.run
loop.TimedLoop.run = lambda self: (seen.append("run the loop"), tick(self))[1]
summary, code = run(RunOptions(duration=0.05, realtime=True, log_enabled=False, progress=False))
print(json.dumps({"seen": seen, "memory": summary["realtime_setup"]["memory"]}))
"""


@pytest.mark.realtime
def test_a_real_time_run_takes_its_memory_and_cpu_before_it_activates_the_rig() -> None:
    """Locking memory (0.1-0.3 s on a busy machine) lies before the drive's first set-point, not between it and
    the first tick, where the emulated drive's 0.1 s control-word watchdog counts (in a subprocess: it locks)."""
    p = subprocess.run([sys.executable, "-c", ORDER], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["seen"] == ["lock memory", "activate the rig", "run the loop"], out
    assert "mlockall" in out["memory"], out
