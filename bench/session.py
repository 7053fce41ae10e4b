"""One bench session: rig file + controller + scenario -> timed loop -> MCAP log, summary, plot.

This is the composition root: the only bench module that knows how to build a mock rig. The
controllers themselves never import `mock_hw`.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench import controllers, scenarios
from bench.config import RigConfig
from bench.config import load as load_rig
from bench.controllers.base import Controller, ControllerContext
from bench.daq import LogReader, LogWriter, Topic, code_version
from bench.errors import BadInput
from bench.hal import Rig
from bench.loop import LoopResult, TimedLoop, log_topics
from bench.scenarios import T_MAGNETISE, Scenario
from bench.supervisor import Supervisor

EXIT_OK, EXIT_TRIP, EXIT_INTERRUPTED = 0, 1, 130


@dataclass
class RunOptions:
    rig: str = "mock"
    controller: str = "foc"
    scenario: str | Scenario = "demo"  # a name in bench.scenarios, or a Scenario built by the caller
    duration: float | None = None  # default: the scenario's
    realtime: bool = False
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)  # controller parameters
    log: Path | None = None
    summary: Path | None = None
    plot: Path | None = None
    out_dir: Path = Path("runs")
    progress: bool = True
    log_enabled: bool = True
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)  # extra log metadata records


def build_rig(cfg: RigConfig, seed: int) -> Rig:
    if cfg.driver == "mock":
        from mock_hw.plant import MockConfig, make_mock_rig

        try:
            mock_cfg = MockConfig.from_dict(cfg.mock)
        except ValueError as exc:
            msg = str(exc)
            field_name, _, problem = msg.partition(" ")
            raise BadInput(field_name if field_name.startswith("mock") else "mock", problem or msg) from None
        return make_mock_rig(mock_cfg, dt=cfg.T_s, seed=seed)
    if cfg.driver == "drivers":
        from bench.drivers import build_driver_rig

        from mock_hw.emulators import emulator_running

        mode = cfg.hw["emulator"]["autostart"]
        if mode == "never" or (mode == "auto" and emulator_running(cfg)):  # devices or `bench emulate`
            return build_driver_rig(cfg)
        # in-process emulators on the rig file's transports, the run's seed for the plant noise
        from mock_hw.emulators import start_emulator

        emu = start_emulator(cfg, seed=seed)
        rig = build_driver_rig(emu.host_config(), on_close=[emu.close])
        rig.truth = emu.truth_view(rig.drivers["frontend"])  # logged only, never seen by controllers
        rig.emulator = emu  # type: ignore[attr-defined]
        return rig
    raise BadInput("rig.driver", f"unsupported driver {cfg.driver!r}")


def make_controller(cfg: RigConfig, rig: Rig, name: str, params: dict[str, Any]) -> Controller:
    ctx = ControllerContext(T_s=cfg.T_s, motor=cfg.motor, I_max=cfg.limits.I_max,
                            counts_per_rev=rig.encoder.counts_per_rev, enc_modulus=rig.encoder.modulus)  # fmt: skip
    return controllers.create(name, ctx, params)


def _paths(opts: RunOptions, scn: Scenario) -> tuple[Path, Path, Path]:
    if opts.log is not None:
        base = opts.log.with_suffix("")
        log = opts.log
    else:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        folder = opts.out_dir / f"{stamp}-{scn.name}-{opts.controller}-seed{opts.seed}"
        folder.mkdir(parents=True, exist_ok=True)
        base, log = folder / "run", folder / "run.mcap"
    log.parent.mkdir(parents=True, exist_ok=True)
    summary = opts.summary or base.with_name(base.name + ".summary.json" if opts.log else "summary.json")
    plot = opts.plot or base.with_name(base.name + ".png" if opts.log else "run.png")
    return log, summary, plot


def _stats(x: np.ndarray) -> dict[str, float]:
    if x.size == 0:
        return {}
    return {"rms": float(np.sqrt(np.mean(x**2))), "max_abs": float(np.max(np.abs(x))), "mean": float(np.mean(x))}


def summarize(log_path: Path, scn: Scenario, res: LoopResult) -> dict[str, Any]:
    """Speed-tracking and load-rejection numbers from the log (true speed where the rig has it)."""
    r = LogReader(log_path)
    meas = ref = cmd = r.read("/rig")
    t = meas["t"]
    if "/truth" in r.topics():
        truth = r.read("/truth")
        omega, source = truth["omega_r"], "truth"
        i_m = np.hypot(truth["i_m_re"], truth["i_m_im"])
    else:
        omega, source, i_m = r.read("/ctrl").get("omega_hat", np.zeros_like(t)), "measured", None
    w_ref, m_L = ref["omega_r_ref"], cmd["m_l_ref"]
    e = w_ref - omega
    active = (t >= T_MAGNETISE) & ~r.read("/rig")["tripped"].astype(bool)
    out: dict[str, Any] = {"speed_source": source, "speed_error": _stats(e[active])}

    # settled tracking: samples more than 0.2 s after the last reference change
    ref_change = np.flatnonzero(np.diff(w_ref) != 0) + 1
    last_change = np.full(t.shape, -np.inf)
    if ref_change.size:
        idx = np.searchsorted(t[ref_change], t, side="right") - 1
        ok = idx >= 0
        last_change[ok] = t[ref_change][idx[ok]]
    settled = active & (t - last_change > 0.2)
    out["speed_error_settled"] = _stats(e[settled])

    # load steps: peak deviation and time to return within 1 rad/s, in the window from each load
    # step to the next one (at most 0.2 s); steps near a reference change are left out
    load_steps = np.flatnonzero(np.abs(np.diff(m_L)) > 0.5) + 1
    peaks, recov = [], []
    for n, i in enumerate(load_steps):
        t_s = t[i]
        t_end = min(t_s + 0.2, t[load_steps[n + 1]] if n + 1 < load_steps.size else np.inf)
        if t_s < T_MAGNETISE or np.any((t[ref_change] > t_s - 0.2) & (t[ref_change] < t_end)):
            continue
        win = (t >= t_s) & (t < t_end) & active
        if not win.any():
            continue
        dev = np.abs(e[win])
        peaks.append(float(dev.max()))
        above = np.flatnonzero(dev > 1.0)
        recov.append(float(t[win][above[-1]] - t_s) if above.size else 0.0)
    out["load_steps"] = {
        "count": len(peaks),
        "peak_deviation_max": max(peaks) if peaks else None,
        "peak_deviation_mean": float(np.mean(peaks)) if peaks else None,
        "recovery_time_1rad_s_mean": float(np.mean(recov)) if recov else None,
    }
    if i_m is not None:
        out["i_mR_error"] = _stats((ref["i_mr_ref"] - i_m)[settled])
    return out


def run(opts: RunOptions) -> tuple[dict[str, Any], int]:
    """Run one session; returns (summary, exit code). Raises BadInput for bad options."""
    cfg = load_rig(opts.rig)
    scn = opts.scenario if isinstance(opts.scenario, Scenario) else scenarios.get(opts.scenario)
    duration = scn.duration if opts.duration is None else opts.duration
    if not (math.isfinite(duration) and 0 < duration <= 3600):
        raise BadInput("duration", f"must be in (0, 3600] s, got {duration}")
    rig = build_rig(cfg, opts.seed)
    ctrl = make_controller(cfg, rig, opts.controller, opts.params)
    sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    rig.configure()  # connects to the devices: an unreachable one fails here, before anything is written
    released = False
    try:
        log_path, summary_path, plot_path = _paths(opts, scn)
        topics = [Topic(name, schema, flds) for name, schema, flds in log_topics(rig, ctrl)]
        meta = {
            "run": {"scenario": scn.name, "description": scn.description, "controller": ctrl.name,
                    "controller_params": ctrl.params(), "seed": opts.seed, "duration": duration,
                    "realtime": opts.realtime, "rate_hz": cfg.rate_hz, "code_version": code_version(),
                    "argv": sys.argv},
            "rig": cfg.as_dict(),
        }  # fmt: skip
        meta.update({k: v for k, v in opts.metadata.items() if k not in meta})
        # the writer yields the CPU to a real-time loop; in lockstep it runs at normal priority so
        # it keeps up with the simulation
        with LogWriter(log_path, topics, metadata=meta, writer_nice=10 if opts.realtime else 0) as log:
            with _progress(opts.progress, duration) as prog:
                rig.activate()
                try:
                    res = TimedLoop(rig, ctrl, scn, sup, T_s=cfg.T_s, duration=duration, realtime=opts.realtime,
                                    log=log, progress=prog).run()  # fmt: skip
                finally:
                    rig.deactivate()  # safe state right after the last tick, before the log is closed
                    released = True
            log_stats = log.stats()
    finally:
        if not released:
            rig.deactivate()
    summary: dict[str, Any] = {
        "scenario": scn.name, "controller": ctrl.name, "rig": cfg.name, "seed": opts.seed,
        "ticks": res.ticks, "duration": res.sim_time, "wall_time": res.wall_time,
        "realtime": opts.realtime, "realtime_factor": res.realtime_factor,
        "deadline_misses": res.deadline_misses, "overruns": res.overruns, "skipped_ticks": res.skipped,
        "timing": res.timing(), "trip_cause": res.trip_cause, "trip_time": res.trip_t,
        "log": str(log_path), "plot": str(plot_path), "log_writer": log_stats,
    }  # fmt: skip
    summary.update(summarize(log_path, scn, res))
    from bench.daq.plots import plot_run

    plot_run(log_path, plot_path, title=f"{scn.description}\ncontroller {ctrl.name}, rig {cfg.name}, seed {opts.seed}")
    summary_path.write_text(json.dumps(summary, indent=2))
    summary["summary"] = str(summary_path)
    code = EXIT_INTERRUPTED if res.interrupted else EXIT_TRIP if res.trip_cause else EXIT_OK
    return summary, code


class _progress:
    """A progress bar over loop time, drawn by a separate process.

    The loop only stores the current loop time into shared memory; drawing happens elsewhere, so
    the bar neither holds the GIL nor costs the real-time loop a deadline.
    """

    def __init__(self, enabled: bool, duration: float) -> None:
        self.enabled, self.duration = enabled, duration

    def __enter__(self):  # noqa: ANN204
        if not self.enabled:
            return None
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self._t = ctx.Value("d", 0.0, lock=False)
        self._stop = ctx.Event()
        self._proc = ctx.Process(target=_draw_progress, args=(self._t, self._stop, self.duration), daemon=True)
        self._proc.start()
        shared = self._t

        def update(t: float) -> None:
            shared.value = t

        return update

    def __exit__(self, *exc: object) -> None:
        if self.enabled:
            self._stop.set()
            self._proc.join(timeout=2.0)
            if self._proc.is_alive():
                self._proc.kill()


def _draw_progress(shared, stop, duration: float) -> None:  # noqa: ANN001
    import signal

    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C belongs to the loop process
    cols = (TextColumn("[bold]bench run"), BarColumn(), TextColumn("{task.completed:6.2f}/{task.total:.2f} s"),
            TimeRemainingColumn())  # fmt: skip
    with Progress(*cols, refresh_per_second=5) as bar:
        task = bar.add_task("run", total=duration)
        while not stop.wait(0.2):
            bar.update(task, completed=shared.value)
        bar.update(task, completed=shared.value)
