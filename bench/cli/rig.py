"""The commands at the rig: `bench run`, the live session's `set`/`switch`/`stop`/`estop`/`mark`, `layout`,
`scenarios`, `controllers`, `plot`, `inspect`, `emulate` and `calibrate`."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import click

from bench.errors import BadInput, clip, clip_repr
from bench.core.outputs import check_output, free_path
from bench.operate.live_client import APPLIED, EXIT_CODES, REFUSED, request, call
from bench.core.scenarios import SCENARIOS, arguments
from bench.core.shutdown import (Interrupted)

from bench.cli.common import (
    FINITE, FiniteRange, OutFile, _live, _live_options, _pacing_options, _parse_params, _parse_scenario_args, _report_end,
    cli,
)  # fmt: skip


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
    from bench.runtime.session import RunOptions
    from bench.runtime.session import run as run_session

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
    """One answer of a live session printed (`bench.operate.live_client.request`): applied -> the lines of
    ``applied(ans)`` (exit 0), refused -> one line with the reason (exit 2), unknown -> one line saying so (exit 4)."""
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
    from bench.operate.foxglove_layout import layout_json

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
    from bench.operate.requests import switch_names

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


@cli.command()
@click.option("--rig", default="emulated", show_default=True, help="rig file with rig.driver = \"drivers\"")
@click.option("--seed", type=int, default=None, help="plant noise seed (default: emulator.seed of the rig file)")
@click.option("--duration", type=FiniteRange(0.0, 1e6, min_open=True), default=None,
              help="stop after this many seconds (default: until Ctrl-C)")  # fmt: skip
def emulate(rig: str, seed: int | None, duration: float | None) -> int:
    """Run the rig's device emulators (CAN, serial, Modbus TCP on 127.0.0.1) until Ctrl-C."""
    import time

    from bench.core.config import load as load_rig
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
    from bench.workflows.commission.calibrate import calibrate as run_calibration

    result = run_calibration(rig, samples=samples, write=not dry_run)
    click.echo(json.dumps(result, indent=2))
    if "not_written" in result:
        click.echo(f"bench: {result['not_written']}", err=True)
        return 1
    return 0
