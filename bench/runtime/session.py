"""One bench session: rig file + controller + scenario -> timed loop -> MCAP log, summary, plot.

Its rig and controller come from the composition root, `bench.runtime.compose`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench import controllers

from bench.core import nameplate, scenarios

from bench.runtime import jit_warm
from bench.core.config import RigConfig, is_real_rig
from bench.core.config import load as load_rig
from bench.controllers.base import Controller
from bench.daq import LogReader, LogWriter, Topic, code_version
from bench.daq.memory import MemoryLog
from bench.errors import BadInput
from bench.core.outputs import check_output, free_room, new_folders, remove_empty, reserve_room
from bench.hal import Rig
from bench.core.jit_cache import take_notes
from bench.runtime.run_summary import (LOG_CLOSE_TIMEOUT, close_log, log_kept, one_line, stall_report, summarize,
                                       summary_time, true_R_r, write_summary_and_plot)  # fmt: skip
from bench.runtime.loop import LoopResult, TimedLoop, log_topics
from bench.core.rt_host import realtime_setup, realtime_teardown, save_sched
from bench.core.scenarios import Scenario
from bench.core.setpoints import Margins
from bench.core.shutdown import (EXIT_OK, EXIT_TRIP, Interrupted, SignalGuard, pause_for_test, signal_cause,
                                 signal_exit_code, child_context, spawning, child_ignores_signals)
from bench.core.supervisor import Supervisor
from bench.runtime.metrics import voltage_limit_warning
from bench.daq.replay import read_requests, read_stalls
from bench.daq.live import PANEL_FIELDS, panel_text, switch_codes, stream_every
from bench.daq.writer_process import PANEL
from bench.runtime.fault_injection import inject, describe
from bench.drivers import canlog
from bench.operate.operator import controller_param, prepared_controllers, Operator
from bench.runtime.compose import build_rig, make_controller
from bench.operate.requests import ParamSpace, scheduled, merged

LOG_RESERVE_TICKS = 256  # log ring rows kept for the trip and the coast-down after a log fault (> POST_TRIP)


@dataclass
class RunOptions:
    """What `run` does: the options of `bench run`, as fields with their defaults.

    Attributes
    ----------
    rig : str | RigConfig
        A rig name (``rigs/NAME.toml``) or file, or a `RigConfig` built by the caller (``bench sweep``).
    controller : str
        The controller plugin (``bench controllers``).
    scenario : str | Scenario
        A scenario name (``bench scenarios``), or a `Scenario` built by the caller.
    scenario_args : dict[str, float]
        A parameterised scenario's arguments (``load-step``: ``speed``, ``load``); its defaults where left out.
    duration : float | None
        Run length [s]; None: the scenario's.
    realtime : bool | None
        Pace by the wall clock; None: real time on a rig with real devices, lockstep otherwise.
    allow_soft_realtime : bool
        A real rig without SCHED_FIFO runs anyway (recorded in the summary).
    seed : int
        Random seed of the mock rig's noise.
    params : dict
        Controller parameters (``-p NAME=VALUE``), checked against the plugin's schema.
    log, summary, plot : Path | None
        Output files; None: ``run.mcap``, ``summary.json``, ``run.png`` in a new run folder under `out_dir`
        (with `log` given, the others sit beside it).
    out_dir : Path
        Where run folders are made.
    force : bool
        Overwrite existing log, summary or plot files.
    progress : bool
        Draw the progress bar (stderr).
    log_enabled : bool
        False: keep the per-tick record in memory only (no MCAP, no plot; ``summary["record"]``).
    log_buffer : float
        Seconds of ticks the log ring holds: a writer stall this long loses nothing.
    can_log : Path | None
        Every CAN frame into this file (python-can's can.logger; driver rigs).
    live_port : int | None
        Serve the run live (Foxglove WebSocket) on this port; 0: any free port; None: no live server.
    live_host : str
        The live server's address (no authentication: loopback unless asked).
    live_rate : float
        Rate of /rig, /ctrl, /truth on the live stream [Hz].
    replay_params : Path | None
        Re-apply this log's parameter changes and operator actions at the same ticks.
    switches : tuple
        Parts switched while running, (t [s], part, choice) each, after the scenario's own (`Scenario.switches`).
    metadata : dict
        Extra log metadata records.
    label : str
        What the progress bar says.
    inject_fault : str | None
        A fault injected on purpose to test a trip path (`bench.runtime.fault_injection`: ``over-speed``); mock and
        emulated rigs only.
    """

    rig: str | RigConfig = "mock"  # a rig name or file, or a RigConfig built by the caller (bench sweep)
    controller: str = "foc"
    scenario: str | Scenario = "demo"  # a name in bench.core.scenarios, or a Scenario built by the caller
    scenario_args: dict[str, float] = field(default_factory=dict)  # a parameterised scenario's (scenarios.arguments)
    duration: float | None = None  # default: the scenario's
    realtime: bool | None = None  # None: real time on a rig with real devices, lockstep otherwise
    allow_soft_realtime: bool = False  # a real rig without SCHED_FIFO runs anyway (recorded)
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)  # controller parameters
    log: Path | None = None
    summary: Path | None = None
    plot: Path | None = None
    out_dir: Path = Path("runs")
    force: bool = False  # overwrite existing --log/--summary/--plot files
    progress: bool = True
    log_enabled: bool = True  # False: keep the per-tick record in memory only (no MCAP, no plot)
    log_buffer: float = 10.0  # [s] of ticks the log ring holds: a writer stall this long loses nothing
    can_log: Path | None = None  # every CAN frame into this file (python-can's can.logger, bench.drivers.canlog)
    live_port: int | None = None  # serve the run live (Foxglove WebSocket, bench.daq.live); 0: any free port
    live_host: str = "127.0.0.1"  # the protocol has no authentication: loopback unless asked
    live_rate: float = 100.0  # [Hz] of /rig, /ctrl, /truth on the live stream
    # re-apply this log's parameter changes and operator actions (bench.operate.operator)
    replay_params: Path | None = None
    switches: tuple[tuple[float, str, str], ...] = ()  # parts switched while running, after the scenario's own
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)  # extra log metadata records
    label: str = "bench run"  # what the progress bar says (bench collect narx, bench tune speed, ...)
    # lockstep only (bench perf stall, tests): {loop time [s]: stall [s]}, the ticks a stalled real-time loop skips
    inject_stalls: dict[float, float] = field(default_factory=dict)
    # a fault injected on purpose (bench.runtime.fault_injection; mock and emulated rigs)
    inject_fault: str | None = None





COMPILED_FROM = 25.0  # [s] of simulated time from which the compiled engines pay their start-up (mock_hw.plant)


def default_engines(cfg: RigConfig, controller: str, params: dict[str, Any], duration: float,
                    realtime: bool) -> tuple[RigConfig, dict[str, Any], str | None]:  # fmt: skip
    """The fastest engines that give the same results, where the run does not choose: the compiled mock plant and
    FOC tick ("auto": bit-identical to the Python reference, where numba imports and the configuration is covered)
    for a real-time run (less compute per tick: fewer deadline misses) and from `COMPILED_FROM` seconds of simulated
    time (numba's import and cached code, about 0.8 s at start, are then paid back). Shorter lockstep runs start
    faster on the reference. A rig file's ``[mock] engine`` and a ``-p engine=...`` are kept as they are.

    The compiled engines are taken only when numba's cache holds them (`bench.runtime.jit_warm.is_warm`): after an
    install or an update they would first compile for about a minute before the first tick. Then this run keeps the
    Python engines (the same results), a background process compiles them for the next run, and the third value is the
    note that says so (else None)."""
    if not (realtime or duration >= COMPILED_FROM) or importlib.util.find_spec("numba") is None:
        return cfg, params, None
    cls = controllers.available().get(controller)
    auto_ctrl = "engine" in getattr(cls, "schema", {}) and "engine" not in params
    auto_plant = cfg.driver == "mock" and "engine" not in cfg.mock
    if not (auto_ctrl or auto_plant):
        return cfg, params, None

    if not jit_warm.is_warm():
        started = jit_warm.warm_in_background()
        return cfg, params, ("the compiled engines are not in numba's cache yet (once after an install or update): "
                             "this run uses the Python engines (the same results); "
                             + ("compiling them in the background for the next run" if started else
                                "another process is compiling them"))  # fmt: skip
    if auto_ctrl:
        params = {**params, "engine": "auto"}
    if auto_plant:
        cfg = dataclasses.replace(cfg, mock={**cfg.mock, "engine": "auto"})
    return cfg, params, None


def scenario_scaling(cfg: RigConfig) -> scenarios.Scaling | None:
    """How the scenarios are scaled to ``cfg``'s motor (`bench.core.nameplate.scaled`); None on the thesis motor."""
    k = nameplate.scaled(cfg.motor, cfg.nameplate)
    return None if k is None else scenarios.Scaling(k.speed, k.torque, k.i_mR)










def artifact_identity(value: str) -> str:
    """What an artifact parameter points at, for the run folder's hash: the content hash of the files it names
    (``path``, ``path.npz``, ``path.json``, those that exist), else its resolved path: two artifacts of one name
    in different folders, or one rebuilt in place, give different hashes."""
    import hashlib

    p = Path(value).expanduser()
    h = hashlib.sha1()
    found = False
    for f in (p, p.with_name(p.name + ".npz"), p.with_name(p.name + ".json")):
        try:
            if f.is_file():
                h.update(f.name.encode() + b"\0" + f.read_bytes())
                found = True
        except OSError:
            continue
    if found:
        return h.hexdigest()[:12]
    try:
        return str(p.resolve())
    except (OSError, RuntimeError):
        return value


def run_name(scenario: str, controller: str, params: dict[str, Any], seed: int) -> str:
    """``fig5.7-foc-speed_controller=lpv-lpv_speed_artifact=sc-seed0``: the changed parameters in the
    name, or (when they would make it longer than a file name should be) a short hash of them and of the
    artifacts' identities (`artifact_identity`: an artifact path shows only its file name)."""
    import hashlib
    import re

    changed = controllers.changed_params(controller, params)
    tail = "-".join(f"{k}={v}" for k, v in changed.items())
    if len(tail) > 80:
        ids = {k: artifact_identity(str(params[k])) for k in changed
               if isinstance(params.get(k), str) and (k.endswith("_artifact") or "/" in params[k] or "\\" in params[k])}
        digest = hashlib.sha1(json.dumps([changed, ids], sort_keys=True).encode()).hexdigest()[:8]
        tail = f"{len(changed)}params-{digest}"
    name = "-".join(part for part in (scenario, controller, tail, f"seed{seed}") if part)
    return re.sub(r"[^A-Za-z0-9._=+-]", "_", name)


def _run_folder(out_dir: Path, scn: Scenario, opts: RunOptions) -> Path:
    """A new folder per run: two runs started in the same second never share one. The name says what
    distinguishes the run: scenario, controller, the -p values that differ from the defaults."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = f"{stamp}-{run_name(scn.name, opts.controller, opts.params, opts.seed)}"
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput("--out", f"cannot create {out_dir}: {exc.strerror or exc}") from None
    for n in range(1, 1000):
        folder = out_dir / (base if n == 1 else f"{base}-{n}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue
        except OSError as exc:
            raise BadInput("--out", f"cannot create a run folder in {out_dir}: {exc.strerror or exc}") from None
    raise BadInput("--out", f"{out_dir} has 999 run folders named {base}*")


def _paths(opts: RunOptions, scn: Scenario) -> tuple[Path, Path, Path]:
    """(log, summary, plot) paths, checked; the run folder (without --log) is created here."""
    if opts.log is not None:
        base, log = opts.log.with_suffix(""), opts.log
        summary = opts.summary or base.with_name(base.name + ".summary.json")
        plot = opts.plot or base.with_name(base.name + ".png")
    else:
        for option, path in (("--summary", opts.summary), ("--plot", opts.plot)):
            if path is not None:
                check_output(option, path, opts.force)
        folder = _run_folder(opts.out_dir, scn, opts)
        log = folder / "run.mcap"
        summary, plot = opts.summary or folder / "summary.json", opts.plot or folder / "run.png"
    for option, path in (("--log", log), ("--summary", summary), ("--plot", plot)):
        check_output(option, path, opts.force)
    if len({log.resolve(), summary.resolve(), plot.resolve()}) < 3:
        raise BadInput("--log", f"log, summary and plot must be three different files, got {log}, {summary}, {plot}")
    return log, summary, plot


def _pacing(cfg: RigConfig, opts: RunOptions) -> bool:
    """Real time or lockstep; a real rig is always paced by the wall clock, with real-time scheduling."""
    real = is_real_rig(cfg)
    realtime = real if opts.realtime is None else opts.realtime
    if real and not realtime:
        raise BadInput("--lockstep", f"rig {cfg.name!r} drives real devices (emulator.autostart = \"never\"): "
                       "it runs in real time only")  # fmt: skip
    if real and not opts.allow_soft_realtime:
        saved = save_sched()
        applied = realtime_setup()
        realtime_teardown(saved)
        if not applied["sched_fifo"]:
            raise BadInput("--allow-soft-realtime", "SCHED_FIFO real-time scheduling cannot be applied here (needs "
                           "root or CAP_SYS_NICE); the loop would be late under load. Fix the permissions, or "
                           "pass --allow-soft-realtime to run anyway")  # fmt: skip
    return realtime








def open_log(path: Path, topics: list[Topic], metadata: dict[str, dict[str, Any]], *, realtime: bool,
             rate_hz: float, buffer_s: float = 10.0, on_fault: Any = None,
             attachments: list[tuple[str, str, bytes]] | None = None,
             live: dict[str, Any] | None = None, panel: bool = False,
             operator: dict[str, Any] | None = None) -> LogWriter:  # fmt: skip
    """The run's MCAP writer. Real time: the writer yields the CPU to the loop (nice 10), and the loop
    never waits for it (a full ring is a fault, i.e. a trip). Lockstep: the writer runs at normal
    priority and sets the pace (a put may wait up to 5 s for it), and put() is not timed (its cost is
    the tick's budget, and its timing tells nothing without a deadline)."""
    return LogWriter(path, topics, metadata=metadata, writer_nice=10 if realtime else 0,
                     max_wait=0.0 if realtime else 5.0, on_fault=on_fault, timing=realtime,
                     ring_ticks=int(buffer_s * rate_hz) + LOG_RESERVE_TICKS, reserve_ticks=LOG_RESERVE_TICKS,
                     close_timeout=LOG_CLOSE_TIMEOUT, attachments=attachments or (), live=live,
                     panel=panel, operator=operator)  # fmt: skip


def check_live_address(host: str, port: int) -> None:
    """`BadInput` unless a server could listen on host:port now (bound as the server binds, with
    SO_REUSEADDR: the last run's connections in TIME_WAIT do not block it). Port 0 too, so that an
    address this machine does not have (--live-host 1.2.3.4) is refused before anything runs."""
    import errno
    import socket

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            bad_host = isinstance(exc, socket.gaierror) or exc.errno == errno.EADDRNOTAVAIL
            raise BadInput("--live-host" if bad_host else "--live-port",
                           f"cannot serve {host}:{port}: {exc.strerror or exc}") from None


def _check_live(opts: RunOptions, rate_hz: float) -> None:
    """The live server's options, and its port free, before anything runs."""
    if not opts.log_enabled:
        raise BadInput("--live", "the live stream comes from the log writer: it needs a logged run")
    if not (math.isfinite(opts.live_rate) and 0 < opts.live_rate <= rate_hz):
        raise BadInput("--live-rate", f"must be in (0, {rate_hz:g}] Hz (the loop rate), got {opts.live_rate}")
    if not 0 <= int(opts.live_port) <= 65535:
        raise BadInput("--live-port", f"must be in 0..65535 (0: any free port), got {opts.live_port}")
    check_live_address(opts.live_host, int(opts.live_port))


@dataclass
class _Plan:
    """Everything a run needs, checked before any device is opened or any file written."""

    cfg: RigConfig
    scn: Scenario
    duration: float
    realtime: bool
    replay: Any = None  # bench.operate.requests.ReplaySource of --replay-params
    switches: tuple[tuple[float, str, str], ...] = ()  # the scenario's and the options' scheduled switches
    fault: dict[str, Any] | None = None  # what was injected (bench.runtime.fault_injection); cfg has it
    stalls: dict[int, int] = field(default_factory=dict)  # the recorded run's loop stalls a lockstep replay repeats


def _scenario_args(opts: RunOptions, scn: Scenario) -> dict[str, float]:
    """The parameterised scenario's arguments as run (defaults filled in; {} for the others and for a Scenario
    object)."""
    if not isinstance(opts.scenario, str):
        return {}
    cfg = opts.rig if isinstance(opts.rig, RigConfig) else load_rig(opts.rig)
    return scenarios.check_arguments(scn.name, scenarios.scaled_arguments(scn.name, opts.scenario_args,
                                                                            scenario_scaling(cfg)))  # fmt: skip


def prepare(opts: RunOptions) -> _Plan:
    """Validate the options that need no rig (raises `BadInput`); opens and writes nothing."""
    cfg = opts.rig if isinstance(opts.rig, RigConfig) else load_rig(opts.rig)
    if isinstance(opts.scenario, Scenario):
        if opts.scenario_args:
            raise BadInput("scenario_args", "only with a scenario name (a Scenario object is built with its own)")
        scn = opts.scenario
    else:
        # arguments inside the margins; scaled to the rig's motor where it is not the thesis motor
        # (bench.core.nameplate)
        scn = scenarios.get(opts.scenario, opts.scenario_args, Margins.of_rig(cfg), scenario_scaling(cfg))
    duration = scn.duration if opts.duration is None else opts.duration
    if not (math.isfinite(duration) and cfg.T_s <= duration <= 3600):
        raise BadInput("duration", f"must be in [{cfg.T_s:.3g}, 3600] s (at least one tick), got {duration}")
    margins = Margins.of_rig(cfg)  # its own set-points, over the run, inside too (a named one: remembered per process)
    if isinstance(opts.scenario, str) and scenario_scaling(cfg) is None:
        scenarios.check_named(scn.name, scenarios.check_arguments(scn.name, opts.scenario_args), margins, duration)
    else:  # (a scenario scaled to another motor: the profile as it was built)
        scenarios.check_profile(scn, margins, duration)
    fault = None
    if opts.inject_fault is not None:
        cfg, fault = inject(cfg, opts.inject_fault, scn, duration)
    if not (math.isfinite(opts.log_buffer) and 0.05 <= opts.log_buffer <= 120):
        raise BadInput("--log-buffer", f"must be in [0.05, 120] s, got {opts.log_buffer}")
    if opts.live_port is not None:
        _check_live(opts, cfg.rate_hz)
    if opts.controller not in controllers.available():
        controllers.create(opts.controller, None, {})  # type: ignore[arg-type]  # raises the BadInput
    replay, stalls = None, {}
    if opts.replay_params is not None:
        if opts.live_port is not None:
            raise BadInput("--replay-params", "cannot be combined with --live (a replay takes no requests)")
        if opts.switches:  # (they would be dropped: the replay applies the recorded run's switches)
            raise BadInput("--switch", "cannot be combined with --replay-params (the replay applies the switches "
                                       "the recorded run made, at their ticks)")  # fmt: skip
        replay = read_requests(str(opts.replay_params), cfg.rate_hz)
        stalls = read_stalls(str(opts.replay_params))
    switches = tuple(scn.switches) + tuple(opts.switches)
    for t, part, choice in switches:
        if not (isinstance(t, (int, float)) and math.isfinite(t) and 0 <= t < duration):
            raise BadInput("--switch", f"{part}={choice}: the time must be in [0, {duration:g}) s (the run), got {t!r}")
    if replay is not None:
        switches = ()  # the recorded run's switches are in its /params: the replay applies them
    return _Plan(cfg, scn, duration, _pacing(cfg, opts), replay, switches, fault, stalls)


def run(opts: RunOptions) -> tuple[dict[str, Any], int]:
    """Run one session; returns (summary, exit code). Raises BadInput for bad options.

    Every ending goes through one path (bench.core.shutdown): safe command, log closed, summary and
    plot written, exit code 0 / 1 (tripped or failed) / 128 + signal.
    """
    with SignalGuard() as guard:
        try:
            plan = prepare(opts)
        except Interrupted as exc:  # while the options were checked: the summary says that nothing ran
            return _nothing_ran(opts, exc)
        if plan.fault is not None:
            print(f"bench: {describe(plan.fault)}", file=sys.stderr, flush=True)
        return _execute(opts, plan, guard)


def _nothing_ran(opts: RunOptions, exc: Interrupted) -> tuple[dict[str, Any], int]:
    """The summary of a run that a signal ended while its options were checked, in the folder it would have had."""
    import types

    name = opts.scenario if isinstance(opts.scenario, str) else opts.scenario.name
    code = signal_exit_code(exc.signum)
    summary: dict[str, Any] = {"scenario": name, "controller": opts.controller, "seed": opts.seed, "exit_code": code,
                               "trip_cause": f"{exc} during start-up (checking the options): nothing ran",
                               "trip_time": None, "ticks": 0, "warnings": []}  # fmt: skip
    paths = _late_paths(opts, types.SimpleNamespace(name=name), [])
    if paths is not None:
        summary.update({"log": None, "plot": None})
        write_summary_and_plot(summary, paths, plot=False)
    return summary, code


@dataclass
class _Run:
    """What a run has built so far: the one shutdown path (`_execute`) releases and reports whatever is there."""

    cfg: RigConfig
    stage: str = "choosing the engines"  # what start-up was doing (a signal before the loop names it)
    problems: list[str] = field(default_factory=list)  # warnings: what went wrong around the run
    rig: Rig | None = None
    ctrl: Controller | None = None
    engines: dict[str, Any] | None = None  # the plant and controller engines that ran (default_engines)
    log: Any = None
    loop: TimedLoop | None = None
    operator: Operator | None = None
    can_logger: Any = None
    paths: tuple[Path, Path, Path] | None = None  # log, summary, plot (None: in-memory record only)
    spare: Path | None = None  # disk space set aside for summary.json (bench.core.outputs.reserve_room)
    made: list[Path] = field(default_factory=list)  # folders this run made (gone again if it is refused)


def _execute(opts: RunOptions, plan: _Plan, guard: SignalGuard) -> tuple[dict[str, Any], int]:
    """Start, run and end one run; every way it ends goes through the one shutdown below: the safe command first,
    then the cause and exit code, then the log, summary and plot."""
    run = _Run(plan.cfg)
    res: LoopResult | None = None
    cause: str | None = None  # why the run ended early, if not in the loop's result
    bar = _ProgressBar(opts.progress, plan.duration, opts.label)
    try:
        loop = _start(opts, plan, run, bar)
        run.stage = "taking the CPU for real time"
        loop.take_realtime()  # before the drive's first set-point: nothing slow between it and the first tick
        run.stage = "activating the rig"
        run.rig.activate()
        guard.running(loop.sup.request_trip)  # from here a signal trips at the next tick
        res = loop.run()
    except Interrupted as exc:  # a signal before the loop ran
        cause = f"{exc} during start-up ({run.stage}): nothing ran"
        run.paths = run.paths or _late_paths(opts, plan.scn, run.made)  # the summary says so
    except BadInput:
        free_room(run.spare)
        if run.paths is not None and opts.log is None:
            with contextlib.suppress(OSError):
                run.paths[0].parent.rmdir()  # the new run folder, if still empty
        remove_empty(run.made)  # and the folders it was made in (runs/), if this run made them
        raise  # after the finally below: nothing ran
    except Exception as exc:  # start-up failed: a device, the log writer, ...
        cause = f"start-up failed: {type(exc).__name__}: {one_line(str(exc))}"
        run.paths = run.paths or _late_paths(opts, plan.scn, run.made)
    finally:
        guard.shutting_down()
        if run.loop is not None:  # a signal or a failure after the real-time setup, before the loop ran
            run.loop.give_back_realtime()
        signal_in_run, signals_before = guard.first, guard.count  # signals from here on are only reported
        if run.rig is not None:  # 1. safe command (again, if the loop already sent it), devices released
            # the CAN logger stops before the devices (and emulators) go, so it closes its file in order
            _release(run.rig, run.problems, before_close=[run.can_logger.stop] if run.can_logger is not None else [])
        elif run.can_logger is not None:
            run.can_logger.stop()
        bar.stop()  # after the safe command: nothing that may wait comes before it
        pause_for_test("session-shutdown")  # (tests: a signal during the shutdown, the rig already safe)
    # 2. the outcome: the cause and the exit code
    if res is not None and res.trip_cause:
        cause = res.trip_cause
    if cause is None and signal_in_run is not None:  # a signal after the last tick, before the shutdown
        cause = signal_cause(signal_in_run)
    code = signal_exit_code(signal_in_run) if signal_in_run is not None else EXIT_TRIP if cause else EXIT_OK
    # 3. the log: the summary as known so far goes into it, then it is closed (bounded time); 4. the
    # numbers read back from the log, the plot and summary.json, whatever happened above
    summary = summarise(opts, plan, run, res, cause, code)
    if guard.count > signals_before:  # the run's outcome stands; the shutdown finished anyway
        run.problems.append(f"{guard.count - signals_before} signal(s) during the shutdown: ignored until it finished")
    run.problems.extend(take_notes())  # the compiled engines' cache repaired, not saved, or not usable
    summary["warnings"] = run.problems
    paths = run.paths
    if paths is not None:
        free_room(run.spare)  # its room is the summary's now
        write_summary_and_plot(summary, paths, plot=bool(res is not None and res.ticks and summary["log"]))
        if opts.log is None:
            with contextlib.suppress(OSError):
                paths[0].parent.rmdir()  # the run folder, if nothing could be written into it
    return summary, code


def _start(opts: RunOptions, plan: _Plan, run: _Run, bar: _ProgressBar) -> TimedLoop:
    """Start-up, in `_Run`'s stages: the engines, the rig, the controller, the run's folders, the devices, the
    operator's parameter space and schedule, the log; returns the loop, ready to take the CPU. Bad input raises
    `BadInput` before anything runs."""
    scn = plan.scn
    cfg, params, note = default_engines(run.cfg, opts.controller, opts.params, plan.duration, plan.realtime)
    run.cfg = cfg
    if note is not None:
        run.problems.append(note)
        print(f"bench: {note}", file=sys.stderr, flush=True)
    run.stage = "building the rig"
    run.rig = rig = build_rig(cfg, opts.seed, plan.realtime)
    if plan.realtime and getattr(rig, "emulator", None) is not None:
        print(f"bench: note: the emulators run in this process and share its interpreter lock with the loop: beside "
              f"busy processes the loop stalls behind them; `bench emulate --rig {cfg.path or cfg.name}` in a process of its "
              "own keeps 3 kHz (docs/realtime-pc.md)", file=sys.stderr, flush=True)  # fmt: skip
    run.stage = "building the controller"
    run.ctrl = ctrl = make_controller(cfg, rig, opts.controller, params)
    run.engines = {"plant": getattr(rig.truth, "engine", None),  # what runs (an "auto" resolved)
                   "controller": "compiled" if getattr(ctrl, "_kernel", None) is not None else "python"}  # fmt: skip
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    if opts.can_log is not None:
        can_cfg = rig.drivers["can"].cfg if hasattr(rig, "drivers") else None
        canlog.check(can_cfg, opts.can_log)
        check_output("--can-log", opts.can_log, opts.force)
    if opts.log_enabled:  # the folders made here go again if the run is refused below (bad input)
        run.made = new_folders(*(p.parent for p in (opts.log, opts.summary, opts.plot) if p is not None),
                               opts.out_dir if opts.log is None else None)  # fmt: skip
        run.paths = _paths(opts, scn)  # the last check: the run folder exists from here on
        run.spare = reserve_room(run.paths[1])  # a log that fills the disk leaves the summary its room
    if opts.can_log is not None:
        run.can_logger = canlog.CanLogger(can_cfg, opts.can_log)
    run.stage = "connecting to the devices"
    rig.configure()  # connects to the devices: an unreachable one fails here, before the log starts
    run.stage = "opening the log"
    topics = [Topic(name, schema, flds) for name, schema, flds in log_topics(rig, ctrl)]
    space = schedule = takers = None  # the parameters clients may change; the scheduled switches; the takers
    if opts.live_port is not None or plan.replay is not None or plan.switches:
        space, schedule, takers = _operator_space(cfg, rig, ctrl, params, plan)
    run.log = log = _open_run_log(opts, plan, run, topics, sup, space)
    prog = bar.start(log.panel_source() if isinstance(log, LogWriter) else None,  # panel: the writer's view
                     space.describe() if space is not None else None)  # fmt: skip
    if space is not None:
        source = plan.replay if plan.replay is not None else log.inbox if opts.live_port is not None else None
        run.operator = Operator(ctrl, space, merged(source, schedule), log.event, sup.request_trip,
                                busy=lambda: sup.cause, controllers=takers)  # fmt: skip
    run.loop = TimedLoop(rig, ctrl, scn, sup, T_s=cfg.T_s, duration=plan.duration, realtime=plan.realtime,
                         log=log, progress=prog, operator=run.operator,
                         inject_stalls=plan.stalls | {int(round(t / cfg.T_s)): max(1, int(round(d / cfg.T_s)))
                                                      for t, d in opts.inject_stalls.items()})  # fmt: skip
    return run.loop


def _operator_space(cfg: RigConfig, rig: Rig, ctrl: Controller, params: dict[str, Any], plan: _Plan
                    ) -> tuple[ParamSpace, Any, Any]:  # fmt: skip
    """The parameters clients may change (bounded by the rig), the scheduled switches as requests at their ticks,
    and the whole controllers that may take over, built before the loop; a switch that cannot be had is
    `BadInput`."""

    def build(name: str) -> Controller:  # a plugin that may take over, with the run's parameters it has
        cls = controllers.available()[name]
        return make_controller(cfg, rig, name, {k: v for k, v in params.items() if k in cls.schema})

    takers, not_ready = prepared_controllers(ctrl, build)  # whole-controller switches, built before the loop
    for t, part, choice in plan.switches:
        if part == "controller" and choice in not_ready:
            raise BadInput("--switch", f"controller={choice} at {t:g} s: {not_ready[choice]}")
    space = ParamSpace.of(ctrl, cfg.limits, rig.load.torque_limit,  # the overrides' bounds: the rig's
                          controller_param(ctrl, takers))  # fmt: skip
    schedule = scheduled(plan.switches, space, cfg.T_s)  # BadInput (exit 2) before anything runs
    prepare_switching = getattr(ctrl, "prepare_switching", None)
    if prepare_switching is not None:  # every part it may switch to, built before the loop
        unavailable = prepare_switching()
        for t, part, choice in plan.switches:
            why = unavailable.get(f"{part}={choice}")
            if why is not None:
                raise BadInput("--switch", f"{part}={choice} at {t:g} s cannot be had: {why}")
    return space, schedule, takers


def _open_run_log(opts: RunOptions, plan: _Plan, run: _Run, topics: list[Topic], sup: Supervisor,
                  space: ParamSpace | None) -> Any:  # fmt: skip
    """The run's log: an MCAP file with the run's metadata and rig file (a writer fault trips the run), its live
    view if asked; in memory where no log is wanted."""
    if run.paths is None:
        return MemoryLog(topics)
    cfg, scn, ctrl = run.cfg, plan.scn, run.ctrl
    meta = {
        "run": {"scenario": scn.name, "description": scn.description, "controller": ctrl.name,
                "controller_params": ctrl.params(), "seed": opts.seed, "duration": plan.duration,
                "realtime": plan.realtime, "rate_hz": cfg.rate_hz, "code_version": code_version(),
                "argv": sys.argv},
        "rig": cfg.as_dict(),
    }  # fmt: skip
    meta.update({k: v for k, v in opts.metadata.items() if k not in meta})
    rig_file = [("rig.toml", "application/toml", Path(cfg.path).read_bytes())] if cfg.path else []
    live = None
    if opts.live_port is not None:
        live = {"host": opts.live_host, "port": opts.live_port, "every": stream_every(cfg.rate_hz, opts.live_rate)}
    log = open_log(run.paths[0], topics, meta, realtime=plan.realtime, rate_hz=cfg.rate_hz,
                   buffer_s=opts.log_buffer, on_fault=sup.request_trip, attachments=rig_file,
                   live=live, panel=opts.progress and plan.realtime,
                   operator=space.describe() if space is not None else None)  # fmt: skip
    if log.live_port is not None:
        print(f"bench: live: ws://{opts.live_host}:{log.live_port} (Foxglove: Open connection)",
              file=sys.stderr, flush=True)  # fmt: skip
    return log




def summarise(opts: RunOptions, plan: _Plan, run: _Run, res: LoopResult | None, cause: str | None,
               code: int) -> dict[str, Any]:  # fmt: skip
    """The run's summary: what ran and how it ended, the loop's timing, the operator's requests, the log closed
    (the summary so far goes into it first), and the numbers read back from the log."""
    cfg, scn, ctrl, log, operator, problems = run.cfg, plan.scn, run.ctrl, run.log, run.operator, run.problems
    summary: dict[str, Any] = {
        "scenario": scn.name, "scenario_args": _scenario_args(opts, scn), "controller": opts.controller,
        "controller_params": ctrl.params() if ctrl else None,
        "rig": cfg.name, "seed": opts.seed, "exit_code": code, "trip_cause": cause,
        "trip_time": summary_time(res.trip_t) if res is not None else None, "realtime": plan.realtime,
        "engines": run.engines,
    }  # fmt: skip
    if plan.fault is not None:
        summary["fault_injection"] = plan.fault
    if res is not None:
        summary.update({
            "ticks": res.ticks, "duration": summary_time(res.sim_time), "wall_time": res.wall_time,
            "realtime_factor": res.realtime_factor, "deadline_misses": res.deadline_misses,
            "overruns": res.overruns, "skipped_ticks": res.skipped, "timing": res.timing(),
            "realtime_setup": res.rt_setup, "start_epoch_ns": res.start_epoch_ns,
            "stalls": stall_report(res, run.rig, cfg),
        })  # fmt: skip
    else:
        summary["ticks"] = 0
    if operator is not None:
        summary["operator"] = operator.summary()
    summary["log_writer"] = close_log(log, summary, problems)
    served = ((summary["log_writer"] or {}).get("writer") or {}).get("requests")
    if operator is not None and served:  # what the live server received, checked and refused
        summary["operator"]["server"] = served
    paths = run.paths
    if paths is not None:
        summary.update({"log": str(paths[0]) if log_kept(paths[0]) else None, "plot": None, "summary": None})
    if res is not None and res.ticks and (paths is None or summary["log"]):
        try:
            summary.update(summarize(log if paths is None else LogReader(paths[0]), scn, cfg.motor.torque_constant,
                                     true_R_r(run.rig)))
        except Exception as exc:  # noqa: BLE001 - a torn log still gets a summary
            problems.append(f"summary from the log failed: {type(exc).__name__}: {exc}")

        stuck = voltage_limit_warning(summary.get("voltage_limit"), summary["controller_params"])
        if stuck:  # the run ended at the voltage limit: which limit, and why the drive stays there
            problems.append(stuck)
    if paths is None:
        summary["record"] = log  # the in-memory per-tick record (MemoryLog), for the caller
    if plan.realtime and res is not None and not res.rt_setup.get("sched_fifo"):
        problems.append("real-time scheduling (SCHED_FIFO) not applied: the loop may be late under load")
    return summary


def _late_paths(opts: RunOptions, scn: Scenario, made: list[Path]) -> tuple[Path, Path, Path] | None:
    """The run's paths when start-up ended before it made them (a signal, a device that failed): the summary of
    a run that never ticked still goes where the run's would have (None: no log wanted, or no place for it)."""
    if not opts.log_enabled:
        return None
    try:
        made += new_folders(*(p.parent for p in (opts.log, opts.summary, opts.plot) if p is not None),
                            opts.out_dir if opts.log is None else None)  # fmt: skip
        return _paths(opts, scn)
    except (BadInput, OSError):
        return None








def _release(rig: Rig, problems: list[str], before_close: list[Any] = ()) -> None:  # type: ignore[assignment]
    """Safe command first, then ``before_close`` (each may return a problem), then release the devices;
    never raises (problems are reported)."""
    for step in (rig.safe, *before_close, rig.deactivate):
        try:
            problem = step()
        except Exception as exc:  # noqa: BLE001 - the next step must still run
            problem = f"{getattr(step, '__qualname__', step)} failed: {type(exc).__name__}: {exc}"
        if isinstance(problem, str):
            problems.append(problem)
    close = getattr(rig, "close", None)  # a driver rig that never got configured still holds emulators
    if close is not None:
        try:
            close()
        except Exception as exc:  # noqa: BLE001
            problems.append(f"rig close failed: {type(exc).__name__}: {exc}")




class _ProgressBar:
    """A progress bar with ETA over loop time, on stderr, drawn by a separate process.

    The loop only stores the current loop time into shared memory; drawing happens elsewhere, so
    the bar neither holds the GIL nor costs the real-time loop a deadline. Nothing here can block
    the shutdown: the stop request is a plain shared flag (no lock a stopped or killed child could
    hold), the process is deaf to terminal keys (bench.core.shutdown.spawning), and `stop` waits at most
    2 s, then kills it.
    """

    def __init__(self, enabled: bool, duration: float, label: str = "bench run") -> None:
        self.enabled, self.duration, self.label = enabled, duration, label
        self._proc: Any = None

    def start(self, panel: Any = None, operator: dict | None = None) -> Any:
        """Start drawing; returns ``update(t)`` for the loop (None when disabled). ``operator``: the run's parameter
        description, for the panel's names of switches."""
        if not self.enabled:
            return None

        ctx = child_context()  # spawn, without importing the caller's main script again (no guard needed)
        shared = self._t = ctx.RawValue("d", 0.0)
        self._stop = ctx.RawValue("b", 0)
        self._proc = ctx.Process(target=_draw_progress, args=(self._t, self._stop, self.duration, self.label,
                                                              os.getpid(), panel, operator), daemon=True)  # fmt: skip
        with spawning():
            self._proc.start()

        def update(t: float) -> None:
            shared.value = t

        return update

    def stop(self) -> None:
        """Stop drawing (idempotent; never raises, never waits more than 2 s)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        self._stop.value = 1
        proc.join(timeout=2.0)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=1.0)


def _draw_progress(shared, stop, duration: float, label: str, parent: int, panel: Any = None,  # noqa: ANN001
                   operator: dict | None = None) -> None:  # fmt: skip
    """The bar; with ``panel`` (the log writer's shared index array, real-time runs) also the terminal
    panel of bench.daq.live.panel_text under it: what the writer saw in the rows, not the loop's state."""
    child_ignores_signals()  # signals, terminal keys included, belong to the loop process
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
    from rich.text import Text

    cols = (TextColumn(f"[bold]{label}"), BarColumn(), TextColumn("{task.completed:6.2f}/{task.total:.2f} s"),
            TimeRemainingColumn())  # fmt: skip
    view = None
    if panel is not None:
        view = np.frombuffer(panel, np.float64)[PANEL : PANEL + len(PANEL_FIELDS)]
        codes = switch_codes(operator)
    line = Text("")

    class _Bar(Progress):
        def get_renderables(self):  # noqa: ANN202 - the bar, then the panel line
            yield self.make_tasks_table(self.tasks)
            if view is not None:
                yield line

    with _Bar(*cols, refresh_per_second=5, console=Console(stderr=True)) as bar:  # stdout is for data
        task = bar.add_task("run", total=duration)
        while not stop.value and os.getppid() == parent:  # the loop process died: stop drawing
            time.sleep(0.2)
            if view is not None:
                line.plain = panel_text(view.copy(), codes)
            bar.update(task, completed=shared.value)
        bar.update(task, completed=shared.value)
