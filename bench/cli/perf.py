"""`bench perf NAME`: every benchmark, each printing JSON (the benchmarks themselves are `bench.perf`)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from bench.errors import BadInput
from bench.core.progress import VERIFIED, stages, summarised_warnings
from bench.core.outputs import check_output
from synthesis.environment import environment

from bench.cli.common import FiniteRange, _parse_params, cli


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
    from bench.batch.engine import SCENARIOS

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
@click.option("--speed-step", is_flag=True, help="instead: stalls of 2, 4, 7 and 12 ms from 1 ms before fig5.7's "
              "speed step to 11.5 ms after it, under the PI laws and the LPV laws switched in (312 runs)")
def perf_stall(stalls: str, plot: Path | None, speed_step: bool) -> None:
    """Loop stalls injected at the rated point, at 100 rad/s and 7 N m, and 0.4 ms into a run (magnetising), with
    the drive's ride-through and without."""
    from bench.perf.stall import run

    if speed_step:
        from bench.perf.stall import speed_step as grid

        _perf_echo(grid())
        return

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
    from bench.workflows.commission import accuracy

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


@perf.command("commission")
@click.option("--motors", type=click.IntRange(1, 200), default=5, show_default=True,
              help="hidden motors (the first of bench perf identify's draw)")
@click.option("--motors-seed", type=int, default=0, show_default=True, help="seed of the motor draw")
@click.option("--seed", type=int, default=0, show_default=True, help="noise seed of every run")
@click.option("--rotating", is_flag=True, help="bench commission --rotating (L_m at the rated flux from the no-load test)")
def perf_commission(motors: int, motors_seed: int, seed: int, rotating: bool) -> None:
    """Commissioned vs true: bench commission on hidden mock motors, then the same designs for the true
    parameters; Fig. 5.7's experiment with both (flux-angle and speed-tracking errors against the truth)."""
    from bench.workflows.commission.versus_true import benchmark

    with summarised_warnings("perf commission", checked=VERIFIED):
        res = benchmark(motors, motors_seed, seed, rotating, say=stages("perf commission"))
    _perf_echo(res)


@perf.command("narx")
@click.option("--samples", type=click.IntRange(100, 1_000_000), default=22000, show_default=True,
              help="samples per data set at 600 Hz")
@click.option("--max-nfev", type=click.IntRange(1, 1_000_000), default=3000, show_default=True, help="LM evaluation budget")
def perf_narx(samples: int, max_nfev: int) -> None:
    """Wall time of `collect narx` (training + validation set) and `train narx` on the mock rig (lockstep)."""
    from bench.workflows.narx import benchmark

    click.echo(json.dumps(benchmark(samples, max_nfev), indent=2, default=float))
