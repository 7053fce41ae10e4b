"""What this machine's kernel offers a real-time loop, for the run summary, and taking it (`realtime_setup`: a CPU
and SCHED_FIFO priority, for the loop and for `bench emulate`'s device thread; docs/realtime-pc.md).

Read-only and cheap (a few small files under /proc and /sys): the preemption model (PREEMPT_RT, in mainline
Linux since 6.12, or a dynamic/voluntary/none kernel), the CPUs isolated from the scheduler (``isolcpus=``),
the kernel's real-time throttling, and the process's limits for SCHED_FIFO priority and locked memory (what a
user without root may get through /etc/security/limits.conf).
"""

from __future__ import annotations

import os
import platform
import resource
from pathlib import Path
from typing import Any


def _read(path: str) -> str | None:
    try:
        return Path(path).read_text().strip()
    except OSError:
        return None


def preemption_model() -> str:
    """``PREEMPT_RT``, ``PREEMPT_DYNAMIC (full)`` (the mode where the kernel says), ``PREEMPT``, ``VOLUNTARY`` or
    ``none``, from /sys/kernel/realtime, the debugfs preempt mode and the kernel's version string."""
    if _read("/sys/kernel/realtime") == "1":
        return "PREEMPT_RT"
    version = platform.version()
    if "PREEMPT_RT" in version:
        return "PREEMPT_RT"
    if "PREEMPT_DYNAMIC" in version:
        mode = _read("/sys/kernel/debug/sched/preempt")  # e.g. "none voluntary (full) lazy" (root, debugfs)
        chosen = mode[mode.index("(") + 1:mode.index(")")] if mode and "(" in mode else None
        return f"PREEMPT_DYNAMIC ({chosen})" if chosen else "PREEMPT_DYNAMIC"
    if "PREEMPT" in version:
        return "PREEMPT"
    return "VOLUNTARY" if "VOLUNTARY" in version else "none"


def isolated_cpus() -> list[int]:
    """The CPUs the kernel keeps for pinned work (``isolcpus=``/cpusets), from a cpulist such as ``2-3,5``."""
    text = _read("/sys/devices/system/cpu/isolated") or ""
    out: list[int] = []
    for part in filter(None, text.split(",")):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def _limit(which: int) -> Any:
    soft, _ = resource.getrlimit(which)
    return "unlimited" if soft == resource.RLIM_INFINITY else soft


def report() -> dict[str, Any]:
    """The kernel's real-time facts for the run summary (``realtime_setup.host``)."""
    runtime = _read("/proc/sys/kernel/sched_rt_runtime_us")
    return {
        "kernel": platform.release(),
        "preemption": preemption_model(),
        "isolated_cpus": _read("/sys/devices/system/cpu/isolated") or "",
        "cpus": os.cpu_count(),
        "rt_throttling": "off" if runtime == "-1" else f"{int(runtime) / 1e4:g} % of each second" if runtime else None,
        "rlimit_rtprio": _limit(resource.RLIMIT_RTPRIO),
        "rlimit_memlock": _limit(resource.RLIMIT_MEMLOCK),
        "root": os.geteuid() == 0,
    }


RT_PRIORITY = 50  # SCHED_FIFO priority of the real-time loop (1..99)


def realtime_setup(cpu_index: int = -1, priority: int | None = None) -> dict[str, Any]:
    """Best effort: pin this thread to one CPU and give it SCHED_FIFO priority.

    A 3 kHz loop in CPython on a 2-core VM is late mostly because other processes (the log writer,
    the progress bar, anything else) get its CPU. As root (or with CAP_SYS_NICE, or an rtprio limit in
    /etc/security/limits.conf) the loop takes a real-time priority; the kernel's RT throttling
    (sched_rt_runtime_us) still leaves 5 % to others. ``cpu_index`` picks from the CPUs the kernel
    isolated (``isolcpus=``) if there are any, else from the allowed ones (the loop takes the last, an
    emulator the first). Returns what was applied and what the kernel offers (`report`),
    for the run summary; never fails (docs/realtime-pc.md).
    """
    applied: dict[str, Any] = {"affinity": None, "sched_fifo": False}
    try:
        allowed = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        allowed = []
    for cpus in (isolated_cpus(), allowed if len(allowed) > 1 else []):
        if not cpus:  # an isolated CPU first (one is enough), else one of two or more allowed ones
            continue
        try:
            os.sched_setaffinity(0, {cpus[cpu_index]})
            applied["affinity"] = cpus[cpu_index]
            break
        except (OSError, IndexError):  # not ours to take (a cpuset): the next choice
            continue
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY if priority is None else priority))
        applied["sched_fifo"] = True
    except (AttributeError, OSError, PermissionError):
        pass
    try:
        applied["host"] = report()
    except (OSError, ValueError):  # a report, never a failure
        pass
    return applied


def realtime_teardown(saved: tuple[set[int], int, Any] | None) -> None:
    """Give back the CPU affinity and scheduling policy `save_sched` saved (best effort)."""
    if saved is None:
        return
    affinity, policy, param = saved
    try:
        os.sched_setscheduler(0, policy, param)
        os.sched_setaffinity(0, affinity)
    except (AttributeError, OSError):
        pass


def save_sched() -> tuple[set[int], int, Any] | None:
    """This thread's CPU affinity and scheduling policy, for `realtime_teardown` (None where the OS has none)."""
    try:
        return os.sched_getaffinity(0), os.sched_getscheduler(0), os.sched_getparam(0)
    except (AttributeError, OSError):
        return None
