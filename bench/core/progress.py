"""Progress of long jobs, always on stderr (stdout carries the data), with the time so far and an ETA.

* `stages(what)`: one line per stage, ``[  12.3 s] train narx: 2/4 LM training ...``;
* `Steps`: counted work (LM evaluations, cases, ...) as a bar with an ETA, drawn only on a terminal;
  elsewhere (a log file, CI) it prints a line every tenth of the way;
* a stage line or a bar means the command's work is under way (`bench.core.shutdown.begin_work`);
* `summarised_warnings`: library warnings become one line each at the end, counted, without the
  library's file paths; the solver's "Solution may be inaccurate" notes become one line saying whether
  the result is affected (it is re-checked independently).

The real-time loop's bar (a separate process, so the loop only stores a float) is in
`bench.runtime.session`.
"""

from __future__ import annotations

import contextlib
import sys
import time
import warnings
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

from bench.core.shutdown import begin_work

Say = Callable[[str], None]


def stages(what: str) -> Say:
    """A stage printer: ``say("collect ...")`` -> ``[   0.0 s] what: collect ...`` on stderr."""
    t0 = time.perf_counter()

    def say(stage: str) -> None:
        begin_work()  # (a signal from now on is no longer one "while starting")
        try:
            print(f"[{time.perf_counter() - t0:6.1f} s] {what}: {stage}", file=sys.stderr, flush=True)
        except OSError:  # stderr gone (terminal closed): the job goes on
            pass

    return say


class Steps:
    """``with Steps(total, "LM evaluations") as step: ... step(k)`` - a bar with ETA on stderr."""

    def __init__(self, total: int, label: str, *, tty: bool | None = None) -> None:
        self.total, self.label = max(1, int(total)), label
        self.tty = sys.stderr.isatty() if tty is None else tty
        self._bar: Any = None
        self._next_line = 0.1
        self._t0 = time.perf_counter()

    def __enter__(self) -> Callable[[int], None]:
        begin_work()
        if self.tty:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
            from rich.progress import TimeRemainingColumn

            self._bar = Progress(TextColumn(f"[bold]{self.label}"), BarColumn(), MofNCompleteColumn(),
                                 TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                                 console=Console(stderr=True), transient=True)  # fmt: skip
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=self.total)
        return self.update

    def update(self, done: int) -> None:
        done = min(int(done), self.total)
        if self._bar is not None:
            self._bar.update(self._task, completed=done)
            return
        frac = done / self.total
        if frac >= self._next_line:
            el = time.perf_counter() - self._t0
            eta = el * (1 - frac) / frac if frac > 0 else float("nan")
            try:
                print(f"  {self.label}: {done}/{self.total} ({frac:.0%}), {el:.0f} s, ETA {eta:.0f} s",
                      file=sys.stderr, flush=True)  # fmt: skip
            except OSError:
                pass
            self._next_line = (int(frac * 10) + 1) / 10

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.stop()


def _solver_note(msg: str) -> bool:
    """cvxpy's "Solution may be inaccurate", synthesis.lmi's "optimal_inaccurate": the solver's own doubt."""
    return "inaccurate" in msg


#: what a verified design passed (`summarised_warnings`' ``checked`` for the syntheses: `bench.workflows.synth`)
VERIFIED = "the independent verification (stability, H-inf norm, analysis LMI, time-varying gain)"


@contextlib.contextmanager
def summarised_warnings(what: str, *, checked: str | None = None) -> Iterator[None]:
    """Collect the warnings raised inside and print them on stderr at the end, one line each.

    The solver's notes that a solution may be inaccurate become ONE line that says whether the result
    is affected: ``checked`` names the independent check the block makes of its result (raising if it
    fails), e.g. "the independent verification"; the block's normal end means the result passed it.
    Other warnings: each distinct one once, with its count.
    """
    ok = False
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield
            ok = True
        finally:
            counts = Counter(f"{w.category.__name__}: {str(w.message).splitlines()[0]}" for w in caught)
            lines = [msg + (f" ({n} times)" if n > 1 else "") for msg, n in counts.items() if not _solver_note(msg)]
            if any(_solver_note(msg) for msg in counts):
                doubt = "the solver called some of its solutions inaccurate"
                if checked is None:
                    lines.insert(0, f"{doubt} (this command does not re-check them)")
                elif ok:
                    lines.insert(0, f"{doubt}; the result is not affected: it passed {checked}")
                else:
                    lines.insert(0, f"{doubt}; no result was kept (the error below says why)")
            for line in lines:
                try:
                    print(f"bench: note ({what}): {line}", file=sys.stderr)
                except OSError:
                    pass
