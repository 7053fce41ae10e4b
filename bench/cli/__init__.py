"""The `bench` command (click).

Bad input of any kind ends in one line on stderr, ``bench: error: <field>: <what is allowed>``,
and exit code 2 - never a traceback. A run that tripped exits 1; Ctrl-C exits 130 after the rig
is safe and the log is closed.

The commands live by role: `bench.cli.rig` (at the rig: run, the live session's requests, plot, inspect,
emulate, calibrate), `bench.cli.workflows` (reproduce, sweep, tune, identify, commission, synth, collect, train,
pipeline) and `bench.cli.perf` (the benchmarks), on the group of `bench.cli.common` with its shared option types.
This module registers them and is the entry point (`main`).

Each command imports what it runs inside its function: the group itself loads click and a few light modules
(`bench --help` imports in about 45 ms), not cvxpy, torch, numba or the device libraries.
"""

from __future__ import annotations

import sys

import click

from bench.cli.common import EXIT_BAD_INPUT, _report_end, cli  # noqa: F401 (_report_end: the API's name for it)
from bench.cli import perf, rig, workflows  # noqa: F401 (registering their commands on the group)
from bench.cli.rig import run  # noqa: F401 (the API's name for `bench run`)
from bench.errors import BadInput, DesignFailed
from bench.core.shutdown import (COMMAND_SIGNALS, EXIT_INTERNAL, Interrupted, SignalGuard, after_commit,
                                 signal_exit_code, work_begun)  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    """Entry point: exit codes 0 ok, 1 tripped/failed, 2 bad input, 3 internal error, 4 no answer from a live
    session (bench set/switch/stop/estop/mark: not known whether it was applied), 128 + signal.

    SIGINT/SIGTERM/SIGHUP raise `bench.core.shutdown.Interrupted` (not KeyboardInterrupt, which click
    and some libraries turn into something else); a session replaces this with its own handling.
    A command past a commit point (`bench.core.shutdown.commit_section`: the rig file replaced) is not
    interrupted any more: it finishes, and a last line says the signal came after the commit.
    Called as the program (``argv`` None: the console script, ``python -m bench``) the signals are
    ignored from the moment the outcome is decided to the process's end (`SignalGuard.hold`): the
    exit code is the outcome, never a death by SIGTERM while the interpreter winds down.
    """
    code = 0
    try:
        with SignalGuard(COMMAND_SIGNALS) as guard:
            try:
                ret = cli.main(args=argv, prog_name="bench", standalone_mode=False)
                code = ret if isinstance(ret, int) else 0
            finally:
                if argv is None:
                    guard.hold()
    except BadInput as exc:
        click.echo(f"bench: error: {exc}", err=True)
        code = EXIT_BAD_INPUT
    except DesignFailed as exc:
        click.echo(f"bench: design failed: {exc}", err=True)
        code = 1
    except Interrupted as exc:  # outside a session (a session ends through its own shutdown path)
        click.echo(f"bench: {exc}" + ("" if work_begun() else " while starting: nothing ran"), err=True)
        code = signal_exit_code(exc.signum)
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("bench: interrupted", err=True)
        code = 130
    except click.ClickException as exc:
        click.echo(f"bench: error: {exc.format_message()}", err=True)
        code = EXIT_BAD_INPUT
    except Exception as exc:  # a bug: one line, the traceback only on request
        import os
        import traceback

        if os.environ.get("BENCH_TRACEBACK"):
            traceback.print_exc()
        first = (str(exc).splitlines() or [""])[0]
        click.echo(f"bench: internal error: {type(exc).__name__}: {first} (BENCH_TRACEBACK=1 shows where)", err=True)
        code = EXIT_INTERNAL
    committed, late = after_commit()
    if committed is not None and (late or code >= 2):
        import signal

        try:
            if late:
                names = ", ".join(dict.fromkeys(signal.Signals(s).name for s in late))
                click.echo(f"bench: {names} arrived after {committed} was replaced (the commit point): not "
                           f"interrupted, the command finished; exit {code} is its outcome", err=True)  # fmt: skip
            if code >= 2:
                click.echo(f"bench: note: {committed} had been replaced before this (its backup is beside it)",
                           err=True)  # fmt: skip
        except OSError:  # stderr gone (terminal closed)
            pass
    sys.exit(code)


if __name__ == "__main__":
    main()
