"""How a bench session ends: exit codes, signals, and the order of the shutdown steps.

Every way a run can end goes through the same path (`bench.session.run`):

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
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
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


class SignalGuard:
    """Catch the `SIGNALS` for the duration of a session (main thread only; a no-op elsewhere).

    Modes: ``start-up`` (first signal raises `Interrupted`), ``running`` (a signal calls the
    ``on_signal`` callback given to `running`, which requests a trip at the next tick), ``shutdown``
    (signals are only counted and reported on stderr). ``first`` is the first signal received.
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
            for s in self.signals:
                self._saved[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for s, old in self._saved.items():
            signal.signal(s, old)
        self._saved.clear()

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
