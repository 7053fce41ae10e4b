"""A sweep spec expanded into cases, and one case run as an ordinary lockstep session.

A `Case` is plain data (it travels to Dask workers): the scenario, seed, controller parameters, the
plant mismatch and the resulting rig-file dictionary. Its ``case_id`` is a hash of what the run
depends on (effective rig, controller, parameters, scenario, duration, seed), so a resumed sweep
recognises a finished case however the spec spelled it. `run_case` runs it through
`bench.runtime.session.run` (no per-tick log unless a log folder is given) and returns one results row.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.workflows.sweep import plant as plant_keys, tasks
from bench.workflows.sweep.spec import SweepSpec
from bench.core import scenarios
from bench import controllers
from bench.errors import BadInput
from bench.core.setpoints import Margins
from bench.core.outputs import write_text

STATUSES = ("ok", "tripped", "error")


@dataclass(frozen=True)
class Case:
    index: int  # position in the spec's expansion
    case_id: str
    scenario: str
    seed: int
    duration: float | None
    controller: str
    params: dict[str, Any]  # what the spec sets (the controller's defaults fill the rest)
    plant: dict[str, float | int]  # every plant key the spec names, effective value
    labels: dict[str, str]  # variant dimension -> label
    rig: dict[str, Any] = field(repr=False)  # rig-file dictionary with the plant applied
    scenario_args: dict[str, float] = field(default_factory=dict)  # what the spec sets of a parameterised scenario

    def inputs(self) -> dict[str, Any]:
        """The row's input columns."""
        row: dict[str, Any] = {"case_id": self.case_id, "index": self.index, "scenario": self.scenario,
                               "seed": self.seed, "duration_set": self.duration, "controller": self.controller}  # fmt: skip
        row.update({f"label.{k}": v for k, v in self.labels.items()})
        row.update({f"params.{k}": v for k, v in self.params.items()})
        row.update({f"plant.{k}": v for k, v in self.plant.items()})
        row.update({f"scenario.{k}": v for k, v in self.scenario_args.items()})
        return row

    def rig_toml(self) -> str:
        """The case's rig file (for `bench run --rig FILE` to rerun it alone)."""
        import tomlkit

        return tomlkit.dumps(self.rig)

    def bench_run_args(self, rig_file: str) -> list[str]:
        """``bench run`` arguments that run this case alone (with ``rig_file`` holding `rig_toml`)."""
        args = ["run", "--rig", rig_file, "--controller", self.controller, "--scenario", self.scenario,
                "--seed", str(self.seed), "--lockstep"]  # fmt: skip
        if self.duration is not None:
            args += ["--duration", repr(self.duration)]
        for k, v in self.params.items():
            args += ["-p", f"{k}={json.dumps(v)}"]
        for k, v in self.scenario_args.items():
            args += ["--scenario-arg", f"{k}={v!r}"]
        return args


def _sample(spec: SweepSpec) -> list[dict[str, float]]:
    """The random or Latin-hypercube points of ``[design.ranges]`` (one dict per sample)."""
    if spec.kind == "grid":
        return [{}]
    keys = list(spec.ranges)
    lo = np.array([spec.ranges[k][0] for k in keys])
    hi = np.array([spec.ranges[k][1] for k in keys])
    if spec.kind == "lhs":
        from scipy.stats import qmc

        u = qmc.LatinHypercube(d=len(keys), seed=np.random.default_rng(spec.design_seed)).random(spec.samples)
    else:
        u = np.random.default_rng(spec.design_seed).random((spec.samples, len(keys)))
    pts = lo + u * (hi - lo)
    return [{k: float(p[i]) for i, k in enumerate(keys)} for p in pts]


def _hash(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _inputs(spec: SweepSpec, vs: tuple, axes_point: Any, smp: dict[str, float], schema: dict[str, Any]
            ) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:  # fmt: skip
    """One case's controller parameters, plant values and scenario arguments: the spec's, then its variants',
    its point on the axes, its random sample (integers rounded where the parameter is one)."""
    params, plant, scn_args = dict(spec.params), dict(spec.plant), dict(spec.scenario_args)
    for v in vs:
        params.update(v.params)
        plant.update(v.plant)
    for (key, _), val in axes_point:
        group, sub = key.split(".", 1)
        {"params": params, "plant": plant, "scenario": scn_args}[group][sub] = val
    for key, val in smp.items():
        group, sub = key.split(".", 1)
        if group == "scenario":
            scn_args[sub] = val
        elif group == "params":
            params[sub] = int(round(val)) if schema[sub].kind == "int" else val
        else:
            plant[sub] = int(round(val)) if plant_keys.KEYS[sub].integer else val
    return params, plant, scn_args


def _rig_of(rig_base: dict[str, Any], base_mock: dict[str, Any], plant: dict[str, Any], pkey: str
            ) -> tuple[dict[str, Any], str, Margins]:  # fmt: skip
    """The mock rig of a case's plant values, validated (`bench.core.config.parse`: one line naming the plant if the
    rig file would refuse it), the hash of its configuration and its set-point margins."""
    from bench.core.config import parse

    rig = {**rig_base, "mock": plant_keys.apply(base_mock, plant)}
    try:
        cfg = parse(rig, None)
    except BadInput as exc:
        raise BadInput(f"plant {pkey}", f"the mock rig refuses it: {exc}") from None
    d = {k: v for k, v in cfg.as_dict().items() if k != "path"}
    # the plant engine does not change a run (bit-identical, tests/test_compiled_plant.py):
    # not part of the case; sweeps take the compiled one where numba imports
    d["mock"] = {k: v for k, v in d["mock"].items() if k != "engine"}
    rig["mock"].setdefault("engine", "auto")
    return rig, _hash(d), Margins.of_rig(cfg)


def _task_cases(spec: SweepSpec) -> list[tasks.TaskCase]:
    """Every case of a task sweep, in a fixed order: variants, axes, samples (like the session sweeps)."""
    task = tasks.get(spec.task)
    dims = list(spec.variants.items())
    axes = list(spec.axes.items())
    cases: list[tasks.TaskCase] = []
    for vs in itertools.product(*(v for _, v in dims)):
        for point in itertools.product(*(vals for _, vals in axes)):
            for smp in _sample(spec):
                args = {k: a.default for k, a in task.args.items()}
                args.update(spec.task_args)
                for v in vs:
                    args.update(v.args)
                for (key, _), val in zip(axes, point):
                    args[key.split(".", 1)[1]] = val
                for key, val in smp.items():
                    sub = key.split(".", 1)[1]
                    args[sub] = int(round(val)) if task.args[sub].kind == "int" else val
                cid = _hash({"task": task.name, "args": args})
                cases.append(tasks.TaskCase(len(cases), cid, task.name, args,
                                            {d: v.label for (d, _), v in zip(dims, vs)}))
    if len({c.case_id for c in cases}) != len(cases):
        raise BadInput("design", "two cases of the spec are the same computation (same task arguments)")
    return cases


def expand(spec: SweepSpec) -> list[Case]:
    """Every case of the spec, in a fixed order: scenario, variants, axes, samples, seed.

    Every case's rig is validated here (`bench.core.config.parse`): a mismatch the rig file would refuse
    (e.g. leakage that makes L_m^2 >= L_s L_r) stops the sweep before anything runs; so does a case whose scenario
    arguments, the defaults of those the spec leaves out included, or its own profile over the run leave the rig's
    set-point margins (`bench.core.scenarios.check_arguments`, `check_profile`, `bench.core.setpoints`).
    """
    if spec.task:  # a computation sweep
        return _task_cases(spec)  # type: ignore[return-value]
    schema = _controller_schema(spec.controller)
    base_mock = spec.rig_data.get("mock", {})
    base_plant = plant_keys.base_values(base_mock)
    named_plant = set(spec.plant) | {k.split(".", 1)[1] for k in (*spec.axes, *spec.ranges) if k.startswith("plant.")}
    named_plant |= {k for vs in spec.variants.values() for v in vs for k in v.plant}
    named_params = set(spec.params) | {k.split(".", 1)[1] for k in (*spec.axes, *spec.ranges) if k.startswith("params.")}
    named_params |= {k for vs in spec.variants.values() for v in vs for k in v.params}
    rig_base = {k: v for k, v in spec.rig_data.items() if k != "mock"}
    rigs: dict[str, tuple[dict[str, Any], str, Margins]] = {}  # plant key -> (rig dict, hash of its config, margins)
    inside: set[str] = set()  # the (scenario, arguments, margins) found inside the margins already

    samples = _sample(spec)
    dims = list(spec.variants.items())
    axes = list(spec.axes.items())
    cases: list[Case] = []
    for scn in spec.scenarios:
        for vs in itertools.product(*(v for _, v in dims)):
            for point in itertools.product(*(vals for _, vals in axes)):
                for smp in samples:
                    params, plant, scn_args = _inputs(spec, vs, zip(axes, point), smp, schema)
                    full_params = {k: params.get(k, schema[k].default) for k in sorted(named_params)}
                    full_plant = {k: plant.get(k, base_plant[k]) for k in sorted(named_plant)}
                    pkey = json.dumps(plant, sort_keys=True)
                    if pkey not in rigs:
                        rigs[pkey] = _rig_of(rig_base, base_mock, plant, pkey)
                    rig, rig_hash, margins = rigs[pkey]
                    key = json.dumps([scn, scn_args, repr(margins)], sort_keys=True)
                    if key not in inside:
                        checked = scenarios.check_arguments(scn, scn_args, margins)  # BadInput naming the argument
                        scenarios.check_named(scn, checked, margins, spec.duration)  # and its own profile
                        inside.add(key)
                    labels = {d: v.label for (d, _), v in zip(dims, vs)}
                    for seed in spec.seeds:
                        # the controller's engine does not change a run either (tests/test_compiled_foc.py)
                        effective = {k: params.get(k, p.default) for k, p in schema.items() if k != "engine"}
                        what = {"rig": rig_hash, "controller": spec.controller, "params": effective, "scenario": scn,
                                "duration": spec.duration, "seed": seed}  # fmt: skip
                        if scn_args:  # (only then: the cases of sweeps without them keep their ids)
                            what["scenario_args"] = scenarios.check_arguments(scn, scn_args)
                        cases.append(Case(len(cases), _hash(what), scn, seed, spec.duration, spec.controller,
                                          full_params, full_plant, labels, rig, scn_args))  # fmt: skip
    ids = [c.case_id for c in cases]
    if len(set(ids)) != len(ids):
        raise BadInput("design", "two cases of the spec are the same run (same plant, parameters, scenario, seed)")
    return cases


def _controller_schema(name: str) -> dict[str, Any]:
    return controllers.available()[name].schema


def _flat(prefix: str, d: Any) -> dict[str, Any]:
    if not isinstance(d, dict):
        return {}
    return {f"{prefix}_{k}": v for k, v in d.items() if isinstance(v, (int, float, bool)) or v is None}


def summary_row(summary: dict[str, Any]) -> dict[str, Any]:
    """The output columns of one session summary (`bench.runtime.session.run`)."""
    ls = summary.get("load_steps") or {}
    timing = (summary.get("timing") or {}).get("compute_us") or {}
    cause = summary.get("trip_cause")
    row: dict[str, Any] = {
        "status": "tripped" if cause else "ok", "error": None, "exit_code": summary.get("exit_code"),
        "trip_cause": cause, "trip_time": summary.get("trip_time"), "ticks": summary.get("ticks"),
        "sim_time": summary.get("duration"), "wall_time": summary.get("wall_time"),
        "realtime_factor": summary.get("realtime_factor"), "deadline_misses": summary.get("deadline_misses"),
        "overruns": summary.get("overruns"),
        "compute_us_p50": timing.get("p50"), "compute_us_p99": timing.get("p99"), "compute_us_max": timing.get("max"),
        "load_steps": ls.get("count"), "load_dip_max": ls.get("peak_deviation_max"),
        "load_dip_mean": ls.get("peak_deviation_mean"), "load_recovery_mean": ls.get("recovery_time_1rad_s_mean"),
    }  # fmt: skip
    row.update(_flat("speed_error", summary.get("speed_error")))
    row.update(_flat("speed_error_settled", summary.get("speed_error_settled")))
    row.update(_flat("i_mR_error", summary.get("i_mR_error")))
    est = {k: v for k, v in (summary.get("estimation_errors") or {}).items() if k != "tripped"}
    row.update({f"est_{k}": v for k, v in est.items()})
    row["warnings"] = "; ".join(summary.get("warnings") or ()) or None
    return row


def run_session(case: Case, log_dir: Path | None = None) -> dict[str, Any]:
    """The session of one case (`bench.runtime.session.run`); returns its summary."""
    from bench.core.config import parse
    from bench.runtime.session import RunOptions, run

    cfg = parse(case.rig, None)
    params = dict(case.params)
    if "engine" in _controller_schema(case.controller):  # the FOC: compiled where it applies, as the plant
        params.setdefault("engine", "auto")
    opts = RunOptions(rig=cfg, controller=case.controller, scenario=case.scenario,
                      scenario_args=dict(case.scenario_args), duration=case.duration,
                      realtime=False, seed=case.seed, params=params, progress=False,
                      log_enabled=log_dir is not None, label=f"case {case.case_id}")  # fmt: skip
    if log_dir is not None:
        opts.log, opts.force = log_dir / f"{case.case_id}.mcap", True

        write_text(log_dir / f"{case.case_id}.rig.toml", case.rig_toml())  # whole or not at all (a full disk)
    summary, _ = run(opts)
    return summary


def run_case(case: Case, log_dir: str | None = None) -> dict[str, Any]:
    """One results row: the case's inputs and its summary numbers; an exception is recorded, never raised."""
    t0 = time.perf_counter()
    row = case.inputs()
    try:
        summary = run_session(case, Path(log_dir) if log_dir else None)
        row.update(summary_row(summary))
        if log_dir:
            row["log"] = summary.get("log")
    except Exception as exc:  # noqa: BLE001 - the sweep goes on; the row says what happened
        row.update(error_row(f"{type(exc).__name__}: {exc}", traceback.format_exc(limit=-3)))
    row["case_wall_time"] = time.perf_counter() - t0
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


def error_row(error: str, detail: str | None = None) -> dict[str, Any]:
    """Output columns of a case that raised (or whose worker died twice)."""
    return {"status": "error", "error": error, "error_detail": detail}
