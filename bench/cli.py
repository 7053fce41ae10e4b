"""The `bench` command (click).

Bad input of any kind ends in one line on stderr, ``bench: error: <field>: <what is allowed>``,
and exit code 2 - never a traceback. A run that tripped exits 1; Ctrl-C exits 130 after the rig
is safe and the log is closed.

Each command imports what it runs inside its function: the group itself loads click and a few light modules
(`bench --help` imports in about 45 ms), not cvxpy, torch, numba or the device libraries.
"""

from __future__ import annotations

import json
import math
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from bench.errors import BadInput, DesignFailed, clip, clip_repr
from bench.progress import VERIFIED, stages, summarised_warnings
from bench.outputs import check_name, written_note, check_output, free_path
from bench.live_client import APPLIED, EXIT_CODES, REFUSED, request, call
from bench.scenarios import SCENARIOS, arguments
from bench import reproduce
from synthesis.environment import environment
from bench.shutdown import (
    Interrupted, COMMAND_SIGNALS, EXIT_INTERNAL, SignalGuard, after_commit, signal_exit_code, work_begun,
)

EXIT_BAD_INPUT = 2


class FiniteRange(click.FloatRange):
    """click.FloatRange that also refuses nan and inf (they pass every comparison click makes).

    Without bounds its help says FLOAT (click's would be ``FLOAT RANGE [x<=None]``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.min is None and self.max is None:
            self.name = "float"

    def _describe_range(self) -> str:
        return "" if self.min is None and self.max is None else super()._describe_range()

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        import math

        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


FINITE = FiniteRange()  # any finite float


class OutFile(click.Path):
    """An output file path (``click.Path(dir_okay=False)``) that names a file the file system can make:
    not empty (click turns '' into '.'), no name over NAME_MAX (bench.outputs.check_name)."""

    def __init__(self) -> None:
        super().__init__(dir_okay=False, path_type=Path)

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        if isinstance(value, str) and not value.strip():
            self.fail("needs a file name, got ''", param, ctx)
        path = super().convert(value, param, ctx)
        check_name("/".join(param.opts) if param is not None else "path", path)
        return path


def _parse_params(items: tuple[str, ...], option: str = "--param") -> dict[str, Any]:
    """``-p NAME=VALUE`` items (of ``option``) -> {name: value}; VALUE is read as a TOML value (number, true,
    "text") or, if it is not one, taken as a string. One parameter per item."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise BadInput(option, f"expected NAME=VALUE, got {clip_repr(item)}")
        if any(c in item for c in "\n\r\0"):
            raise BadInput(option, f"one NAME=VALUE per item, without line breaks, got {clip_repr(item)}")
        if name.strip() in out:
            raise BadInput(f"{option} {clip(name.strip())}", "given twice")
        try:
            out[name.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            out[name.strip()] = value
        except ValueError:  # an integer of more than 4300 digits (Python's int-conversion limit)
            raise BadInput(f"{option} {clip(name.strip())}",
                           f"a number of {len(value.strip())} digits is not a parameter value") from None
    return out


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="imbench")
def cli() -> None:
    """imbench: induction-motor test bench (thesis: Trangbaek 2001)."""


def _pacing_options(f: Callable) -> Callable:
    """--realtime/--lockstep and --allow-soft-realtime, shared by every command that runs a session."""
    f = click.option("--allow-soft-realtime", is_flag=True,
                     help="run a real rig even where SCHED_FIFO cannot be applied (recorded in the summary)")(f)  # fmt: skip
    return click.option("--realtime/--lockstep", "realtime", default=None,
                        help="pace the loop by the wall clock, or run simulated time as fast as possible "
                             "[default: real time on a rig with real devices (refuses --lockstep), else lockstep]")(f)  # fmt: skip


def _live_options(f: Callable) -> Callable:
    """--live, --live-port, --live-host, --live-rate: the same on every command that runs a session."""
    f = click.option("--live-rate", type=FINITE, default=100.0, show_default=True,
                     help="/rig, /ctrl, /truth rate on the live stream [Hz]")(f)  # fmt: skip
    f = click.option("--live-host", default="127.0.0.1", show_default=True,
                     help="live server address; anything but loopback opens it to the network (no authentication)")(f)  # fmt: skip
    f = click.option("--live-port", type=int, default=8765, show_default=True,
                     help="live server port (0: any free one)")(f)  # fmt: skip
    return click.option("--live", is_flag=True, help="serve the run live to Foxglove (WebSocket, from the log writer)")(f)


def _live(live: bool, live_port: int, live_host: str, live_rate: float) -> dict[str, Any]:
    """RunOptions fields for the live stream, with the warning a network-facing server deserves."""
    if live and live_host not in ("127.0.0.1", "localhost", "::1"):
        from bench.session import check_live_address

        if 0 <= live_port <= 65535:  # an address this machine lacks: the one-line error, not the warning
            check_live_address(live_host, live_port)
        click.echo(f"bench: warning: the live server on {live_host} has no authentication: anyone who can reach it "
                   "sees the rig's data, changes tunable parameters and can stop the run", err=True)  # fmt: skip
    return {"live_port": live_port if live else None, "live_host": live_host, "live_rate": live_rate}


def _report_end(result: dict[str, Any], code: int, keys: tuple[str, ...] | None = None) -> None:
    """The run's numbers on stdout (JSON), and a line on stderr if it did not end normally.

    The summary file is already written; one that could not be (a full disk) is printed here in full
    on stderr, and the last line says which files were and were not written. A closed terminal
    (SIGHUP) must not turn this into an error.
    """
    try:
        if keys is not None:
            click.echo(json.dumps({k: result.get(k) for k in keys}, indent=2, default=str))
        if "summary" in result and not result["summary"]:  # its file could not be written: it is not lost
            full = json.dumps({k: v for k, v in result.items() if k != "record"}, indent=2, default=str)
            click.echo(f"bench: the summary in full (its file could not be written):\n{full}", err=True)
        cause = result.get("trip_cause")
        if cause:
            t = result.get("trip_time")
            when = f" at t = {t:.4f} s" if isinstance(t, float) else ""
            word = "INTERRUPTED" if code >= 128 else "TRIPPED"
            click.echo(f"bench: {word}{when}: {cause} (rig safe; {written_note(result)})", err=True)
        for warning in result.get("warnings") or ():
            click.echo(f"bench: warning: {warning}", err=True)
    except OSError:  # stdout/stderr gone
        pass


@cli.command()
@click.option("--rig", default="mock", show_default=True, help="rig name (rigs/NAME.toml) or rig-file path")
@click.option("--controller", default="foc", show_default=True, help="controller plugin (see `bench controllers`)")
@click.option("--scenario", default="demo", show_default=True, help="scenario (see `bench scenarios`)")
@click.option("--scenario-arg", "scenario_args", multiple=True, metavar="NAME=VALUE",
              help="a parameterised scenario's argument, e.g. speed=80 for load-step; repeatable")
@click.option("--duration", type=FINITE, default=None, help="run length [s]; default: the scenario's")
@_pacing_options
@click.option("--seed", type=int, default=0, show_default=True, help="random seed (noise)")
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="controller parameter, repeatable")
@click.option("--log", type=OutFile(), default=None, help="MCAP log path")
@click.option("--summary", type=OutFile(), default=None, help="summary JSON path")
@click.option("--plot", type=OutFile(), default=None, help="PNG plot path")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("runs"), show_default=True,
              help="folder for run folders when --log is not given")  # fmt: skip
@click.option("--force", is_flag=True, help="overwrite existing --log/--summary/--plot files")
@click.option("--log-buffer", type=FINITE, default=10.0, show_default=True, metavar="SECONDS",
              help="ticks the log ring holds: a log-writer stall shorter than this loses nothing; longer trips")
@click.option("--can-log", type=OutFile(), default=None,
              help="every CAN frame into FILE.blf/.asc/... (python-can's can.logger; driver rigs)")
@_live_options
@click.option("--replay-params", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="LOG.mcap",
              help="re-apply that run's parameter changes and operator actions at the same ticks")
@click.option("--switch", "switches", multiple=True, metavar="T:PART=CHOICE",
              help="switch a part at loop time T [s] while running, e.g. 5:speed_controller=lpv; repeatable")
@click.option("--no-progress", is_flag=True, help="no progress bar")
@click.option("--inject-fault", default=None, metavar="NAME",
              help="test a trip path, mock and emulated rigs only: over-speed (the over-speed trip lowered to half "
                   "the scenario's largest speed reference)")  # fmt: skip
def run(rig: str, controller: str, scenario: str, scenario_args: tuple[str, ...], duration: float | None,
        realtime: bool | None,
        allow_soft_realtime: bool, seed: int, param: tuple[str, ...], log: Path | None, summary: Path | None,
        plot: Path | None, out: Path, force: bool, log_buffer: float, can_log: Path | None, live: bool,
        live_port: int, live_host: str, live_rate: float, replay_params: Path | None, switches: tuple[str, ...],
        no_progress: bool, inject_fault: str | None) -> int:  # fmt: skip
    """Run a controller against a rig through a scenario; write log, summary and plot."""
    from bench.session import RunOptions
    from bench.session import run as run_session

    opts = RunOptions(rig=rig, controller=controller, scenario=scenario,
                      scenario_args=_parse_scenario_args(scenario_args), duration=duration, realtime=realtime,
                      allow_soft_realtime=allow_soft_realtime, seed=seed, params=_parse_params(param), log=log,
                      summary=summary, plot=plot, out_dir=out, force=force, log_buffer=log_buffer,
                      can_log=can_log, **_live(live, live_port, live_host, live_rate), replay_params=replay_params,
                      switches=_parse_switches(switches), progress=not no_progress and sys.stderr.isatty(),
                      inject_fault=inject_fault)  # fmt: skip
    result, code = run_session(opts)
    _report_end(result, code, ("ticks", "duration", "realtime_factor", "deadline_misses", "speed_error",
                               "speed_error_settled", "load_steps", "trip_cause", "exit_code", "log", "plot",
                               "summary"))  # fmt: skip
    return code


def _parse_scenario_args(items: tuple[str, ...]) -> dict[str, float]:
    """``NAME=VALUE`` items of --scenario-arg (the names checked against the scenario when the run starts)."""
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not eq or not name.strip() or not math.isfinite(v):
            raise BadInput("--scenario-arg", f"must be NAME=NUMBER (e.g. speed=80), got {clip_repr(item)}")
        out[name.strip()] = v
    return out


def _parse_switches(items: tuple[str, ...]) -> tuple[tuple[float, str, str], ...]:
    """``T:PART=CHOICE`` items of --switch (checked against the controller when the run starts)."""
    out = []
    for item in items:
        t, _, assignment = item.partition(":")
        part, eq, choice = assignment.partition("=")
        try:
            when = float(t)
        except ValueError:
            when = math.nan
        if not eq or not part or not choice or not math.isfinite(when):
            raise BadInput("--switch", f"must be T:PART=CHOICE (e.g. 5:speed_controller=lpv), got {clip_repr(item)}")
        out.append((when, part.strip(), _parse_params((f"{part.strip()}={choice.strip()}",))[part.strip()]))
    return tuple(out)


ANSWERS = ("Exit codes: 0 applied (the tick is printed, also when the answer came late); 2 refused (one line: "
           "why) or bad input; 4 no answer within --timeout: not known whether it was applied (see /params, "
           "/events or the log).")  # fmt: skip


def _client_options(f: Callable) -> Callable:
    f = click.option("--timeout", "wait", type=click.FloatRange(0.1, 3600.0), default=5.0, show_default=True,
                     help="how long to wait for the loop's answer [s]; without one the outcome is unknown (exit 4)")(f)  # fmt: skip
    f = click.option("--port", type=click.IntRange(1, 65535), default=8765, show_default=True,
                     help="the live session's port (bench run --live-port)")(f)  # fmt: skip
    return click.option("--host", default="127.0.0.1", show_default=True, help="the live session's address")(f)


def _answered(action: str, ans: dict, applied: Callable[[dict], list[str]]) -> int:
    """One answer of a live session printed (`bench.live_client.request`): applied -> the lines of ``applied(ans)``
    (exit 0), refused -> one line with the reason (exit 2), unknown -> one line saying so (exit 4)."""
    if ans["state"] == APPLIED:
        late = " (the answer came late)" if ans.get("late") else ""
        for line in applied(ans):
            click.echo(line + late)
    elif ans["state"] == REFUSED:
        click.echo(f"bench: error: {clip(str(ans.get('status')).removeprefix('refused: '), 400)}", err=True)
    else:
        click.echo(f"bench: {action}: unknown: {ans.get('status')}", err=True)
    return EXIT_CODES[ans["state"]]


def _at(ans: dict) -> str:
    t = ans.get("t")
    return f"at tick {ans.get('tick')}" + (f" (t = {t:.4f} s)" if isinstance(t, float) else "")


@cli.command("set", epilog=ANSWERS)
@click.argument("assignments", nargs=-1, required=True, metavar="NAME=VALUE...")
@_client_options
def set_cmd(assignments: tuple[str, ...], host: str, port: int, wait: float) -> int:
    """Change parameters of a running session (`bench run --live`), all in one request: the loop applies them
    together between two ticks, or none. Waits for the loop's answer.

    Tunable controller parameters (`bench controllers`) and the overrides omega_r_ref_override,
    m_l_ref_override, i_mr_ref_override (VALUE off hands back to the scenario)."""
    params = _parse_params(assignments)
    for name, v in params.items():  # the protocol carries no nan/inf/bigint: the server would drop it
        if isinstance(v, float) and not math.isfinite(v) or isinstance(v, int) and not -(2**63) <= v < 2**63:
            shown = f"an integer of {len(str(abs(v)))} digits" if isinstance(v, int) else repr(v)
            raise BadInput(name, f"must be a finite number (within +-9.2e18), got {shown}")
    ans = request("set", {"parameters": params}, host, port, wait)
    return _answered("set", ans, lambda a: [f"{i['name']}: {i['old']} -> {i['new']} {_at(a)}" for i in a["items"]])


@cli.command("switch", epilog=ANSWERS)
@click.argument("assignments", nargs=-1, required=True, metavar="PART=CHOICE...")
@_client_options
def switch_cmd(assignments: tuple[str, ...], host: str, port: int, wait: float) -> int:
    """Switch parts of a running session (`bench run --live`) at a tick boundary, bumpless; waits for the loop.
    Several parts are one request: the loop checks them together and switches all of them between two ticks, or
    none.

    PART: observer, speed_controller, current_controller, speed_source (FOC; `bench controllers` lists the
    choices), or controller (the whole plugin, where another one can take over: relay_tune; alone). A part that
    cannot be had (no artifact for this motor or rate, a range below the rig's speed limit), a switch during a stop
    or after a trip is refused with the reason, and the old parts keep running."""
    parts: dict[str, str] = {}
    for item in assignments:
        part, eq, choice = item.partition("=")
        if not eq or not part.strip() or not choice.strip():
            raise BadInput("switch", f"must be PART=CHOICE (e.g. speed_controller=lpv), got {clip_repr(item)}")
        if part.strip() in parts:
            raise BadInput(f"switch {clip_repr(part.strip())}", "given twice")
        parts[part.strip()] = choice.strip()
    ans = request("switch", {"parts": parts}, host, port, wait)
    return _answered("switch", ans, lambda a: [f"{i['name']} -> {i['new']} {_at(a)}" for i in a["items"]])


def _action(action: str, note: str, host: str, port: int, wait: float) -> int:
    return _answered(action, call(action, note, host, port, wait=wait), lambda a: [f"{action}: applied {_at(a)}"])


@cli.command("stop", epilog=ANSWERS)
@_client_options
def stop_cmd(host: str, port: int, wait: float) -> int:
    """Operator stop of a live session: ramp the speed to zero, hold, end the run normally."""
    return _action("stop", "", host, port, wait)


@cli.command("estop", epilog=ANSWERS)
@_client_options
def estop_cmd(host: str, port: int, wait: float) -> int:
    """Emergency stop of a live session: safe state at the next tick (the run trips)."""
    return _action("estop", "", host, port, wait)


@cli.command("mark", epilog=ANSWERS)
@click.argument("note")
@_client_options
def mark_cmd(note: str, host: str, port: int, wait: float) -> int:
    """Write a note into a live session's log (/events)."""
    return _action("mark", note, host, port, wait)


@cli.command("layout")
def layout_cmd() -> None:
    """Print the Foxglove layout for imbench runs (live or recorded): plots, parameters, services."""
    from bench.foxglove_layout import layout_json

    click.echo(layout_json(), nl=False)


@cli.command()
def scenarios() -> None:
    """List the scenarios."""
    for name, make in SCENARIOS.items():
        s = make()
        args = arguments(name)
        takes = f"  (--scenario-arg {', '.join(f'{a}={v:g}' for a, v in args.items())})" if args else ""
        click.echo(f"{name:12s} {s.duration:6.2f} s  {s.description}{takes}")


@cli.command()
@click.argument("name", required=False)
@click.option("--json", "as_json", is_flag=True, help="the parameter schema as JSON")
@click.option("--markdown", is_flag=True, help="the docs page (docs/controllers.md)")
def controllers(name: str | None, as_json: bool, markdown: bool) -> None:
    """List the controller plugins and their parameters (unit, allowed values, * = tunable while running)."""
    from bench.controllers import available

    table = available()
    if name is not None and name not in table:
        raise BadInput("controller", f"unknown controller {name!r}; allowed: {', '.join(sorted(table))}")
    chosen = {name: table[name]} if name else dict(sorted(table.items()))
    if markdown:
        from bench.controllers.schema import markdown as schema_markdown

        click.echo(schema_markdown(chosen), nl=False)
        return
    if as_json:
        click.echo(json.dumps({n: {"summary": c.summary, "parameters": {
            k: {"default": p.default, "unit": p.unit, "allowed": p.allowed(), "tunable": p.tunable, "doc": p.doc}
            for k, p in c.schema.items()}} for n, c in chosen.items()}, indent=2))  # fmt: skip
        return
    for n, cls in chosen.items():
        click.echo(f"{n}: {cls.summary}")
        width = max((len(k) for k in cls.schema), default=0)
        for key, p in cls.schema.items():
            click.echo(f"  {key:{width}s} {'*' if p.tunable else ' '} = {p.default!r:<16} {p.allowed()}"
                       + (f"  - {p.doc}" if p.doc else ""))  # fmt: skip
        click.echo("")
    click.echo("-p NAME=VALUE sets one; * = may change while the rig runs", err=True)


@cli.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="PNG path [default: LOG.png, or LOG-2.png, ... where that exists (the run wrote LOG.png)]")
@click.option("--force", is_flag=True, help="overwrite an existing PNG (without --out: LOG.png)")
def plot(log: Path, out: Path | None, force: bool) -> None:
    """Plot a run log (thesis-style PNG, with parameter changes and operator actions marked); prints its path."""
    from bench.daq.plots import plot_run

    out = out or (log.with_suffix(".png") if force else free_path(log.with_suffix(".png")))
    check_output("--out", out, force)
    png = plot_run(log, out)
    click.echo(str(png))


@cli.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="everything (summary, fields, metadata) as JSON")
def inspect(log: Path, as_json: bool) -> None:
    """Show what a log holds: run, outcome, topics (messages, fields), attachments; --json for all of it."""
    from bench.daq import LogReader

    r = LogReader(log)

    def fields(topic: str) -> list[str] | str:
        try:
            return r.fields(topic)
        except ValueError as exc:  # a foreign encoding: show the topic, say why there are no fields
            return str(exc)

    s, meta = r.summary(), r.metadata()
    if as_json:
        click.echo(json.dumps({"summary": s, "topics": {t: fields(t) for t in r.topics()}, "metadata": meta,
                               "attachments": sorted(r.attachments())}, indent=2, default=str))  # fmt: skip
        return
    run, end = meta.get("run", {}), meta.get("shutdown", {})
    state = "finished" if s["finalised"] else f"not finished (torn: {s['stop_reason'] or 'no summary section'})"
    lines = [f"{log}: {s['message_count']} messages, {s['duration_s']:.3f} s of log time, {state}"]
    if run:
        lines.append(f"run: scenario {run.get('scenario')}, controller {run.get('controller')}, seed {run.get('seed')}, "
                     f"{'real time' if run.get('realtime') else 'lockstep'}, code {run.get('code_version')}")  # fmt: skip
    if end:
        lines.append(f"end: exit code {end.get('exit_code')}" + (f", cause: {end['cause']}" if end.get("cause") else ""))
    for t in r.topics():
        f = fields(t)
        desc = f"{len(f)} fields" if isinstance(f, list) else f
        lines.append(f"  {t:8s} {s['topics'][t]['messages']:8d} messages  {s['topics'][t]['type']}  ({desc})")
    try:
        changes = [e for e in r.events() if e.get("kind") == "set"]
    except Exception:  # noqa: BLE001 - a torn /params: the rest of the listing still helps
        changes = []
    from bench.requests import switch_names

    for e in changes[:50]:  # parts switched (and parameters changed) while running, at their ticks
        what = "switch" if e["name"] in switch_names() else "set"
        lines.append(f"  {what} t = {e['t']:.4f} s (tick {e['tick']}): {e['name']} {e['old_text']} -> {e['new_text']} "
                     f"({e['who']}): {e['status']}")  # fmt: skip
    if len(changes) > 50:
        lines.append(f"  ... {len(changes) - 50} more parameter changes (bench inspect --json does not list them; "
                     "LogReader.events does)")  # fmt: skip
    att = sorted(r.attachments())
    if att:
        lines.append(f"attachments: {', '.join(att)}")
    lines.append(f"metadata records: {', '.join(meta)} (bench inspect --json shows them)")
    click.echo("\n".join(lines))


@cli.command("reproduce")
@click.argument("name", required=False)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("runs/reproduce"),
              show_default=True, help="folder for NAME.png and NAME.json (docs/figures regenerates the committed ones)")
@click.option("--force", is_flag=True, help="overwrite an earlier reproduction in --out")
def reproduce_cmd(name: str | None, out: Path, force: bool) -> None:
    """Reproduce a thesis figure; without NAME, list them."""
    if name is None:
        for key, desc in reproduce.available().items():
            click.echo(f"{key:12s} {desc}")
        return
    result, written = reproduce.reproduce(name, out, force=force)
    click.echo(json.dumps(result, indent=2, default=float))
    click.echo(f"bench: wrote {', '.join(str(p) for p in written)}", err=True)


class _DefaultRun(click.Group):
    """``bench sweep SPEC.toml ...`` runs a sweep (``run`` is implied); ``bench sweep report DIR`` reports."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("-h", "--help"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


@cli.group(cls=_DefaultRun)
def sweep() -> None:
    """Sweeps and Monte-Carlo studies on Dask: `bench sweep SPEC.toml --out DIR`, `bench sweep report DIR`."""


def _dask_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """--workers / --scheduler: where sweep tasks run (a local Dask cluster, or a running scheduler)."""
    f = click.option("--scheduler", default=None, metavar="ADDRESS",
                     help="a running Dask scheduler, e.g. tcp://host:8786")(f)  # fmt: skip
    return click.option("--workers", type=int, default=None, help="local cluster: worker processes [default: 2]")(f)


def _workers(workers: int | None, scheduler: str | None) -> int | None:
    if workers is not None and scheduler is not None:
        raise BadInput("--workers", "give --workers (local cluster) or --scheduler, not both")
    return 2 if workers is None and scheduler is None else workers


@sweep.command("run")
@click.argument("spec", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="folder for results.parquet (a re-run resumes: finished cases are skipped)")
@_dask_options
@click.option("--connect-timeout", type=FiniteRange(0.1, 600), default=10.0, show_default=True, metavar="SECONDS",
              help="how long to try reaching --scheduler")  # fmt: skip
@click.option("--keep-logs", is_flag=True, help="an MCAP log (and rig file) per case in DIR/logs")
@click.option("--allow-large", is_flag=True, help="run a sweep of more than 100000 cases")
@click.option("--no-progress", is_flag=True, help="no progress bar")
@click.option("--batch", type=click.IntRange(0, 100_000), default=None, metavar="N",
              help="the cases the batch engine covers run up to N per task in one compiled loop [default: 256; "
                   "0: every case on the scalar engine, with per-tick timing]")
@click.option("--dashboard", is_flag=True, help="local cluster: serve Dask's status pages on 127.0.0.1, HTTPS "
              "(the address on stderr) [default: none]")  # fmt: skip
def sweep_run(spec: Path, out: Path, workers: int | None, scheduler: str | None, connect_timeout: float,
              keep_logs: bool, allow_large: bool, no_progress: bool, batch: int | None,
              dashboard: bool) -> int:  # fmt: skip
    """Run every case of a sweep file (mock rig, lockstep) and write DIR/results.parquet."""
    from bench.sweep.batching import DEFAULT_BATCH
    from bench.sweep.engine import run_sweep
    from bench.sweep.spec import load

    batch = DEFAULT_BATCH if batch is None else batch
    workers = _workers(workers, scheduler)
    sp = load(spec)
    result = run_sweep(sp, out, workers=workers, scheduler=scheduler, keep_logs=keep_logs, progress=not no_progress,
                       connect_timeout=connect_timeout, allow_large=allow_large, batch=batch, dashboard=dashboard,
                       say=lambda line: click.echo(f"bench: {line}", err=True))  # fmt: skip
    click.echo(json.dumps(result, indent=2, default=str))
    if result.get("table_error"):  # a full disk: the rows are in the JSON above, not lost
        click.echo(f"bench: sweep: {result['table_error']}; its {len(result['rows'])} rows are in the JSON on "
                   "stdout", err=True)  # fmt: skip
        return 1
    return 1 if result["error"] else 0


@sweep.command("report")
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
def sweep_report(out: Path) -> None:
    """Plots (PNG) and a markdown summary of a sweep's results.parquet, written into the same folder."""
    from bench.sweep.report import report

    written = report(out)
    click.echo(json.dumps({"written": [str(p) for p in written]}, indent=2))


@cli.group()
def perf() -> None:
    """Benchmarks (print JSON)."""


def _perf_echo(result: object) -> None:
    """A benchmark's JSON on stdout, with what it was measured with (`synthesis.environment`) under "environment"."""
    out = dict(result) if isinstance(result, dict) else {"result": result}
    out.setdefault("environment", environment())
    click.echo(json.dumps(out, indent=2, default=float))


@perf.command("sweep")
@click.option("--cases", type=click.IntRange(6, 600), default=12, show_default=True, help="cases (a multiple of 6)")
@click.option("--duration", type=FiniteRange(0.5, 60), default=3.0, show_default=True, help="simulated s per case")
@click.option("--rounds", type=click.IntRange(1, 20), default=2, show_default=True,
              help="serial / Dask rounds, alternating, per cluster size")
def perf_sweep(cases: int, duration: float, rounds: int) -> None:
    """Sweep throughput: serial in-process vs Dask with 1 and 2 local workers (overhead, efficiency)."""
    from bench.perf.sweep import run as run_perf
    if cases % 6:
        raise BadInput("--cases", f"must be a multiple of 6 (3 observers x 2 plants x seeds), got {cases}")
    _perf_echo(run_perf(cases, duration, rounds))


@perf.command("batch")
@click.option("--sizes", default="1,10,100,1000", show_default=True, help="batch sizes, comma-separated")
@click.option("--large", is_flag=True, help="also a batch of 10000 cases")
@click.option("--duration", type=FiniteRange(0.01, 60), default=0.5, show_default=True, help="simulated s per case")
@click.option("--scenario", default="fig5.7", show_default=True, help="a scenario the batch engine runs")
@click.option("--cold", is_flag=True, help="start-up measured with an empty numba cache (compiles everything)")
@click.option("--atlas", is_flag=True, help="instead: the robustness atlas' cases the batch engine covers, timed, "
              "40 random cases of each atlas checked row by row against the scalar engine")
@click.option("--no-peers", is_flag=True,
              help="without gym-electric-motor and motulator (pip install 'imbench[peers]')")  # fmt: skip
@click.option("--peers-python", type=click.Path(dir_okay=False, exists=True), default=None, metavar="PYTHON",
              help="the interpreter the peers run in (a venv of their own) [default: this one]")
@click.option("--plot", "plot_png", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="PNG",
              help="also a plot: motor-ticks/s vs batch size, the scalar engine and the peers as lines")
def perf_batch(sizes: str, large: bool, duration: float, scenario: str, cold: bool, atlas: bool, no_peers: bool,
               peers_python: str | None, plot_png: Path | None) -> None:  # fmt: skip
    """Batch engine: motor-ticks/s vs batch size, the scalar engine and peers side by side, JIT start-up apart."""
    from bench.perf.batch import plot, run as run_perf

    if atlas:
        from bench.perf.batch import atlas as run_atlas

        _perf_echo(run_atlas())
        return

    try:
        ns = tuple(int(x) for x in sizes.split(","))
    except ValueError:
        raise BadInput("--sizes", f"comma-separated integers, got {sizes!r}") from None
    if not ns or not all(1 <= n <= 20_000 for n in ns):  # ~25 kB of state per case, twice while stacked
        raise BadInput("--sizes", f"each in 1..20000, got {sizes!r}")
    from bench.batch import SCENARIOS

    if scenario not in SCENARIOS:
        raise BadInput("--scenario", f"one of {', '.join(SCENARIOS)}, got {scenario!r}")
    if plot_png is not None and not plot_png.parent.is_dir():
        raise BadInput("--plot", f"no such folder: {plot_png.parent}")
    doc = run_perf(ns + ((10_000,) if large and 10_000 not in ns else ()), duration, scenario, cold=cold,
                   peers=not no_peers, peers_python=peers_python)  # fmt: skip
    if plot_png is not None:
        doc["plot"] = str(plot(doc, plot_png))
    _perf_echo(doc)


@perf.command("loop")
@click.option("--duration", type=FiniteRange(0.1, 600), default=10.0, show_default=True)
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="FOC parameter, e.g. -p observer=lpv")
def perf_loop(duration: float, param: tuple[str, ...]) -> None:
    """Real-time 3 kHz loop, FOC + logging, on the mock rig."""
    from bench.perf.loop import run_benchmark

    _perf_echo(run_benchmark("loop", duration, params=_parse_params(param)))


@perf.command("sim")
@click.option("--duration", type=FiniteRange(0.1, 600), default=10.0, show_default=True)
@click.option("--no-log", is_flag=True, help="measure without logging")
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="FOC parameter, e.g. -p observer=lpv")
def perf_sim(duration: float, no_log: bool, param: tuple[str, ...]) -> None:
    """Lockstep simulated seconds per wall second, with full logging."""
    from bench.perf.loop import run_benchmark

    _perf_echo(run_benchmark("sim", duration, log=not no_log, params=_parse_params(param)))


@perf.command("tick")
@click.option("--duration", type=FiniteRange(0.5, 60), default=3.0, show_default=True)
@click.option("--rounds", type=click.IntRange(1, 20), default=3, show_default=True)
def perf_tick(duration: float, rounds: int) -> None:
    """The lockstep tick in yardsticks, without and with the log, and where its time goes."""
    from bench.perf.tick import run

    _perf_echo(run(duration, rounds))


@perf.command("switch")
@click.option("--duration", type=FiniteRange(3.0, 600.0), default=8.0, show_default=True, help="[s] per run")
@click.option("--rounds", type=click.IntRange(1, 20), default=2, show_default=True)
def perf_switch(duration: float, rounds: int) -> None:
    """Real-time runs with 20 part switches and without, side by side: deadline misses, compute time at the switches."""
    from bench.perf.switch import run

    _perf_echo(run(duration, rounds))


@perf.command("stall")
@click.option("--stalls", default="2,4,8,16,20,32,64", show_default=True, help="stall lengths [ms], comma-separated")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="PNG of a 16 ms stall at the rated point, both drives")
def perf_stall(stalls: str, plot: Path | None) -> None:
    """Loop stalls injected at the rated point, at 100 rad/s and 7 N m, and 0.4 ms into a run (magnetising), with
    the drive's ride-through and without."""
    from bench.perf.stall import run

    try:
        ms = tuple(float(x) for x in stalls.split(","))
    except ValueError:
        raise BadInput("--stalls", f"must be comma-separated numbers of milliseconds, got {stalls!r}") from None
    if not all(0.5 <= x <= 1000.0 for x in ms):
        raise BadInput("--stalls", f"each must be in [0.5, 1000] ms, got {stalls!r}")
    if plot is not None:
        check_output("--plot", plot, force=True)
    _perf_echo(run(ms, plot))


@perf.command("load")
@click.option("--runs", type=click.IntRange(1, 200), default=20, show_default=True)
@click.option("--hogs", type=click.IntRange(0, 16), default=2, show_default=True, help="CPU-bound processes beside each run")
@click.option("--rig", default="mock", show_default=True, help="rig name or file")
@click.option("--scenario", default="hold", show_default=True)
@click.option("--duration", type=FiniteRange(0.5, 600.0), default=10.0, show_default=True, help="[s] per run")
@click.option("--emulator", type=click.Choice(["in-process", "process"]), default="in-process", show_default=True,
              help="a driver rig's emulators: started by each run in its process, or a `bench emulate` beside it")
def perf_load(runs: int, hogs: int, rig: str, scenario: str, duration: float, emulator: str) -> None:
    """Real-time runs one after another with CPU-bound processes beside each: trips, stalls, deadline misses."""
    from bench.perf.load import run

    _perf_echo(run(runs, hogs, rig, scenario, duration, emulator))


@perf.command("observers")
@click.option("--calls", type=click.IntRange(100, 10_000_000), default=20000, show_default=True)
@click.option("--repeats", type=click.IntRange(1, 100), default=5, show_default=True)
def perf_observers(calls: int, repeats: int) -> None:
    """Per-call CPU cost of every flux observer and speed estimator, and the FOC tick with each."""
    from bench.perf.observers import run

    _perf_echo(run(calls, repeats))


@perf.command("speed")
@click.option("--repeats", type=click.IntRange(1, 100), default=5, show_default=True)
def perf_speed(repeats: int) -> None:
    """Per-call CPU time of the LPV speed controllers (600 Hz, robust, 3 kHz) and the PI, and the FOC tick with each."""
    from bench.perf.speed import run

    _perf_echo(run(repeats))


@perf.command("current")
@click.option("--repeats", type=click.IntRange(1, 100), default=5, show_default=True)
def perf_current(repeats: int) -> None:
    """Per-tick CPU time of the current controllers (PI, LPV 600 Hz and 3 kHz)."""
    from bench.perf.current import run

    _perf_echo(run(repeats))


@perf.command("synthesis")
@click.option("--repeats", type=click.IntRange(1, 100), default=3, show_default=True)
@click.option("--current", is_flag=True, help="the quasi-LPV current controller of 6.2.2 instead of the flux observer")
def perf_synthesis(repeats: int, current: bool) -> None:
    """Wall time of the LMI syntheses (flux observer 5.6.2, or --current 6.2.2)."""
    from bench.perf import synthesis

    with summarised_warnings("perf synthesis"):
        res = synthesis.run_current(repeats) if current else synthesis.run(repeats)
    _perf_echo(res)


@perf.command("robust")
@click.option("--repeats", type=click.IntRange(1, 100), default=3, show_default=True)
def perf_robust(repeats: int) -> None:
    """Robust LPV synthesis (chapter 7): wall times and the checks of Theorem 7.1."""
    from bench.perf.robust import run

    with summarised_warnings("perf robust"):
        res = run(repeats)
    _perf_echo(res)


@perf.command("identify")
@click.option("--motors", type=click.IntRange(1, 200), default=20, show_default=True,
              help="random hidden motors (the thesis motor comes first, in addition)")
@click.option("--motors-seed", type=int, default=0, show_default=True, help="seed of the motor draw")
@click.option("--seed", type=int, default=0, show_default=True,
              help="noise seed of every run; repeatability adds seed+1, seed+2, ...")
@click.option("--repeat-motors", type=click.IntRange(0, 200), default=3, show_default=True,
              help="random motors identified again over the noise seeds")
@click.option("--repeat-seeds", type=click.IntRange(2, 100), default=10, show_default=True,
              help="noise seeds per repeated motor (the first is --seed)")
@click.option("--saturation-row/--no-saturation-row", default=True, show_default=True,
              help="one more run: the thesis motor with main-flux saturation (outside the summary)")
@click.option("--voltages", type=click.Choice(["both", "measured", "reference"]), default="both", show_default=True,
              help="the modes judged, each by its own runs (with its own defaults)")
@click.option("--one-run", is_flag=True, help="one run per motor and seed (measured voltages), fitted with each mode")
@click.option("--engine", type=click.Choice(["auto", "compiled", "python"]), default="auto", show_default=True,
              help="mock plant engine (bit-identical)")
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="standstill_id parameter for every run")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="keep the rig files, logs and plots here (default: a temporary folder, removed)")
@click.option("--markdown", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="also write the result as markdown tables (the docs' tables) into this file")
@click.option("--rotating", is_flag=True, help="the rotating tests instead: standstill (measured voltages) then "
              "rotating on each motor; L_m at the rated flux, J, friction against the truth")  # fmt: skip
def perf_identify(motors: int, motors_seed: int, seed: int, repeat_motors: int, repeat_seeds: int,
                  saturation_row: bool, voltages: str, one_run: bool, engine: str, param: tuple[str, ...],
                  out: Path | None, markdown: Path | None, rotating: bool) -> None:  # fmt: skip
    """Standstill identification against the mock's hidden truth: random motors, both voltages, noise seeds, time."""
    from bench.commission import accuracy

    if rotating:
        _perf_echo(accuracy.run_rotating(motors, motors_seed=motors_seed, seed=seed, saturation_row=saturation_row))
        return

    res = accuracy.run(motors, motors_seed=motors_seed, seed=seed, repeat_motors=repeat_motors,
                       repeat_seeds=repeat_seeds, params=_parse_params(param), one_run=one_run,
                       voltages=accuracy.VOLTAGES if voltages == "both" else (voltages,),
                       saturation_row=saturation_row, engine=engine, out_dir=out)  # fmt: skip
    if markdown is not None:
        markdown.write_text(accuracy.markdown(res), encoding="utf-8")
    _perf_echo(res)


@perf.command("writer", context_settings={"ignore_unknown_options": True})
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
def perf_writer(args: tuple[str, ...]) -> None:
    """MCAP logging throughput for several topic layouts (options: --help of bench.perf.writer)."""
    from bench.perf.writer import main as writer_main

    writer_main(list(args))


@perf.command("drivers")
@click.option("--duration", type=FiniteRange(0.1, 600), default=10.0, show_default=True)
@click.option("--rate", type=FiniteRange(100, 50_000), default=3000.0, show_default=True)
@click.option("--emulator", type=click.Choice(["process", "thread"]), default="process", show_default=True)
@click.option("--interface", type=click.Choice(["tcp", "virtual"]), default="tcp", show_default=True)
@click.option("--lockstep", is_flag=True, help="lockstep instead of real time (throughput)")
def perf_drivers(duration: float, rate: float, emulator: str, interface: str, lockstep: bool) -> None:
    """The real drivers against the emulators (another process) at the loop rate: frames, misses, tick cost."""
    from bench.perf.drivers import run_benchmark

    _perf_echo(run_benchmark(duration, rate, emulator, interface, not lockstep))


@perf.command("live")
@click.option("--duration", type=FiniteRange(3, 600), default=10.0, show_default=True)
@click.option("--pairs", type=click.IntRange(1, 20), default=2, show_default=True)
def perf_live(duration: float, pairs: int) -> None:
    """Real-time runs with and without --live (one client subscribed to everything), side by side."""
    from bench.perf.live import run

    _perf_echo(run(duration, pairs))


@perf.command("operator")
@click.option("--duration", type=FiniteRange(0.5, 60), default=2.0, show_default=True)
@click.option("--rounds", type=click.IntRange(1, 20), default=3, show_default=True)
def perf_operator(duration: float, rounds: int) -> None:
    """Lockstep tick cost without, with an idle and with a busy operator (on-line parameters), side by side."""
    from bench.perf.operator import run

    _perf_echo(run(duration, rounds))


@perf.command("plant")
@click.option("--ticks", type=click.IntRange(100, 10_000_000), default=30000, show_default=True)
@click.option("--substeps", type=click.IntRange(1, 1000), default=1, show_default=True)
@click.option("--engine", type=click.Choice(["auto", "compiled", "python"]), default="auto", show_default=True,
              help="the mock plant's engine ([mock] engine)")
def perf_plant(ticks: int, substeps: int, engine: str) -> None:
    """The mock rig's read + write per tick."""
    from bench.perf.plant import measure

    _perf_echo(measure(ticks, substeps, engine=engine))


@cli.group()
def tune() -> None:
    """Tuning experiments on a rig (relay feedback)."""


@tune.command("speed")
@click.option("--rig", default="mock", show_default=True, help="rig name (rigs/NAME.toml) or rig-file path")
@click.option("--amplitude", type=FiniteRange(0.0, 100.0, min_open=True), default=None,
              help="relay torque amplitude d [N m] (default: relay_tune's)")
@click.option("--hysteresis", type=FiniteRange(0.0, 100.0), default=None,
              help="relay hysteresis eps [rad/s] (default: relay_tune's)")
@click.option("--duration", type=FINITE, default=None, help="run length [s]; default: the relay0 scenario's")
@click.option("--seed", type=int, default=0, show_default=True, help="random seed (noise)")
@_pacing_options
@_live_options
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="relay_tune/FOC parameter, repeatable")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("runs"), show_default=True,
              help="folder for the run folder")  # fmt: skip
def tune_speed_cmd(rig: str, amplitude: float | None, hysteresis: float | None, duration: float | None, seed: int,
                   realtime: bool | None, allow_soft_realtime: bool, live: bool, live_port: int, live_host: str,
                   live_rate: float, param: tuple[str, ...], out: Path) -> int:  # fmt: skip
    """Relay-feedback experiment around 0 rad/s -> ultimate gain/period -> Ziegler-Nichols speed PI."""
    from bench.tuning import tune_speed

    params = _parse_params(param)
    if amplitude is not None:
        params["relay_amplitude"] = amplitude
    if hysteresis is not None:
        params["relay_hysteresis"] = hysteresis
    res = tune_speed(rig, params=params, duration=duration, seed=seed, out_dir=out, progress=sys.stderr.isatty(),
                     realtime=realtime, allow_soft_realtime=allow_soft_realtime,
                     live=_live(live, live_port, live_host, live_rate))  # fmt: skip
    click.echo(json.dumps(res, indent=2, default=str))
    if "tripped" in res:
        _report_end(res["run"], res["exit_code"])
        return res["exit_code"]
    for w in res["relay"]["warnings"]:
        click.echo(f"bench: warning: {w}", err=True)
    click.echo(f"bench: to run with these gains: {res['command']}", err=True)
    return 0


def _rotating_options(f: Callable) -> Callable:
    f = click.option("--rotating-param", "-r", multiple=True, metavar="NAME=VALUE",
                     help="rotating_id parameter, repeatable")(f)  # fmt: skip
    return click.option("--rotating", is_flag=True,
                        help="after the standstill test, the rotating tests (a FREE shaft: it turns up to 0.8 x the "
                             "over-speed limit): L_m at the rated flux and its curve, J, friction")(f)  # fmt: skip


@cli.command()
@click.option("--rig", default="mock", show_default=True, help="rig name (rigs/NAME.toml) or rig-file path")
@click.option("--voltages", type=click.Choice(["measured", "reference"]), default=None,
              help="voltages the fits use: the filtered measurement, or the inverter reference (no voltage sensing) "
                   "[default: measured; with --from-log: the recorded run's]")  # fmt: skip
@click.option("--seed", type=int, default=0, show_default=True, help="random seed (noise)")
@_pacing_options
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="standstill_id parameter, repeatable")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("runs"), show_default=True,
              help="folder for the run folder (log, identify.json, plots)")  # fmt: skip
@click.option("--write", is_flag=True, help="write L_s = L_r, L_m, R_s, R_r into the rig file's [motor] (backup kept)")
@click.option("--from-log", "from_log", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="re-estimate from a recorded identification log (run.mcap) instead of running the test; "
                   "-p takes only dc_fit_from then")  # fmt: skip
@click.option("--log-buffer", type=FINITE, default=10.0, show_default=True, metavar="SECONDS",
              help="seconds of ticks the log ring holds (a writer stall this long loses nothing)")
@click.option("--json", "as_json", is_flag=True,
              help="the whole result as JSON on stdout, also on a terminal (the default where stdout is a pipe or a "
                   "file; a terminal gets a short table, the JSON is in the run folder's identify.json)")  # fmt: skip
@_rotating_options
def identify(rig: str, voltages: str | None, seed: int, realtime: bool | None, allow_soft_realtime: bool,
             param: tuple[str, ...], out: Path, write: bool, from_log: Path | None, log_buffer: float,
             as_json: bool, rotating: bool, rotating_param: tuple[str, ...]) -> int:  # fmt: skip
    """Standstill identification (thesis 3.6): DC test -> R_s and the inverter error, multisine -> the motor's
    inverse-Gamma and L_s = L_r parameters, with 95 % intervals. On a terminal a table of the identified
    motor (value, 95 % interval, unit) and the warnings; piped, or with --json, the whole result as JSON on
    stdout (as scripts read it); either way in identify.json in the run folder. Exit 1 when the test trips
    or the result is refused as implausible (the reasons on stderr; nothing written)."""
    from bench.commission import identify as ident

    params = _parse_params(param)
    rotating_params = _parse_params(rotating_param, "--rotating-param")
    if from_log is not None:
        if write:
            raise BadInput("--write", "not with --from-log: a re-estimate writes no rig file; run the test on the rig")
        if rotating:
            raise BadInput("--rotating", "not with --from-log (re-fit a rotating log with "
                           "bench.commission.rotating_fit.analyse_log)")  # fmt: skip
        ident.check_rotating(rotating, voltages or "measured", rotating_params)  # no -r without --rotating
        extra = sorted(set(params) - {"dc_fit_from"})
        if extra:
            raise BadInput("--param", f"with --from-log only dc_fit_from is allowed (the rest describes the recorded "
                           f"test), got {', '.join(extra)}")  # fmt: skip
        res = ident.from_log(from_log, out, voltages=voltages, dc_fit_from=params.get("dc_fit_from"))
    else:
        res = ident.identify(rig, voltages=voltages or "measured", params=params, seed=seed, out_dir=out,
                             progress=sys.stderr.isatty(), realtime=realtime, allow_soft_realtime=allow_soft_realtime,
                             write=write, log_buffer=log_buffer, rotating=rotating,
                             rotating_params=rotating_params)  # fmt: skip
    # a pipe or a file keeps getting the JSON it always got (scripts parse it); a person at a terminal the table
    table = not as_json and sys.stdout.isatty()
    if table and "tripped" in res:
        click.echo(f"the identification stopped: {res['tripped']}; the run: {res['run'].get('summary')}")
    elif table:
        click.echo(ident.summary_table(res))  # the warnings and refusals are in it
    else:
        click.echo(json.dumps(res, indent=2, default=str))
    if "tripped" in res:
        _report_end(res["run"], res["exit_code"])
        return res["exit_code"]
    for w in res["warnings"] if not table else ():
        click.echo(f"bench: warning: {w}", err=True)
    for r in res["refused"] if not table else ():
        click.echo(f"bench: REFUSED: {r}", err=True)
    return 1 if res["refused"] or (write and not res.get("written")) else 0  # refused, or asked to write and refused


@cli.command()
@click.option("--rig", required=True, help="rig name (rigs/NAME.toml) or rig-file path; its [motor] is written on GO")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="report folder (new or empty): report.md, commission.json, the runs, the artifacts, PNGs")
@click.option("--voltages", type=click.Choice(["measured", "reference"]), default="measured", show_default=True,
              help="voltages the identification uses")
@click.option("--rated-speed", "rated", type=FiniteRange(1.0, 5000.0), default=None,
              help="top of the check's speed ramp [rad/s, electrical] (default: 0.75 x the over-speed limit, "
                   "capped by the voltage)")  # fmt: skip
@click.option("--current-rate", type=click.Choice(["600", "1000", "1500", "3000"]), default="600", show_default=True,
              help="rate of the quasi-LPV current controller [Hz] (thesis 6.2.2: 600)")
@click.option("--seed", type=int, default=0, show_default=True, help="random seed (noise of the mock rig)")
@click.option("--dry-run", is_flag=True, help="do everything but write the rig file")
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="standstill_id parameter, repeatable")
@click.option("--judge", type=click.Choice(["rig", "truth"]), default="rig", show_default=True,
              help="rig: GO decided by what a real rig measures (the mock's truth withheld); truth: the mock's flux "
                   "truth judged as well")  # fmt: skip
@click.option("--skip-identify", is_flag=True, help="no identification: design for and check the rig file's [motor] "
              "as it is (nothing is written)")  # fmt: skip
@_rotating_options
@click.option("--standstill-only", is_flag=True, help="no rotating test even where the shaft may turn: the result is "
              "provisional (L_m from the standstill test)")  # fmt: skip
@_pacing_options
def commission(rig: str, out: Path, voltages: str, rated: float | None, current_rate: str, seed: int, dry_run: bool,
               param: tuple[str, ...], judge: str, skip_identify: bool, rotating: bool, rotating_param: tuple[str, ...],
               standstill_only: bool, realtime: bool | None, allow_soft_realtime: bool) -> int:  # fmt: skip
    """Nameplate to verified closed loop: identify the motor (standstill, then rotating wherever the shaft may turn:
    the mock and emulated rigs, and a rig whose file says free_shaft = true), synthesise and verify the LPV flux
    observer and the quasi-LPV current controller for it, check them in closed loop, report GO / NO-GO (exit 0 / 1)
    and on GO write [motor] into the rig file (backup kept). The rig file needs the motor's [nameplate]."""
    from bench.commission.commission import commission as run_commission

    if rotating and standstill_only:
        raise BadInput("--standstill-only", "not with --rotating")
    say = stages("commission")
    with summarised_warnings("commission", checked=VERIFIED):
        rep, code = run_commission(rig, out, voltages=voltages, ident_params=_parse_params(param), rated=rated,
                                   rotating=True if rotating else False if standstill_only else None,
                                   rotating_params=_parse_params(rotating_param, "--rotating-param"),
                                   current_rate=float(current_rate), seed=seed, dry_run=dry_run, realtime=realtime,
                                   allow_soft_realtime=allow_soft_realtime, progress=sys.stderr.isatty(),
                                   say=say, judge=judge, skip_identify=skip_identify)  # fmt: skip
    click.echo(json.dumps({k: rep.get(k) for k in ("verdict", "go", "provisional", "report", "json", "candidate_rig",
                                                   "written", "run_command", "wall_time_s", "warnings", "stages")},
                          indent=2, default=str))
    for w in rep.get("warnings") or ():  # every stage's (also in report.md)
        click.echo(f"bench: warning: {w}", err=True)
    if "run" in rep:
        _report_end(rep["run"], code)
    click.echo(f"bench: commission: {rep['verdict']} (report: {rep['report']})", err=True)
    return code


@perf.command("commission")
@click.option("--motors", type=click.IntRange(1, 200), default=5, show_default=True,
              help="hidden motors (the first of bench perf identify's draw)")
@click.option("--motors-seed", type=int, default=0, show_default=True, help="seed of the motor draw")
@click.option("--seed", type=int, default=0, show_default=True, help="noise seed of every run")
@click.option("--rotating", is_flag=True, help="bench commission --rotating (L_m at the rated flux from the no-load test)")
def perf_commission(motors: int, motors_seed: int, seed: int, rotating: bool) -> None:
    """Commissioned vs true: bench commission on hidden mock motors, then the same designs for the true
    parameters; Fig. 5.7's experiment with both (flux-angle and speed-tracking errors against the truth)."""
    from bench.commission.versus_true import benchmark

    with summarised_warnings("perf commission", checked=VERIFIED):
        res = benchmark(motors, motors_seed, seed, rotating, say=stages("perf commission"))
    _perf_echo(res)


@perf.command("narx")
@click.option("--samples", type=click.IntRange(100, 1_000_000), default=22000, show_default=True,
              help="samples per data set at 600 Hz")
@click.option("--max-nfev", type=click.IntRange(1, 1_000_000), default=3000, show_default=True, help="LM evaluation budget")
def perf_narx(samples: int, max_nfev: int) -> None:
    """Wall time of `collect narx` (training + validation set) and `train narx` on the mock rig (lockstep)."""
    from bench.narx import benchmark

    click.echo(json.dumps(benchmark(samples, max_nfev), indent=2, default=float))


@cli.group()
def synth() -> None:
    """Design LPV controllers (synthesis + independent verification) and save them as artifacts."""


def _check_artifact(out: Path, force: bool) -> None:
    """An artifact is OUT.npz + OUT.json: both checked before the work starts."""
    for suffix in (".npz", ".json"):
        check_output("--out", Path(str(out) + suffix), force)


@synth.command("flux-observer")
@click.option("--omega-max", type=FiniteRange(1.0, 2000.0), default=400.0, show_default=True,
              help="largest |omega_r| the observer is scheduled for [rad/s, electrical] (default: the rigs' "
                   "over-speed limit; gamma does not grow with it)")
@click.option("--discretisation", type=click.Choice(["full", "thesis"]), default="full", show_default=True,
              help="reading of 5.6.1: full = the whole plant through D_bl (optimum 1.96e-5, reached); "
                   "thesis = only (5.79) through D_bl, outputs from x_k (optimum >= 9.96e-5)")
@click.option("--rate", type=FiniteRange(100.0, 100_000.0), default=3000.0, show_default=True,
              help="sample rate [Hz]")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="artifact path without suffix (default: runs/artifacts/flux_observer_<omega-max>rad_<rate>Hz)")
@click.option("--rig", default="mock", show_default=True,
              help="rig whose nominal [motor] the design uses (rigs/NAME.toml or a path)")
@click.option("--force", is_flag=True, help="overwrite an existing artifact")
def synth_flux_observer(omega_max: float, discretisation: str, rate: float, out: Path | None, rig: str,
                        force: bool) -> None:  # fmt: skip
    """LPV flux observer of thesis 5.6.2 (gamma = 1.1 gamma_a), verified, saved as npz + JSON with the
    independent lower bound on gamma (gamma_lower_bound, gap)."""
    tail = "" if discretisation == "full" else f"_{discretisation}"
    out = out or Path("runs") / "artifacts" / f"flux_observer_{omega_max:g}rad_{rate:g}Hz{tail}"
    _check_artifact(out, force)
    from bench.synth import flux_observer
    with summarised_warnings("flux observer", checked=VERIFIED):
        info = flux_observer(omega_max, rate, out, rig=rig, discretisation=discretisation,
                             progress=stages("flux observer"))  # fmt: skip
    click.echo(json.dumps(info, indent=2, default=float))


@synth.command("current-controller")
@click.option("--rate", type=FiniteRange(100.0, 100_000.0), default=600.0, show_default=True,
              help="sample rate [Hz] (thesis 6.2.2: 600 Hz)")
@click.option("--discretisation", type=click.Choice(["causal", "full"]), default="causal", show_default=True,
              help="causal: y, z_p from the sampled state; full: D_bl * M of the whole plant (u_k reaches y_k)")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="artifact path without suffix (default: runs/artifacts/current_controller_<rate>Hz)")
@click.option("--rig", default="mock", show_default=True,
              help="rig whose nominal [motor] the design uses (rigs/NAME.toml or a path)")
@click.option("--input-delay", "input_delay", type=FiniteRange(0.0, 1.0), default=0.0, show_default=True,
              help="computation delay in the design model, fraction of a sample (0.2 = one 3 kHz tick at 600 Hz)")
@click.option("--prewarp", type=FiniteRange(1.0, 1e6), default=None, help="prewarp the causal Tustin at this [rad/s]")
@click.option("--rescale", type=click.Choice(["diagonal", "full"]), default="diagonal", show_default=True,
              help="gamma bisection's re-balancing: diagonal (the shipped artifacts) or full (from the lower bound: "
                   "the LMIs' optimum; at 3 kHz worse on the mock rig, see docs/results/synthesis.md 4.0)")
@click.option("--force", is_flag=True, help="overwrite an existing artifact")
def synth_current_controller(rate: float, discretisation: str, out: Path | None, rig: str, input_delay: float,
                             prewarp: float | None, rescale: str, force: bool) -> None:  # fmt: skip
    """Quasi-LPV stator current controller of thesis 6.2.2 (gamma = 1.1 gamma_a), verified, saved as npz + JSON."""
    out = out or Path("runs") / "artifacts" / f"current_controller_{rate:g}Hz"
    _check_artifact(out, force)
    from bench.synth import current_controller
    with summarised_warnings("current controller", checked=VERIFIED):
        info = current_controller(rate, out, discretisation=discretisation, rig=rig, input_delay=input_delay,
                                  prewarp=prewarp, rescale=rescale, progress=stages("current controller"))
    click.echo(json.dumps(info, indent=2, default=float))


@synth.command("speed-controller")
@click.option("--model", "model_path", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="NARX model artifact of `bench train narx` (path without suffix)")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="artifact path without suffix (default: runs/artifacts/speed_controller[_robust]_600Hz)")
@click.option("--rig", default="mock", show_default=True, help="rig whose nominal [motor] the i_mR observer (6.29) uses")
@click.option("--gains", "n_gains", type=int, default=2, show_default=True,
              help="residual gains kept (largest sector widths; thesis: 2)")
@click.option("--filter", "filter_reading", type=click.Choice(["dc", "pole"]), default="dc", show_default=True,
              help="5 Hz performance filter: dc = w_p/(s+w_p), pole = 1/(s+w_p)")
@click.option("--robust", is_flag=True, help="the robust controller of 7.2 (epsilon iteration, Thm 7.1)")
@click.option("--e-bar", "e_bar", default="model", show_default=True,
              help="robust: scheduling-error bound: model (6.3.3 for --noise), thesis (3.1 %, 2.5 %) or a,b")
@click.option("--noise", type=FiniteRange(0.0, 100.0), default=0.5, show_default=True,
              help="speed-measurement noise [rad/s]: the setup's noise weight and the model e_bar")
@click.option("--force", is_flag=True, help="overwrite an existing artifact")
def synth_speed_controller(model_path: Path, out: Path | None, rig: str, n_gains: int, filter_reading: str,
                           robust: bool, e_bar: str, noise: float, force: bool) -> None:  # fmt: skip
    """LPV speed controller of thesis 6.4.3 (or the robust one of 7.2) for a NARX model, verified, saved as npz + JSON."""
    out = out or Path("runs") / "artifacts" / f"speed_controller{'_robust' if robust else ''}_600Hz"
    _check_artifact(out, force)
    from bench.synth import speed_controller
    with summarised_warnings("speed controller", checked=VERIFIED):
        info = speed_controller(model_path, out, rig=rig, n_gains=n_gains, filter_reading=filter_reading,
                                robust=robust, e_bar=e_bar, noise_rad_s=noise,
                                progress=stages("speed controller"))  # fmt: skip
    click.echo(json.dumps(info, indent=2, default=float))
    click.echo(f"bench: note (speed controller): {info['note']}", err=True)


@cli.group()
def collect() -> None:
    """Identification experiments: run an excitation on a rig and log the data set (MCAP)."""


@collect.command("narx")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True, help="MCAP log to write")
@click.option("--seed", type=int, default=0, show_default=True, help="seed of the random references and dither")
@click.option("--samples", type=int, default=22000, show_default=True, help="data-set samples at --sample-hz")
@click.option("--sample-hz", type=FINITE, default=600.0, show_default=True,
              help="data-set rate (a divisor of the loop rate; thesis 600 Hz)")
@click.option("--rig", default="mock", show_default=True, help="rig name (rigs/NAME.toml) or rig-file path")
@_pacing_options
@_live_options
@click.option("--force", is_flag=True, help="overwrite an existing --out file")
@click.option("--param", "-p", multiple=True, metavar="NAME=VALUE", help="excitation-controller parameter, repeatable")
@click.option("--no-progress", is_flag=True, help="no progress bar")
def collect_narx(out: Path, seed: int, samples: int, sample_hz: float, rig: str, realtime: bool | None,
                 allow_soft_realtime: bool, live: bool, live_port: int, live_host: str, live_rate: float, force: bool,
                 param: tuple[str, ...], no_progress: bool) -> int:  # fmt: skip
    """NARX excitation of thesis 6.4.2: random speed and i_mR steps, loose PI, dithered current refs, load 6.4.1."""
    from bench.daq.narx import NarxExperiment
    from bench.narx import collect as run_collect

    params = _parse_params(param)
    if "seed" in params:
        raise BadInput("--param seed", "use --seed")
    exp = NarxExperiment(seed=seed, samples=samples, sample_hz=sample_hz, controller=params)
    summary, code = run_collect(exp, out, rig=rig, realtime=realtime, allow_soft_realtime=allow_soft_realtime,
                                force=force, live=_live(live, live_port, live_host, live_rate),
                                progress=not no_progress and sys.stderr.isatty())  # fmt: skip
    keys = ("ticks", "duration", "wall_time", "realtime_factor", "deadline_misses", "trip_cause", "log", "plot", "summary")
    click.echo(json.dumps({**{k: summary.get(k) for k in keys}, "narx": summary["narx"]["dataset"]}, indent=2))
    _report_end(summary, code)
    return code


@cli.group()
def train() -> None:
    """Identify models from collected data sets."""


@train.command("narx")
@click.option("--train", "train_log", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="training-set log (bench collect narx)")
@click.option("--val", "val_log", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="validation-set log (another seed)")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="model artifact path without suffix: writes OUT.npz, OUT.json and OUT_report/")
@click.option("--neurons", type=int, default=4, show_default=True, help="tanh neurons in the hidden layer")
@click.option("--n", "n", type=int, default=4, show_default=True, help="past speeds in the regressor")
@click.option("--n-i", "n_i", type=int, default=1, show_default=True, help="past i_mR estimates")
@click.option("--n-u", "n_u", type=int, default=2, show_default=True, help="past values of i_sd,ref and i_tau each")
@click.option("--max-nfev", type=int, default=3000, show_default=True, help="LM evaluation budget")
@click.option("--init-scale", type=FINITE, default=1e-3, show_default=True, help="size of Theta_1 at the ARX start")
@click.option("--init-spread", type=FINITE, default=1.0, show_default=True,
              help="relative difference between the neurons at the ARX start")
@click.option("--init-seed", type=int, default=0, show_default=True, help="seed of that difference")
@click.option("--noise", type=FINITE, default=0.5, show_default=True, help="speed-noise bound for 6.3.3 [rad/s]")
@click.option("--search", is_flag=True, help="also train a small grid of neuron counts and orders")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="report folder (default OUT_report)")
@click.option("--force", is_flag=True, help="overwrite an existing model")
def train_narx(train_log: Path, val_log: Path, out: Path, neurons: int, n: int, n_i: int, n_u: int, max_nfev: int,
               init_scale: float, init_spread: float, init_seed: int, noise: float, search: bool,
               report_dir: Path | None, force: bool) -> None:  # fmt: skip
    """ARX + LM-trained MLP (6.4.2), validation report, MLP -> quasi-LPV LFT (6.3); prints JSON."""
    from bench.narx import train as run_train

    if not 0 <= noise < 1000:
        raise BadInput("--noise", f"must be in [0, 1000) rad/s, got {noise}")
    _check_artifact(out, force)
    with summarised_warnings("train narx"):
        summary = run_train(train_log, val_log, out, neurons=neurons, n=n, n_i=n_i, n_u=n_u, max_nfev=max_nfev,
                            init_scale=init_scale, init_spread=init_spread, init_seed=init_seed, noise_rad_s=noise,
                            search=search, report_dir=report_dir, progress=stages("train narx"))  # fmt: skip
    click.echo(json.dumps(summary, indent=2, default=float))


@cli.group()
def pipeline() -> None:
    """Whole chains in one command."""


@pipeline.command("narx-speed")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("runs/pipeline-narx-speed"),
              show_default=True, help="folder for data, models, controllers, report.{json,md} and PNGs")
@click.option("--samples", type=int, default=22000, show_default=True, help="samples per data set at 600 Hz")
@click.option("--seed", type=int, default=1, show_default=True, help="training-set seed (validation: seed + 1)")
@click.option("--max-nfev", type=int, default=3000, show_default=True, help="LM evaluation budget per candidate")
@click.option("--spreads", default="1.0,0.3,0.1", show_default=True,
              help="initialisation spreads of the candidate MLPs (comma-separated)")
@click.option("--rig", default="mock", show_default=True, help="rig name (rigs/NAME.toml) or rig-file path")
@click.option("--quick", is_flag=True, help="small version: 4000 samples, 300 LM evaluations, one candidate")
@click.option("--no-robust", is_flag=True, help="skip the robust controller of 7.2")
@_dask_options
def pipeline_narx_speed(out: Path, samples: int, seed: int, max_nfev: int, spreads: str, rig: str, quick: bool,
                        no_robust: bool, workers: int | None, scheduler: str | None) -> None:  # fmt: skip
    """collect -> train -> LFT -> select -> synthesise -> verify -> closed loop -> report (6.4, 7.2)."""
    try:
        sp = tuple(float(v) for v in spreads.split(","))
    except ValueError:
        raise BadInput("--spreads", f"comma-separated numbers, got {spreads!r}") from None
    if not 1 <= max_nfev <= 1_000_000:
        raise BadInput("--max-nfev", f"must be in [1, 1000000], got {max_nfev}")
    workers = _workers(workers, scheduler)
    say = stages("pipeline")
    from bench.pipeline import run_pipeline
    with summarised_warnings("pipeline", checked=VERIFIED):
        r = run_pipeline(out, samples=samples, seeds=(seed, seed + 1), max_nfev=max_nfev, spreads=sp, rig=rig,
                         quick=quick, robust=not no_robust, progress=say, workers=workers,
                         scheduler=scheduler)  # fmt: skip
    click.echo(json.dumps({"report": str(out / "report.md"), "selected": r["selected"],
                           "gamma": {k: r["nominal"][k] for k in ("gamma_a", "gamma", "gamma_lti")},
                           "timings_s": r["timings_s"]}, indent=2, default=float))  # fmt: skip


@cli.command()
@click.option("--rig", default="emulated", show_default=True, help="rig file with rig.driver = \"drivers\"")
@click.option("--seed", type=int, default=None, help="plant noise seed (default: emulator.seed of the rig file)")
@click.option("--duration", type=FiniteRange(0.0, 1e6, min_open=True), default=None,
              help="stop after this many seconds (default: until Ctrl-C)")  # fmt: skip
def emulate(rig: str, seed: int | None, duration: float | None) -> int:
    """Run the rig's device emulators (CAN, serial, Modbus TCP on 127.0.0.1) until Ctrl-C."""
    import time

    from bench.config import load as load_rig
    from mock_hw.emulators import publish_token, remove_stale_tokens, start_emulator, withdraw_token

    cfg = load_rig(rig)
    if cfg.driver != "drivers":
        raise BadInput("rig.driver", f"bench emulate needs a driver rig (driver = \"drivers\"), got {cfg.driver!r}")
    remove_stale_tokens()  # the secrets of emulators that were killed (kill -9 leaves its file behind)
    emu = start_emulator(cfg, seed=cfg.hw["emulator"]["seed"] if seed is None else seed, realtime=True)
    try:
        publish_token(emu)  # this user's `bench run` attaches to this emulator only (autostart = "auto")
    except BaseException:
        emu.close()
        raise
    host = emu.host_config().hw
    click.echo(json.dumps({"emulating": cfg.name, "can": {"interface": host["can"]["interface"],
                                                          "channel": host["can"]["channel"]},
                           "serial": host["serial"]["port"],
                           "modbus": f"{host['modbus']['host']}:{host['modbus']['port']}"}), err=False)  # fmt: skip
    sys.stdout.flush()
    try:
        end = None if duration is None else time.monotonic() + duration
        while end is None or time.monotonic() < end:
            time.sleep(0.1 if end is None else max(0.0, min(0.1, end - time.monotonic())))
    except Interrupted:  # Ctrl-C, SIGTERM: close the emulators, print the statistics
        pass
    finally:
        stats = dict(emu.stats)
        withdraw_token(emu)
        emu.close()
    click.echo(json.dumps({"stats": stats}))
    # everything is closed; should a library thread still block the interpreter's exit (seen after
    # busy real-time sessions), leave anyway after 5 s
    import os
    import threading

    guard = threading.Timer(5.0, os._exit, args=(0,))
    guard.daemon = True
    guard.start()
    return 0


@cli.command()
@click.option("--rig", required=True, help="rig file to calibrate (its [frontend] offsets are rewritten)")
@click.option("--samples", type=click.IntRange(10, 1_000_000), default=3000, show_default=True,
              help="samples to average")  # fmt: skip
@click.option("--dry-run", is_flag=True, help="measure and print, do not write the rig file")
def calibrate(rig: str, samples: int, dry_run: bool) -> int:
    """Measure the ADC offsets at standstill, inverter disabled, and write them to the rig file (a backup beside
    it; exit 1 with the offsets printed if the file changed meanwhile or cannot be replaced)."""
    from bench.commission.calibrate import calibrate as run_calibration

    result = run_calibration(rig, samples=samples, write=not dry_run)
    click.echo(json.dumps(result, indent=2))
    if "not_written" in result:
        click.echo(f"bench: {result['not_written']}", err=True)
        return 1
    return 0


def main(argv: list[str] | None = None) -> None:
    """Entry point: exit codes 0 ok, 1 tripped/failed, 2 bad input, 3 internal error, 4 no answer from a live
    session (bench set/switch/stop/estop/mark: not known whether it was applied), 128 + signal.

    SIGINT/SIGTERM/SIGHUP raise `bench.shutdown.Interrupted` (not KeyboardInterrupt, which click
    and some libraries turn into something else); a session replaces this with its own handling.
    A command past a commit point (`bench.shutdown.commit_section`: the rig file replaced) is not
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
