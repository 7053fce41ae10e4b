"""What this machine's kernel offers a real-time loop, for the run summary (docs/realtime-pc.md).

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
