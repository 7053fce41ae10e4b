"""The Python entry point: `bench.run` runs one session and returns its summary, or raises.

`bench.runtime.session.run` is the machinery under ``bench run`` (options as a `RunOptions`, a ``(summary, exit code)``
pair back, messages that name the command's options). This layer is for scripts, notebooks and interactive
sessions: keyword arguments, the summary back, an exception when the run did not do what was asked, and
messages that name the Python parameters (``summary=``, ``force=True``) instead of the command's options
(``--summary``, ``--force``): `CLI_OPTIONS` maps one to the other.
"""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path
from typing import Any

from bench.errors import BadInput
from bench.runtime.session import RunOptions
from bench.runtime.session import run as run_session

__all__ = ["run", "RunFailed", "CLI_OPTIONS"]

# ``bench run``'s options -> the parameter of `run` (a flag as the value that sets it): one table for messages
CLI_OPTIONS: dict[str, str] = {
    "--rig": "rig=", "--controller": "controller=", "--scenario": "scenario=", "--scenario-arg": "scenario_args=",
    "--duration": "duration=", "--realtime": "realtime=True", "--lockstep": "realtime=False",
    "--allow-soft-realtime": "allow_soft_realtime=True", "--seed": "seed=", "-p": "params=", "--param": "params=",
    "--log": "log=", "--summary": "summary=", "--plot": "plot=", "--out": "out_dir=", "--force": "force=True",
    "--log-buffer": "log_buffer=", "--can-log": "can_log=", "--live": "live_port=", "--live-port": "live_port=",
    "--live-host": "live_host=", "--live-rate": "live_rate=", "--replay-params": "replay_params=",
    "--switch": "switches=", "--no-progress": "progress=False", "--inject-fault": "inject_fault=",
}  # fmt: skip
_PATHS = ("log", "summary", "plot", "out_dir", "can_log", "replay_params")  # str accepted, made a Path
_FIELDS = frozenset(f.name for f in dataclasses.fields(RunOptions))
_FLAG = re.compile(r"`[^`]*`|(?<![\w-])(--[a-z][a-z-]*|-p)(?![\w-])")  # a backticked command is left as written


class RunFailed(RuntimeError):
    """A run that did not end normally: it did not start (a device, the log writer, ...), a signal ended it, or
    (with ``check=True``) the supervisor tripped or the run failed while running.

    Attributes
    ----------
    summary : dict
        The run's summary, as written to ``summary.json`` (``trip_cause`` says why; ``log`` and ``summary``
        where the files are, if any were written).
    exit_code : int
        What ``bench run`` would have exited with: 1 tripped or failed, 128 + signal when interrupted.
    cause : str
        The summary's ``trip_cause``.
    started : bool
        Whether the loop ran at all (False: nothing ran, no log to read).
    """

    def __init__(self, summary: dict[str, Any], exit_code: int) -> None:
        self.summary, self.exit_code = summary, exit_code
        self.cause = str(summary.get("trip_cause") or f"exit code {exit_code}")
        self.started = bool(summary.get("ticks"))
        where = f"; summary: {summary['summary']}" if summary.get("summary") else ""
        what = "the run did not start" if not self.started else "the run ended early"
        super().__init__(f"{what}: {_python_text(self.cause)} (exit code {exit_code}{where})")


def _python_text(text: str) -> str:
    """``--force`` -> ``force=True``, ``--summary`` -> ``summary=``, outside backticked commands."""
    return _FLAG.sub(lambda m: CLI_OPTIONS.get(m.group(1), m.group(1)) if m.group(1) else m.group(0), text)


def python_input(exc: BadInput) -> BadInput:
    """The same refusal, naming `run`'s parameters: ``run(summary=...): runs/f57.summary.json exists; pass
    force=True to overwrite it``. Fields that are not options (a rig file's, a controller parameter) stay."""
    param = CLI_OPTIONS.get(exc.field) or (f"{exc.field}=" if exc.field in _FIELDS else None)
    problem = _python_text(exc.problem)
    if param is None:
        return exc if problem == exc.problem else BadInput(exc.field, problem)
    out = BadInput(param.split("=")[0], problem)
    out.args = (f"run({param}{'...' if param.endswith('=') else ''}): {problem}",)
    return out


def run(
    scenario: Any = "demo",
    *,
    controller: str = "foc",
    rig: Any = "mock",
    duration: float | None = None,
    seed: int = 0,
    params: dict[str, Any] | None = None,
    log: str | Path | None = None,
    summary: str | Path | None = None,
    plot: str | Path | None = None,
    out_dir: str | Path = "runs",
    force: bool = False,
    realtime: bool | None = None,
    progress: bool | None = None,
    check: bool = True,
    **options: Any,
) -> dict[str, Any]:
    """Run one bench session; returns its summary (what ``summary.json`` holds).

    Works the same from a script (no ``if __name__ == "__main__":`` guard needed), a notebook and an
    interactive session. The parameters are `bench.runtime.session.RunOptions`'s fields; the common ones are named
    here, the others (``scenario_args``, ``log_buffer``, ``live_port``, ``switches``, ...) go in ``options``.

    Parameters
    ----------
    scenario : str | Scenario
        A scenario name (``bench scenarios``), or a `bench.core.scenarios.Scenario`.
    controller, rig, duration, seed, params
        As for ``bench run`` (``params``: the ``-p NAME=VALUE`` values as a dict).
    log, summary, plot : str | Path | None
        Output files; None: ``run.mcap``, ``summary.json``, ``run.png`` in a new folder under ``out_dir``
        (with ``log`` given, the others sit beside it: ``f57.mcap``, ``f57.summary.json``, ``f57.png``).
    force : bool
        Overwrite existing output files (otherwise an existing one is refused before anything runs).
    realtime : bool | None
        Pace by the wall clock; None: only on a rig with real devices.
    progress : bool | None
        Draw the progress bar on stderr; None: when stderr is a terminal.
    check : bool
        Raise `RunFailed` when the supervisor trips or the run fails while running; False: return the summary
        (``summary["exit_code"]``, ``summary["trip_cause"]``). A run that did not start, or that a signal
        ended, always raises.

    Raises
    ------
    BadInput
        A bad argument (a ValueError naming the parameter, e.g. ``run(summary=...): runs/f57.summary.json
        exists; pass force=True to overwrite it``); nothing was opened or written.
    RunFailed
        The run did not end normally; ``.summary`` holds its summary (written to disk too), ``.exit_code``.
    """
    unknown = sorted(set(options) - _FIELDS)
    if unknown:
        raise TypeError(f"run() got unexpected keyword argument(s) {', '.join(unknown)}; allowed: "
                        f"{', '.join(sorted(_FIELDS))}")  # fmt: skip
    kwargs: dict[str, Any] = dict(options, scenario=scenario, controller=controller, rig=rig, duration=duration,
                                  seed=seed, params=dict(params or {}), log=log, summary=summary, plot=plot,
                                  out_dir=out_dir, force=force, realtime=realtime)  # fmt: skip
    kwargs["progress"] = sys.stderr.isatty() if progress is None else bool(progress)
    for name in _PATHS:
        if isinstance(kwargs.get(name), str):
            kwargs[name] = Path(kwargs[name])
    try:
        result, code = run_session(RunOptions(**kwargs))
    except BadInput as exc:
        raise python_input(exc) from None
    if code != 0 and (check or not result.get("ticks") or code >= 128):
        raise RunFailed(result, code)
    return result
