"""Memory for a real-time loop: no page fault and no return of memory to the OS mid-run (best effort).

A page fault in the loop process is a stall: a minor one (a page never touched, or reclaimed) costs a
few µs, a major one (a page read back from disk: a mapped file, swap) milliseconds. The usual recipe of
real-time Linux programs:

* ``mlockall(MCL_CURRENT | MCL_FUTURE)``: every page mapped now is faulted in and locked, and so is every
  later mapping as it is made (numpy arrays, new interpreter arenas) -- no fault later, no swapping, no
  reclaim of the code and data of the interpreter and its libraries (under memory pressure a reclaimed
  page of a library is read back from disk: a major fault, milliseconds). Applied as root (CAP_IPC_LOCK)
  or with ``ulimit -l unlimited`` only: under a finite limit every allocation beyond it would fail for the
  rest of the run. Otherwise nothing is locked and the reason is reported.
* glibc malloc kept from giving memory back (``M_TRIM_THRESHOLD``) and from serving large blocks by
  their own ``mmap`` (``M_MMAP_MAX`` 0): a freed block is reused instead of unmapped and faulted in again.

`lock_memory` applies both and says what it applied (for the run summary's ``realtime_setup``);
`unlock_memory` undoes them after the run. The log ring needs nothing more: multiprocessing zero-fills it
in the loop process when it is made, so its pages are present before the first tick.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import resource
from typing import Any

MCL_CURRENT, MCL_FUTURE = 1, 2
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4  # glibc mallopt parameters
_MMAP_MAX_DEFAULT = 65536  # glibc's default
_TRIM_DEFAULT = 128 * 1024

__all__ = ["lock_memory", "unlock_memory", "faults"]


def _libc() -> Any:
    name = ctypes.util.find_library("c")
    return ctypes.CDLL(name, use_errno=True) if name else None


def _vm_kb(field: str) -> int | None:
    """A ``Vm...`` line of /proc/self/status [kB]."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def faults() -> tuple[int, int]:
    """(minor, major) page faults of this process so far."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_minflt, ru.ru_majflt


def lock_memory(malloc: bool = True) -> dict[str, Any]:
    """Best effort: lock all current and future memory of this process, keep malloc from returning memory.

    Returns ``{"mlockall": bool, "locked_mb": float | None, "malloc_kept": bool, "why": str}`` (``why``
    says what failed, empty if nothing did). Never raises.
    """
    out: dict[str, Any] = {"mlockall": False, "locked_mb": None, "malloc_kept": False, "why": ""}
    libc = _libc()
    if libc is None:
        out["why"] = "no C library found"
        return out
    limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    try:
        if os.geteuid() != 0 and limit != resource.RLIM_INFINITY:
            # MCL_FUTURE under a finite limit: an allocation beyond it would fail mid-run (MemoryError)
            out["why"] = (f"mlockall skipped: ulimit -l is {limit // 1024} kB and the process could not allocate "
                          "beyond it once locked (run as root, or with ulimit -l unlimited)")  # fmt: skip
        elif libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
            out["mlockall"] = True
        else:
            err = ctypes.get_errno()
            lim = "unlimited" if limit == resource.RLIM_INFINITY else f"{limit // 1024} kB"
            out["why"] = (f"mlockall: {os.strerror(err)} (needs CAP_IPC_LOCK or ulimit -l above the process's "
                          f"{(_vm_kb('VmRSS') or 0) // 1024} MB; ulimit -l is {lim})")  # fmt: skip
    except (AttributeError, OSError) as exc:
        out["why"] = f"mlockall: {exc}"
    if malloc:
        try:
            mallopt = libc.mallopt
            out["malloc_kept"] = bool(mallopt(M_TRIM_THRESHOLD, 0x7FFFFFFF)) and bool(mallopt(M_MMAP_MAX, 0))
        except (AttributeError, OSError):  # not glibc
            pass
    locked = _vm_kb("VmLck")
    out["locked_mb"] = round(locked / 1024, 1) if locked is not None else None
    return out


def unlock_memory(applied: dict[str, Any]) -> None:
    """Undo what `lock_memory` applied (after the run)."""
    libc = _libc()
    if libc is None:
        return
    try:
        if applied.get("mlockall"):
            libc.munlockall()
        if applied.get("malloc_kept"):
            libc.mallopt(M_MMAP_MAX, _MMAP_MAX_DEFAULT)
            libc.mallopt(M_TRIM_THRESHOLD, _TRIM_DEFAULT)
    except (AttributeError, OSError):
        pass
