"""The golden runs: what each one runs, on which engines, and its digest (`tests.golden.digest`).

Every run is lockstep with a fixed seed, so the same code gives the same bits. A run that has both engines (the
mock plant's ``[mock] engine`` and the FOC's ``-p engine``) runs on each; both must give the one recorded digest
(they are the same bits today: tests/test_compiled_plant.py, tests/test_compiled_foc.py). The engine is put into
a copy of the rig file, so the run goes through the same paths as ``bench run --rig FILE`` and ``bench identify``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.golden import digest

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parent / "data"
ENGINES = ("python", "compiled")
# The numerical kernels the golden runs are recorded and checked with. Every run depends on the last bits of some
# kernel the host picks for its CPU:
# - glibc's libm takes FMA variants of exp, sin, cos, atan2, pow ... where the CPU has FMA and AVX2: every
#   math-module call of the Python plant and controllers, and the compiled engines, which call the same libm;
# - OpenBLAS picks a BLAS kernel: the Jansen-Lorenz observer's discretisation (scipy.linalg.expm at construction),
#   the least-squares and linear solves of the hand-overs to the LPV parts and to the Jansen-Lorenz observer, the
#   identification's fits;
# - numpy picks SIMD paths (AVX2, AVX-512) for its element-wise functions and sums: the summaries' error numbers,
#   the hand-overs.
# A noisy, quantised closed loop turns a last-bit difference into another trajectory within a second, for which no
# tolerance holds: the kernels are fixed instead, to ones every x86-64 CPU runs. libm: its SSE2 variants;
# OpenBLAS: Prescott's kernel (SSE3), one thread; numpy: its baseline (every dispatched feature off). Then the check
# does not depend on the host's CPU (docs/golden.md: what differs otherwise).
LIBM_ENV = {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4"}
BLAS_ENV = {"OPENBLAS_CORETYPE": "Prescott", "OPENBLAS_NUM_THREADS": "1"}


def numpy_baseline_env() -> dict[str, str]:
    """NPY_DISABLE_CPU_FEATURES naming every CPU feature this numpy build dispatches to (its baseline stays)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__
    except ImportError:  # another numpy layout: the host's paths
        return {}
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(__cpu_dispatch__)} if __cpu_dispatch__ else {}


def rig_file(rig: str, engine: str, work: Path) -> Path:
    """A copy of ``rigs/RIG.toml`` whose mock plant runs on ``engine``."""
    import tomlkit

    from bench.core.config import resolve

    doc = tomlkit.parse(resolve(rig).read_text(encoding="utf-8"))
    if "mock" not in doc:
        doc["mock"] = tomlkit.table()
    doc["mock"]["engine"] = engine
    path = work / f"{rig}.{engine}.toml"
    path.write_text(tomlkit.dumps(doc), encoding="utf-8")
    return path


def _engines_ran(summary: dict[str, Any], want: dict[str, str]) -> None:
    """The run ran on the engines asked for (an engine that cannot load falls back with a note: not this run)."""
    got = summary.get("engines") or {}
    if any(got.get(k) != v for k, v in want.items()):
        raise RuntimeError(f"asked for the engines {want}, ran on {got}; warnings: {summary.get('warnings')}")


@dataclass(frozen=True)
class LogRun:
    """``bench run --lockstep``: its log's columns and events, and its summary."""

    name: str
    rig: str
    scenario: str
    duration: float | None = None
    params: dict[str, Any] = field(default_factory=dict)
    switches: tuple[tuple[float, str, str], ...] = ()  # scheduled (--switch T:PART=CHOICE)
    seed: int = 0
    engines: tuple[str, ...] = ENGINES
    what: str = ""

    def command(self) -> str:
        args = [f"bench run --rig {self.rig} --scenario {self.scenario} --seed {self.seed} --lockstep"]
        args += [f"--duration {self.duration:g}"] if self.duration is not None else []
        args += [f"-p {k}={v}" for k, v in self.params.items()]
        args += [f"--switch {t:g}:{p}={c}" for t, p, c in self.switches]
        return " ".join(args)

    def execute(self, engine: str, work: Path, mcap: bool = False) -> dict[str, Any]:
        """The run on ``engine``; ``mcap``: as ``bench run`` writes it (the MCAP log, summary.json from it, the plot)
        and digested from the file, else with the per-tick record in memory (as sweep cases run: no writer, no
        plot). Both give the same digest."""
        from bench.runtime.session import RunOptions, run

        log = work / f"{self.name}.{engine}.mcap"
        summary, code = run(RunOptions(rig=str(rig_file(self.rig, engine, work)), scenario=self.scenario,
                                       duration=self.duration, realtime=False, seed=self.seed,
                                       params={**self.params, "engine": engine}, switches=self.switches,
                                       log=log if mcap else None, log_enabled=mcap, force=True, progress=False))  # fmt: skip
        _engines_ran(summary, {"plant": engine, "controller": engine})
        T_s = _T_s(self.rig)
        per_tick = digest.from_mcap(log, T_s) if mcap else digest.from_memory(summary["record"], T_s)
        return {"log": per_tick, "summary": digest.normalise_summary(summary), "exit_code": code}


@dataclass(frozen=True)
class IdentifyRun:
    """``bench identify --lockstep``: the identification result (identify.json without its paths), the log and
    the summary of its session. The identification controller has one engine; the plant has two."""

    name: str
    rig: str
    seed: int = 0
    engines: tuple[str, ...] = ENGINES
    what: str = ""
    PATHS = ("log", "run_plot", "plots", "json")  # output paths, not results

    def command(self) -> str:
        return f"bench identify --rig {self.rig} --seed {self.seed} --lockstep"

    def execute(self, engine: str, work: Path, mcap: bool = True) -> dict[str, Any]:
        from bench.workflows.commission.identify import identify

        res = identify(str(rig_file(self.rig, engine, work)), seed=self.seed, out_dir=work / f"identify.{engine}",
                       realtime=False)  # fmt: skip
        if "tripped" in res:
            raise RuntimeError(f"the identification did not finish: {res['tripped']}")
        folder = Path(res["log"]).parent
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        _engines_ran(summary, {"plant": engine})
        return {"log": digest.from_mcap(folder / "run.mcap", _T_s(self.rig)),
                "summary": digest.normalise_summary(summary),
                "result": {k: v for k, v in res.items() if k not in self.PATHS}}


@dataclass(frozen=True)
class AtlasRun:
    """Every ``every``-th case of the robustness atlas' two sweeps (sweeps/atlas-*.toml, in their expansion order)
    through the batch engine, as `bench sweep --batch` runs them (`bench.workflows.sweep.batching`): their results rows.
    The batch engine is compiled only (its Python twin is the scalar session, whose error numbers differ from it in the
    last digits by design: bench.batch.engine `rows_differ`), so this run has one engine."""

    name: str
    sweeps: tuple[str, ...]
    every: int
    sample_every: int = 10  # rows kept whole (the others as hashes: 1000 whole rows would be ~1 MB)
    engines: tuple[str, ...] = ("batch",)
    what: str = ""
    # results-row columns of the wall clock and the host (the batch engine leaves compute_us_* empty)
    VOLATILE = ("wall_time", "realtime_factor", "case_wall_time", "worker", "compute_us_p50", "compute_us_p99",
                "compute_us_max")  # fmt: skip

    def command(self) -> str:
        return f"every {self.every}th case of {' + '.join(self.sweeps)} on the batch engine"

    def cases(self) -> list[Any]:
        from bench.workflows.sweep.cases import expand
        from bench.workflows.sweep.spec import load

        cases = [c for s in self.sweeps for c in expand(load(ROOT / "sweeps" / s))]
        return cases[:: self.every]

    def execute(self, engine: str, work: Path, mcap: bool = False) -> dict[str, Any]:
        from bench.workflows.sweep.batching import DEFAULT_BATCH, group, run_group

        cases = self.cases()
        groups, singles = group(cases, DEFAULT_BATCH, workers=2)
        if singles:
            raise RuntimeError(f"{len(singles)} case(s) the batch engine does not take, e.g. {singles[0].params}")
        by_id = {r["case_id"]: r for g in groups for r in run_group(g)}
        rows = [by_id[c.case_id] for c in cases]
        scalar = [r["case_id"] for r in rows if r.get("compute_us_p50") is not None or r["status"] == "error"]
        if scalar:  # run_group falls back to the scalar engine for a case it turns down: not this run's engine
            raise RuntimeError(f"{len(scalar)} case(s) did not run on the batch engine, e.g. {scalar[0]}")
        return {"rows": digest.table([{k: v for k, v in r.items() if k not in self.VOLATILE} for r in rows],
                                     self.sample_every)}


def _T_s(rig: str) -> float:
    from bench.core.config import load

    return load(rig).T_s


HOLD_SWITCHES = (  # every part, both ways, at the rated point (scenario hold: 297 rad/s, 10 N m from 1 s)
    (1.5, "observer", "lpv"), (1.8, "current_controller", "lpv"), (2.1, "speed_controller", "lpv"),
    (2.6, "speed_controller", "pi"), (2.9, "observer", "jl"), (3.2, "speed_source", "estimate"),
    (3.6, "speed_source", "encoder"), (3.9, "observer", "kubota"), (4.2, "observer", "voltage_model"),
    (4.5, "current_controller", "pi"), (4.8, "observer", "current_model"), (5.1, "controller", "relay_tune"),
    (5.4, "controller", "foc"),
)  # fmt: skip

RUNS: dict[str, LogRun | IdentifyRun | AtlasRun] = {r.name: r for r in (
    LogRun("fig5.7", "mock", "fig5.7", 10.0, what="Fig. 5.7's load cycle, 10 s, the default FOC"),
    LogRun("hold-switches", "mock", "hold", params={"speed_estimator": "rotor_equation"}, switches=HOLD_SWITCHES,
           what="the rated point with scheduled switches of every part and of the whole controller"),
    LogRun("warmup-mras", "mock-warm-fast", "warmup", params={"rr_adapt": "mras"},
           what="a warming rotor with the on-line R_r estimate"),
    IdentifyRun("identify-mock-real", "mock-real", what="standstill identification on the mock with inverter errors"),
    AtlasRun("atlas", ("atlas-observers.toml", "atlas-controllers.toml"), 14,
             what="1000 cases of the robustness atlas on the batch engine"),
)}  # fmt: skip


def execute(name: str, engine: str, work: Path, mcap: bool = False) -> dict[str, Any]:
    """Today's digest of run ``name`` on ``engine`` (as it reads back from JSON)."""
    return json.loads(json.dumps(RUNS[name].execute(engine, work, mcap)))


def path(name: str) -> Path:
    return DATA / f"{name}.json"


def recorded(name: str) -> dict[str, Any]:
    return json.loads(path(name).read_text(encoding="utf-8"))

