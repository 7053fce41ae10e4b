"""How a bench session ends: exit codes, signals, and the order of the shutdown steps.

Every way a run can end goes through the same path (`bench.runtime.session.run`):

1. **safe command** - inverter disabled (coast), zero voltage reference, load torque 0; sent in the
   tick the cause was detected (a trip, a signal, an exception in read/control/write/log, a dead or
   stalled log writer), or at once if the loop was not running yet;
2. **log** - the trip and its cause go into the log (``tripped`` per tick, a ``shutdown`` metadata
   record), and the log is closed within a bounded time;
3. **summary** - ``summary.json`` (and the plot) are written, whatever failed before;
4. **exit code** - what happened (`exit_code`).

Signals (SIGINT, SIGTERM, SIGHUP, SIGTSTP, SIGQUIT) are caught by `SignalGuard`. They are the loop
process's alone: a key typed at a terminal (Ctrl-C, Ctrl-Z, Ctrl-\\) signals the whole foreground process
group, and a child that stopped or died with it (the log writer, the progress bar, multiprocessing's
resource tracker) would hang the shutdown or tear the log. So every child is started inside `spawning`,
with those signals (and SIGTTIN/SIGTTOU) blocked from its first instruction, and ignores them
(`child_ignores_signals`) before it unblocks them. Before the loop runs (opening
devices, starting the log writer) the first signal raises `Interrupted`, so start-up unwinds
through the same ``finally`` blocks. While the loop runs, a signal only *requests* a trip; the loop
acts on it at the next tick boundary (the safe command is never torn in half by an exception in the
middle of a device write). During the shutdown itself further signals are counted and reported,
and skip nothing: the safe command and the summary still come.

A command that changes a file the user keeps (the rig file: `bench identify --write`, `bench commission`) has
one commit point, the rename that puts the new file in place (`commit_section`). Every signal the command
receives before it (in a session, in its shutdown, between sessions) ends the command with 128 + the signal and
the file as it was; signals arriving inside the short commit section are deferred until it ends, and from the
commit point on a signal no longer interrupts: the command finishes and exits with its outcome, and `main`
says the signal came after the commit (`after_commit`).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from multiprocessing import context as _mp_context
from multiprocessing import spawn as _mp_spawn
from typing import Any

EXIT_OK = 0  # the run ended normally
EXIT_TRIP = 1  # the supervisor tripped (cause in the summary and on stderr), or the run failed
EXIT_BAD_INPUT = 2  # bad input: one line naming the field and what is allowed; nothing was run
EXIT_INTERNAL = 3  # an internal error outside a run (a bug); the rig, if any, was made safe first
EXIT_NO_ANSWER = 4  # bench set/switch/stop/estop/mark: no answer from the loop in time, not known whether applied

# Ctrl-Z (SIGTSTP) and Ctrl-\\ (SIGQUIT) too: a suspended or core-dumping control process would leave the
# drive holding its last command, so they end the run through the shutdown path like Ctrl-C
_NAMES = (("SIGINT", "Ctrl-C"), ("SIGTERM", "SIGTERM"), ("SIGHUP", "SIGHUP: terminal closed"),
          ("SIGTSTP", "Ctrl-Z: a rig is not suspended, the run ends"), ("SIGQUIT", "SIGQUIT"))  # fmt: skip
SIGNALS = tuple(getattr(signal, n) for n, _ in _NAMES if hasattr(signal, n))
COMMAND_SIGNALS = SIGNALS[:3]  # outside a session (synthesis, plots, ...) Ctrl-Z suspends as usual
_CAUSES = {getattr(signal, n): f"interrupted ({why})" for n, why in _NAMES if hasattr(signal, n)}


def signal_exit_code(signum: int) -> int:
    """The shell convention: 128 + signal number (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP, 148 Ctrl-Z, 131 SIGQUIT)."""
    return 128 + int(signum)


def signal_cause(signum: int) -> str:
    """Trip cause for a signal, as it appears in the summary and the log."""
    return _CAUSES.get(signum, f"interrupted (signal {int(signum)})")


class Interrupted(BaseException):
    """A signal arrived before the loop ran (BaseException: ``except Exception`` must not eat it)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal_cause(signum))


_critical = {"depth": 0, "pending": None}  # a start-up signal that arrived inside a critical section


@contextlib.contextmanager
def critical_section() -> Iterator[None]:
    """Code a start-up signal must not interrupt half-way (handing a child process its start data):
    a signal arriving inside is raised as `Interrupted` when the section ends."""
    _critical["depth"] += 1
    try:
        yield
    finally:
        _critical["depth"] -= 1
        pending = _critical["pending"]
        if _critical["depth"] == 0 and pending is not None:
            _critical["pending"] = None
            raise Interrupted(pending)


# what a child process of a session ignores: the session's signals and the terminal's stop signals
CHILD_SIGNALS = SIGNALS + tuple(getattr(signal, n) for n in ("SIGTTIN", "SIGTTOU") if hasattr(signal, n))


@contextlib.contextmanager
def spawning() -> Iterator[None]:
    """Start child processes inside this: they inherit a signal mask that blocks `CHILD_SIGNALS` (the mask
    survives fork and exec), so a terminal key can neither stop nor kill one while its interpreter starts;
    the child then calls `child_ignores_signals`. multiprocessing's resource tracker is started here too
    (its own start-up unblocks only SIGINT and SIGTERM, which it ignores): it keeps the others blocked for
    good. It is a `critical_section` too: a start-up signal (another thread may take it while this one
    blocks it) is raised only once the child has its start-up data, never half-way through handing it over."""
    with critical_section():
        if not hasattr(signal, "pthread_sigmask"):
            yield
            return
        from multiprocessing import resource_tracker

        old = signal.pthread_sigmask(signal.SIG_BLOCK, CHILD_SIGNALS)
        try:
            resource_tracker.ensure_running()  # unblocks SIGINT and SIGTERM on its way out: blocked again below
            signal.pthread_sigmask(signal.SIG_BLOCK, CHILD_SIGNALS)
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


_no_main = threading.local()  # set while a `ChildProcess` starts in this thread
_stdlib_preparation_data: Callable[[str], dict[str, Any]] | None = None


def _preparation_data(name: str) -> dict[str, Any]:  # over multiprocessing.spawn.get_preparation_data
    assert _stdlib_preparation_data is not None
    data = _stdlib_preparation_data(name)
    if getattr(_no_main, "on", False):  # the child needs no module of the caller's, its main least of all
        data.pop("init_main_from_path", None)
        data.pop("init_main_from_name", None)
    return data


class ChildProcess(_mp_context.SpawnProcess):
    """A spawned process that does not import the parent's main module (see `child_context`)."""

    @staticmethod
    def _Popen(process_obj: Any) -> Any:
        global _stdlib_preparation_data
        if _stdlib_preparation_data is None:  # installed once; the same as the stdlib's unless `_no_main.on`
            _stdlib_preparation_data = _mp_spawn.get_preparation_data
            _mp_spawn.get_preparation_data = _preparation_data
        _no_main.on = True
        try:
            return _mp_context.SpawnProcess._Popen(process_obj)
        finally:
            _no_main.on = False


class ChildContext(_mp_context.SpawnContext):
    """``spawn``, with `ChildProcess`."""

    Process = ChildProcess  # type: ignore[assignment]


_CHILD_CONTEXT = ChildContext()


def child_context() -> ChildContext:
    """The multiprocessing context of a session's children (the log writer, the progress bar): ``spawn``, except
    that a child does not import the caller's main module. multiprocessing's spawn runs a main *script* again in
    every child (as ``__mp_main__``): without an ``if __name__ == "__main__":`` guard the child would start the
    run again. So a run starts the same from a script, a notebook, ``python -c`` and an interactive session. A
    child's target and arguments must come from importable modules (bench's do), never from the main script."""
    return _CHILD_CONTEXT


def child_ignores_signals() -> None:
    """First thing in a child process started inside `spawning`: ignore `CHILD_SIGNALS` (one pending since
    the start is discarded), then unblock them. The loop process handles them: it makes the rig safe, then
    closes the log; a child ends on its own (the log writer on pipe EOF or the close frame)."""
    for s in CHILD_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, CHILD_SIGNALS)


class _CommandSignals:
    """What the whole command (not one session) knows of its signals: reset when the outermost
    `SignalGuard` is entered (`bench.cli.main`'s, or a session's in library use)."""

    def __init__(self) -> None:
        self.first: int | None = None  # the first signal any guard (or commit section) received
        self.committed: str | None = None  # what was committed (a rig file's path) once a commit point passed
        self.after: list[int] = []  # signals received after the commit point (deferred ones included)
        self.begun = False  # a session (a guard inside the command's) or other work begun (`begin_work`)


_command = _CommandSignals()
_guards = {"depth": 0}  # SignalGuards installed (nested: a session inside `main`'s)


def begin_work() -> None:
    """This command's work is under way (a session's guard says so, and so does a long job's first progress line,
    `bench.core.progress`): a signal from now on no longer ends it "while starting: nothing ran"."""
    _command.begun = True


def work_begun() -> bool:
    """Whether this command has begun a session or other work (False: a signal now ends it before anything ran)."""
    return _command.begun


def signalled() -> int | None:
    """The first signal this command received before any commit point (None: none, or the commit passed)."""
    return _command.first if _command.committed is None else None


def raise_if_signalled() -> None:
    """Raise `Interrupted` for a signal a finished session absorbed (one that arrived during its shutdown
    does not change the run's exit code): a command that goes on to write must stop here instead."""
    first = signalled()
    if first is not None:
        raise Interrupted(first)


def after_commit() -> tuple[str | None, list[int]]:
    """(what was committed, the signals received from its commit section on) for `bench.cli.main`'s report."""
    return _command.committed, list(_command.after)


class CommitSection:
    """Handed out by `commit_section`: call `commit` right after the rename that is the commit point."""

    def __init__(self, what: str) -> None:
        self.what = what
        self.deferred: list[int] = []
        self.done = False

    def commit(self) -> None:
        self.done = True


# deferred inside a commit section: the command's signals and Ctrl-Z (a process stopped half-way would hold
# the rig file's lock); Ctrl-\ (SIGQUIT) is a debugging signal and keeps its core dump
COMMIT_SIGNALS = COMMAND_SIGNALS + tuple(getattr(signal, n) for n in ("SIGTSTP",) if hasattr(signal, n))


@contextlib.contextmanager
def commit_section(what: str) -> Iterator[CommitSection]:
    """The few system calls that replace ``what`` (write the temporary file, fsync, backup, rename, fsync the
    folder): `COMMIT_SIGNALS` that arrive inside are deferred, so the section runs whole and the decision is
    atomic. Refused up front (`Interrupted`) if the command was already signalled (`signalled`): a signal a
    session absorbed must not let the write happen. At the end the handlers are restored and the deferred
    signals raised again: after ``commit()`` the command's guard records them as arriving after the commit
    (`SignalGuard`, `after_commit`); without a commit (an error inside) they interrupt as usual."""
    raise_if_signalled()
    sec = CommitSection(what)

    def defer(signum: int, frame: FrameType | None) -> None:
        sec.deferred.append(signum)

    saved: dict[int, Any] = {}
    try:
        if threading.current_thread() is threading.main_thread():
            for s in COMMIT_SIGNALS:
                saved[s] = signal.signal(s, defer)
        yield sec
    finally:
        if sec.done:
            _command.committed = what
        for s, old in saved.items():
            signal.signal(s, old)
        for s in sec.deferred:
            if _command.first is None:
                _command.first = s
            if sec.done and s in COMMAND_SIGNALS and _guards["depth"]:
                _command.after.append(s)  # the guard would record it so: no need to raise it again
            else:
                signal.raise_signal(s)


_passed: dict[str, int] = {}  # pause_for_test: how often each point was passed


def pause_for_test(point: str) -> None:
    """A test-only hook: with ``BENCH_TEST_PAUSE=POINT:SECONDS[:NTH]`` in the environment the process says
    ``bench: test pause: POINT`` on stderr and sleeps there the NTH time (default 1st) it passes the point
    (the tests signal it at that exact moment). Points: ``session-shutdown`` (a session's shutdown, the rig
    already made safe and released), ``calibrate-measuring`` (`bench calibrate` half-way through its samples),
    ``rigfile-locked`` (the rig file is locked and verified, nothing written yet), ``rigfile-commit`` (inside
    the commit section, the new file and the backup written, before the rename), ``rigfile-committed`` (the
    commit section is over)."""
    want = os.environ.get("BENCH_TEST_PAUSE")
    if not want:
        return
    name, seconds, nth = (want.split(":") + ["1", "1"])[:3]
    if name != point:
        return
    _passed[point] = _passed.get(point, 0) + 1
    if _passed[point] == int(nth):
        sys.stderr.write(f"bench: test pause: {point}\n")
        sys.stderr.flush()
        time.sleep(float(seconds))


def _quiet_swallowed_interrupts() -> None:
    """A start-up signal raises `Interrupted` from the handler; when it lands inside a C callback (llvmlite's
    object-cache notify while numba compiles) ctypes swallows it and prints "Exception ignored ..." with a
    traceback. The guard has recorded the signal (`SignalGuard.first`) and acts on it when the run starts, so that
    report is noise: drop it, once per process, and pass every other unraisable exception on."""
    previous = sys.unraisablehook
    if getattr(previous, "_bench_quiet", False):
        return

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, Interrupted):
            return
        previous(unraisable)

    hook._bench_quiet = True  # type: ignore[attr-defined]
    sys.unraisablehook = hook


class SignalGuard:
    """Catch the `SIGNALS` for the duration of a session (main thread only; a no-op elsewhere).

    Modes: ``start-up`` (first signal raises `Interrupted`), ``running`` (a signal calls the
    ``on_signal`` callback given to `running`, which requests a trip at the next tick), ``shutdown``
    (signals are only counted and reported on stderr), ``held`` (`hold`: the program's outcome is decided).
    ``first`` is the first signal received. A command past its commit point (`commit_section`) is not
    interrupted any more: the guard records the signal (`after_commit`).
    """

    def __init__(self, signals: tuple[int, ...] = SIGNALS) -> None:
        self.signals = signals
        self.first: int | None = None
        self.count = 0
        self._mode = "start-up"
        self._on_signal: Callable[[str], None] | None = None
        self._saved: dict[int, Any] = {}

    def __enter__(self) -> "SignalGuard":
        if threading.current_thread() is threading.main_thread():
            if _guards["depth"] == 0:  # the outermost: a new command
                _command.__init__()
                _quiet_swallowed_interrupts()
            else:
                begin_work()
            _guards["depth"] += 1
            for s in self.signals:
                self._saved[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._saved:
            _guards["depth"] -= 1
        for s, old in self._saved.items():
            signal.signal(s, old)
        self._saved.clear()

    def hold(self) -> None:
        """The program's outcome is decided: its signals are ignored from here to the process's end (the
        interpreter resets Python handlers to the default while it winds down, and a SIGTERM then would kill
        it with -15 after the outcome is decided). The handlers are not restored by ``__exit__`` then. A
        signal already caught but not yet handled when the handler goes (CPython's "ignored due to race
        condition" note) is counted as arriving after a commit, if there was one, and not printed."""
        self._mode = "held"  # from here `_handle` only counts (a handler may still run while this switches)
        for s in self._saved:
            signal.signal(s, signal.SIG_IGN)
        if self._saved:
            _guards["depth"] -= 1
        self._saved.clear()
        previous = sys.unraisablehook

        def quiet(unraisable: Any) -> None:
            text = str(unraisable.exc_value)
            if isinstance(unraisable.exc_value, OSError) and text.endswith("ignored due to race condition"):
                if _command.committed is not None:
                    with contextlib.suppress(ValueError, IndexError):
                        _command.after.append(int(text.split()[1]))
                return
            previous(unraisable)

        sys.unraisablehook = quiet

    def running(self, on_signal: Callable[[str], None]) -> None:
        """From now on a signal calls ``on_signal(cause)`` instead of raising."""
        self._on_signal = on_signal
        self._mode = "running"
        if self.first is not None:  # arrived while switching: act on it now
            on_signal(signal_cause(self.first))

    def shutting_down(self) -> None:
        self._mode = "shutdown"

    @property
    def exit_code(self) -> int | None:
        return None if self.first is None else signal_exit_code(self.first)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.count += 1
        if _command.committed is not None and self._mode in ("start-up", "held"):  # past its commit point:
            _command.after.append(signum)  # the command finishes; `bench.cli.main` reports the signal
            return
        if self._mode == "held":  # the outcome is decided
            return
        if _command.first is None:
            _command.first = signum
        if self.first is None:
            self.first = signum
            if self._mode == "start-up":
                self._mode = "shutdown"  # a second signal must not interrupt the unwinding
                if _critical["depth"]:
                    _critical["pending"] = signum  # raised when the critical section ends
                    return
                raise Interrupted(signum)
            if self._mode == "running" and self._on_signal is not None:
                self._on_signal(signal_cause(signum))
                return
        try:
            sys.stderr.write(f"bench: {signal.Signals(signum).name}: shutting down, the rig is safe; "
                             "finishing the log and the summary\n")  # fmt: skip
        except Exception:  # noqa: BLE001 - stderr may be gone (terminal closed); nothing to report to
            pass
