"""Why the log writer fell behind: CPU starvation, a slow disk, a stopped process, or too much to log.

The writer process keeps two samples of its own accounting in the shared index array
(`bench.daq.writer_process`): ``(monotonic ns, CPU ns, run-queue wait ns, ns in file writes)`` about
`WINDOW_S` ago and at its latest pass, plus the start of a file write in progress. When the ring is full,
the loop process reads the writer's scheduler statistics now (``/proc/<pid>/schedstat``: time on a CPU and
time runnable but waiting for one) and its state, and `stall_cause` names the cause with advice that
fits it, in one line. Reading /proc costs the loop some tens of µs, once, at the trip.
"""

from __future__ import annotations

import os
import time
from typing import Any

WINDOW_S = 5.0  # [s] the writer's reference sample is about this old
SAMPLE_S = 0.25  # [s] the writer samples itself at most this often
# shared index slots (bench.daq.writer_process.IDX_SLOTS covers them): reference and newest sample
REF, NEW, IO_SINCE = 21, 25, 29
SLOTS_END = 30


def schedstat(path: str) -> tuple[int, int] | None:
    """(ns on a CPU, ns runnable but waiting for a CPU) of one task, from its ``schedstat`` file; None if unreadable."""
    try:
        with open(path, "rb") as f:
            run, wait = f.read().split()[:2]
        return int(run), int(wait)
    except (OSError, ValueError):
        return None


def proc_state(pid: int) -> str:
    """The task's state letter from /proc (R running, S sleeping, D disk wait, T stopped, ...); "" if unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0].decode()
    except (OSError, IndexError, ValueError):
        return ""


class SelfSampler:
    """The writer's side: sample its own accounting into ``idx`` (at most every `SAMPLE_S`)."""

    def __init__(self, idx: Any) -> None:
        self.idx = idx
        self.io_ns = 0  # time in file writes so far
        self._hist: list[tuple[int, int, int, int]] = []
        self._next = 0
        self._path = "/proc/thread-self/schedstat"
        self.sample(force=True)

    def _now(self) -> tuple[int, int, int, int]:
        st = schedstat(self._path)
        run, wait = st if st is not None else (time.thread_time_ns(), -1)
        return time.monotonic_ns(), run, wait, self.io_ns

    def sample(self, force: bool = False) -> None:
        now = time.monotonic_ns()
        if not force and now < self._next:
            return
        self._next = now + int(SAMPLE_S * 1e9)
        s = self._now()
        hist = self._hist
        hist.append(s)
        cut = s[0] - int(WINDOW_S * 1e9)
        while len(hist) > 1 and hist[1][0] <= cut:  # keep the newest sample at least WINDOW_S old as the reference
            hist.pop(0)
        idx = self.idx
        idx[REF : REF + 4] = list(hist[0])
        idx[NEW : NEW + 4] = list(s)

    def writing(self, start: bool) -> None:
        """Mark the start (True) or end (False) of a file write."""
        self.idx[IO_SINCE] = time.monotonic_ns() if start else 0


def stall_cause(idx: Any, pid: int) -> str:
    """What kept the writer from keeping up, and what to do, from its samples and its state now (module docstring)."""
    now = time.monotonic_ns()
    t0, cpu0, wait0, io0 = (int(x) for x in idx[REF : REF + 4])
    t1, _, _, io1 = (int(x) for x in idx[NEW : NEW + 4])
    if t1 < now - int(WINDOW_S * 1e9):  # the writer has not passed its loop for a while: since it last did
        t0, cpu0, wait0, io0 = (int(x) for x in idx[NEW : NEW + 4])
    since = int(idx[IO_SINCE])
    win = max(now - t0, 1) / 1e9
    io = (io1 - io0 + (now - since if since else 0)) / 1e9
    st = schedstat(f"/proc/{pid}/schedstat")
    cpu = (st[0] - cpu0) / 1e9 if st else None
    wait = (st[1] - wait0) / 1e9 if st and wait0 >= 0 else None
    state = proc_state(pid)
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    ncpu = os.cpu_count() or 1
    got = f"the writer got {cpu:.2f} s of CPU in {win:.1f} s" if cpu is not None else f"in the last {win:.1f} s"
    machine = f"load average {load:.1f} on {ncpu} CPUs"
    if state in ("T", "t"):
        return (f"the writer process is stopped (SIGSTOP, a debugger; {got}): "
                f"let it run (kill -CONT {pid}) or do not stop it during a run")  # fmt: skip
    if state == "D" or io >= 0.5 * win:
        return (f"the writer spent {io:.1f} s of {win:.1f} s writing to the disk ({got}): the disk is too slow; "
                "log to a faster disk, or a larger --log-buffer rides out short hiccups")  # fmt: skip
    # rows waited all along, so a writer that neither wrote nor was stopped, yet got little CPU, was waiting for
    # one (the kernel counts a wait for a CPU only once the task gets one: a writer starved now shows none yet)
    starved = (wait is not None and wait >= 0.25 * win) or (
        cpu is not None and cpu < 0.5 * win and (state == "R" or load > ncpu))
    if starved:
        waited = f", waited {wait:.1f} s for one" if wait is not None and wait >= 0.05 else ""
        return (f"CPU-starved: {got}{waited} ({machine}{', runnable now' if state == 'R' else ''}): "
                "the machine is overloaded; close other programs, or log less (no --live, fewer channels)")  # fmt: skip
    if cpu is not None and cpu >= 0.7 * win:
        return (f"{got} and still fell behind ({machine}): logging needs more CPU than it gets; "
                "log fewer channels or a lower --live-rate")  # fmt: skip
    return f"{got}, {io:.1f} s of it writing, state {state or '?'} ({machine})"
