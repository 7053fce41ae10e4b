"""The workflows' commands: `reproduce`, `sweep`, `tune`, `identify`, `commission`, `synth`, `collect`, `train`
and `pipeline`."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from bench.errors import BadInput
from bench.core.progress import VERIFIED, stages, summarised_warnings
from bench.core.outputs import check_output
from bench.workflows import reproduce

from bench.cli.common import (
    FINITE, FiniteRange, _live, _live_options, _pacing_options, _parse_params, _report_end, cli,
)  # fmt: skip


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
    from bench.workflows.sweep.batching import DEFAULT_BATCH
    from bench.workflows.sweep.engine import run_sweep
    from bench.workflows.sweep.spec import load

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
    from bench.workflows.sweep.report import report

    written = report(out)
    click.echo(json.dumps({"written": [str(p) for p in written]}, indent=2))


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
    from bench.workflows.tuning import tune_speed

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
    from bench.workflows.commission import identify as ident

    params = _parse_params(param)
    rotating_params = _parse_params(rotating_param, "--rotating-param")
    if from_log is not None:
        if write:
            raise BadInput("--write", "not with --from-log: a re-estimate writes no rig file; run the test on the rig")
        if rotating:
            raise BadInput("--rotating", "not with --from-log (re-fit a rotating log with "
                           "bench.workflows.commission.rotating_fit.analyse_log)")  # fmt: skip
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
    from bench.workflows.commission.commission import commission as run_commission

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
    from bench.workflows.synth import flux_observer
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
@click.option("--centring", type=click.Choice(["scaled", "balanced"]), default="scaled", show_default=True,
              help="where the LMI solution is centred: at the bisection's scaling (the shipped artifacts) or in its "
                   "own balanced coordinates (continuous in the model)")
@click.option("--objective", type=click.Choice(["trace", "dual"]), default="trace", show_default=True,
              help="what the centring minimises: tr X + tr Y (the shipped artifacts) or tr Y + |P~| (a full-order "
                   "controller of lower gain)")
@click.option("--force", is_flag=True, help="overwrite an existing artifact")
def synth_current_controller(rate: float, discretisation: str, out: Path | None, rig: str, input_delay: float,
                             prewarp: float | None, rescale: str, centring: str, objective: str,
                             force: bool) -> None:  # fmt: skip
    """Quasi-LPV stator current controller of thesis 6.2.2 (gamma = 1.1 gamma_a), verified, saved as npz + JSON."""
    out = out or Path("runs") / "artifacts" / f"current_controller_{rate:g}Hz"
    _check_artifact(out, force)
    from bench.workflows.synth import current_controller
    with summarised_warnings("current controller", checked=VERIFIED):
        info = current_controller(rate, out, discretisation=discretisation, rig=rig, input_delay=input_delay,
                                  prewarp=prewarp, rescale=rescale, centring=centring, objective=objective,
                                  progress=stages("current controller"))
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
    from bench.workflows.synth import speed_controller
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
    from bench.workflows.narx import collect as run_collect

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
    from bench.workflows.narx import train as run_train

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
    from bench.workflows.pipeline import run_pipeline
    with summarised_warnings("pipeline", checked=VERIFIED):
        r = run_pipeline(out, samples=samples, seeds=(seed, seed + 1), max_nfev=max_nfev, spreads=sp, rig=rig,
                         quick=quick, robust=not no_robust, progress=say, workers=workers,
                         scheduler=scheduler)  # fmt: skip
    click.echo(json.dumps({"report": str(out / "report.md"), "selected": r["selected"],
                           "gamma": {k: r["nominal"][k] for k in ("gamma_a", "gamma", "gamma_lti")},
                           "timings_s": r["timings_s"]}, indent=2, default=float))  # fmt: skip
