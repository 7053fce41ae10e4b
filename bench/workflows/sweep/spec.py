"""The sweep file (TOML), validated into a `SweepSpec`; every error names the field in one line.

::

    [sweep]
    name = "smoke"               # default: the file name
    rig = "mock"                 # base rig file (driver "mock"); its [motor] is the controllers' model
    controller = "foc"
    scenarios = ["fig5.7"]       # each case runs one; crossed with everything below
    duration = 1.0               # [s], optional (default: each scenario's own)
    seeds = [0, 1]               # run seeds (sensor noise); crossed

    [params]                     # fixed controller parameters, as -p NAME=VALUE of bench run
    speed_Kp = 0.6
    [plant]                      # fixed plant mismatch (bench.workflows.sweep.plant.KEYS)
    R_r = 1.2
    [scenario]                   # a parameterised scenario's arguments (bench scenarios; load-step: speed, load)
    speed = 80.0

    [design]
    kind = "grid"                # grid | random | lhs (Latin hypercube, scipy.stats.qmc)
    samples = 100                # random / lhs: points drawn from [design.ranges]
    seed = 0                     # random / lhs: the design's seed
    [design.axes]                # full factorial over these values
    "params.observer" = ["current_model", "jl"]
    "plant.R_r" = [1.0, 1.5]
    [design.ranges]              # random / lhs: uniform in [lo, hi]
    "plant.R_s" = [0.8, 1.2]
    "scenario.load" = [0.0, 6.0]  # axes and ranges take "scenario.ARG" too
    [[design.variants.mode]]     # named bundles of params and plant settings, crossed; `label` names each
    label = "sensorless"
    params = { speed_source = "estimate", speed_estimator = "kubota" }

Precedence where one case gets a value from several places: ``[params]``/``[plant]`` <
variants < axes < ranges; one name may not be both an axis and a range.

A computation sweep (`bench.workflows.sweep.tasks`) names a task instead of a rig and a controller; its arguments
are ``[task]`` (fixed), ``"task.NAME"`` axes and ranges, and ``args`` of variants::

    [sweep]
    task = "flux_observer_gamma"
    [task]
    variant = "full"
    [design.axes]
    "task.omega_r_max" = [10, 100, 400]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.errors import BadInput, allowed
from bench.core.setpoints import Margins
from bench.workflows.sweep import plant as plant_keys, tasks
from bench import controllers
from bench.core import scenarios

DESIGNS = ("grid", "random", "lhs")
MAX_CASES = 1_000_000
LARGE_CASES = 100_000  # more than this runs only with --allow-large (a typo in an axis multiplies)
_TOP = ("sweep", "params", "plant", "scenario", "design", "task")
_SWEEP = ("name", "description", "rig", "controller", "scenarios", "duration", "seeds", "task")
_SESSION_ONLY = ("rig", "controller", "scenarios", "duration", "seeds")
_DESIGN = ("kind", "samples", "seed", "axes", "ranges", "variants")


@dataclass(frozen=True)
class Variant:
    """One named bundle of a variant dimension."""

    label: str
    params: dict[str, Any] = field(default_factory=dict)
    plant: dict[str, float | int] = field(default_factory=dict)
    args: dict[str, Any] = field(default_factory=dict)  # task sweeps


@dataclass(frozen=True)
class SweepSpec:
    name: str
    description: str
    rig: str  # path of the base rig file
    rig_data: dict[str, Any]  # its TOML content
    controller: str
    scenarios: tuple[str, ...]
    duration: float | None
    seeds: tuple[int, ...]
    params: dict[str, Any]
    plant: dict[str, float | int]
    kind: str
    samples: int
    design_seed: int
    axes: dict[str, tuple[Any, ...]]  # "params.x" / "plant.y" / "scenario.z" -> values
    ranges: dict[str, tuple[float, float]]
    variants: dict[str, tuple[Variant, ...]]
    source: str = ""  # the file's text
    task: str | None = None  # a computation sweep (bench.workflows.sweep.tasks) instead of sessions
    task_args: dict[str, Any] = field(default_factory=dict)  # its fixed arguments
    scenario_args: dict[str, float] = field(default_factory=dict)  # [scenario]: fixed arguments of the scenarios


def _table(name: str, v: Any) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise BadInput(name, f"must be a table, got {v!r}")
    return v


def _known(name: str, table: dict[str, Any], keys: tuple[str, ...]) -> None:
    for k in table:
        if k not in keys:
            raise BadInput(f"{name}.{k}" if name else k, f"unknown field; allowed: {allowed(keys)}")


def _int(name: str, v: Any, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise BadInput(name, f"must be an integer in {lo}..{hi}, got {v!r}")
    return v


def _schema(controller: str) -> dict[str, Any]:
    table = controllers.available()
    if controller not in table:
        raise BadInput("sweep.controller", f"unknown controller {controller!r}; allowed: {allowed(sorted(table))}")
    return table[controller].schema


def _param(name: str, schema: dict[str, Any], key: str, value: Any) -> Any:
    if key not in schema:
        raise BadInput(name, f"unknown parameter {key!r}; allowed: {allowed(sorted(schema))}")
    return schema[key].check(name, value)


def _dotted(name: str, key: str, task: bool = False) -> tuple[str, str]:
    """``"params.observer"`` -> ("params", "observer"); ``"plant.R_r"`` -> ("plant", "R_r"); ``"task.x"``."""
    group, _, sub = key.partition(".")
    if task:
        if group != "task" or not sub:
            raise BadInput(name, "names a task argument as \"task.NAME\"")
    elif group not in ("params", "plant", "scenario") or not sub:
        raise BadInput(name, "names a controller parameter as \"params.NAME\", a plant key as \"plant.NAME\" or a "
                             "scenario argument as \"scenario.NAME\"")
    return group, sub


def _value(name: str, group: str, sub: str, schema: dict[str, Any], v: Any, scns: tuple[str, ...] = (),
           margins: Margins | None = None) -> Any:  # fmt: skip
    if group == "task":
        return _task_arg(name, schema, sub, v)
    if group == "scenario":
        return _scenario_arg(name, scns, sub, v, margins)
    return _param(name, schema, sub, v) if group == "params" else plant_keys.check(name, sub, v)


def _scenario_arg(name: str, scns: tuple[str, ...], key: str, v: Any, margins: Margins | None) -> float:
    """An argument of every scenario of the sweep, inside the rig's set-point ``margins``
    (`bench.core.scenarios.check_arguments`), BadInput naming ``name``."""
    for scn in scns:
        try:  # (this value alone: an axis or a range may set the other arguments)
            v = scenarios.check_argument(scn, key, v, margins)
        except BadInput as exc:
            raise BadInput(name, exc.problem) from None
    return v


def _task_arg(name: str, args: dict[str, Any], key: str, v: Any) -> Any:
    if key not in args:
        raise BadInput(name, f"unknown task argument {key!r}; allowed: {allowed(sorted(args))}")
    return args[key].check(name, v)


def parse(data: dict[str, Any], *, name: str = "sweep", source: str = "") -> SweepSpec:
    """Validate a sweep-file dictionary (raises `BadInput` naming the field)."""
    from bench.core.config import parse as parse_rig
    from bench.core.config import read_toml, resolve

    _known("", data, _TOP)
    sw = _table("sweep", data.get("sweep", {}))
    _known("sweep", sw, _SWEEP)
    name = sw.get("name", name)
    if not isinstance(name, str) or not name.strip() or any(c in name for c in "/\\\n\0"):
        raise BadInput("sweep.name", f"must be a non-empty name without slashes, got {name!r}")
    desc = sw.get("description", "")
    if not isinstance(desc, str):
        raise BadInput("sweep.description", f"must be a string, got {desc!r}")
    task = sw.get("task")
    if task is not None:
        return _parse_task(data, sw, task, name, desc, source)
    if "task" in data:
        raise BadInput("task", "only with [sweep] task = \"NAME\" (a computation sweep)")
    rig = sw.get("rig", "mock")
    if not isinstance(rig, str):
        raise BadInput("sweep.rig", f"must be a rig name or path, got {rig!r}")
    try:
        rig_path = resolve(rig)
        rig_data = read_toml(rig_path, "a rig file")[0]
    except BadInput as exc:
        raise BadInput("sweep.rig", f"{rig!r}: {exc.problem}") from None
    driver = rig_data.get("rig", {}).get("driver", "mock") if isinstance(rig_data.get("rig"), dict) else None
    if driver != "mock":
        raise BadInput("sweep.rig", f"a sweep runs on a mock rig (rig.driver = \"mock\"), {rig!r} has {driver!r}")
    try:  # the set-point margins of its limits: every scenario value of the sweep stays inside them
        margins = Margins.of_rig(parse_rig(rig_data, str(rig_path)))
    except BadInput as exc:
        raise BadInput("sweep.rig", f"{rig!r}: {exc}") from None
    controller = sw.get("controller", "foc")
    if not isinstance(controller, str):
        raise BadInput("sweep.controller", f"must be a controller name, got {controller!r}")
    schema = _schema(controller)
    scns = sw.get("scenarios", ["demo"])
    if not isinstance(scns, list) or not scns or len(set(map(str, scns))) != len(scns):
        raise BadInput("sweep.scenarios", f"must be a non-empty list of distinct scenario names, got {scns!r}")
    for s in scns:
        try:
            scenarios.get(s)
        except BadInput as exc:
            raise BadInput("sweep.scenarios", exc.problem) from None
    duration = sw.get("duration")
    if duration is not None and (isinstance(duration, bool) or not isinstance(duration, (int, float))
                                 or not math.isfinite(duration) or not 0.01 <= duration <= 3600):  # fmt: skip
        raise BadInput("sweep.duration", f"must be a number in [0.01, 3600] s, got {duration!r}")
    seeds = sw.get("seeds", [0])
    if not isinstance(seeds, list) or not seeds:
        raise BadInput("sweep.seeds", f"must be a non-empty list of integers, got {seeds!r}")
    seeds = [_int("sweep.seeds", s, 0, (1 << 63) - 1) for s in seeds]
    if len(set(seeds)) != len(seeds):
        raise BadInput("sweep.seeds", f"must be distinct, got {seeds!r}")

    params = {k: _param(f"params.{k}", schema, k, v) for k, v in _table("params", data.get("params", {})).items()}
    plant = {k: plant_keys.check(f"plant.{k}", k, v) for k, v in _table("plant", data.get("plant", {})).items()}
    scn_args = {k: _scenario_arg(f"scenario.{k}", tuple(scns), k, v, margins)
                for k, v in _table("scenario", data.get("scenario", {})).items()}  # fmt: skip

    kind, samples, design_seed, axes, ranges, variants = _design(data, schema, task=False, scns=tuple(scns),
                                                                 margins=margins)  # fmt: skip

    spec = SweepSpec(name=name, description=desc, rig=str(rig_path), rig_data=rig_data, controller=controller,
                     scenarios=tuple(scns), duration=None if duration is None else float(duration),
                     seeds=tuple(seeds), params=params, plant=plant, kind=kind,
                     samples=samples if kind != "grid" else 1, design_seed=design_seed, axes=axes, ranges=ranges,
                     variants=variants, source=source or _toml(data), scenario_args=scn_args)  # fmt: skip
    n = count(spec)
    if n > MAX_CASES:
        raise BadInput("design", f"{n} cases; at most {MAX_CASES} in one sweep")
    return spec


def _design(data: dict[str, Any], schema: dict[str, Any], task: bool, scns: tuple[str, ...] = (),
            margins: Margins | None = None) -> tuple[Any, ...]:  # fmt: skip
    """``[design]``: kind, samples, seed, axes, ranges, variants (``schema``: the controller's or the task's;
    ``scns``: the scenarios, whose arguments "scenario.NAME" names, inside the rig's set-point ``margins``)."""
    des = _table("design", data.get("design", {}))
    _known("design", des, _DESIGN)
    kind = des.get("kind", "grid")
    if kind not in DESIGNS:
        raise BadInput("design.kind", f"must be one of {allowed(DESIGNS)}, got {kind!r}")
    samples = _int("design.samples", des.get("samples", 1 if kind == "grid" else 0), 1, MAX_CASES)
    design_seed = _int("design.seed", des.get("seed", 0), 0, (1 << 63) - 1)
    if kind == "grid" and "samples" in des:
        raise BadInput("design.samples", "only for kind = \"random\" or \"lhs\" (a grid has its axes' points)")

    axes: dict[str, tuple[Any, ...]] = {}
    for key, values in _table("design.axes", des.get("axes", {})).items():
        fname = f"design.axes.{key}"
        group, sub = _dotted(fname, key, task)
        if not isinstance(values, list) or not values:
            raise BadInput(fname, f"must be a non-empty list of values, got {values!r}")
        vals = tuple(_value(fname, group, sub, schema, v, scns, margins) for v in values)
        if len(set(map(repr, vals))) != len(vals):
            raise BadInput(fname, f"values must be distinct, got {values!r}")
        axes[key] = vals

    ranges: dict[str, tuple[float, float]] = {}
    rng_table = _table("design.ranges", des.get("ranges", {}))
    if rng_table and kind == "grid":
        raise BadInput("design.ranges", "only for kind = \"random\" or \"lhs\"; a grid lists values in [design.axes]")
    if kind != "grid" and not rng_table:
        raise BadInput("design.ranges", f"kind = {kind!r} needs at least one range, e.g. \"plant.R_r\" = [0.5, 1.5]")
    for key, lohi in rng_table.items():
        fname = f"design.ranges.{key}"
        group, sub = _dotted(fname, key, task)
        if key in axes:
            raise BadInput(fname, "is also an axis; give it in one place")
        if group == "scenario":
            pass  # a scenario's arguments are all numbers
        elif group == "params" and (sub not in schema or schema[sub].kind not in ("int", "float")):
            raise BadInput(fname, "a range needs a numeric controller parameter")
        if group == "task" and (sub not in schema or schema[sub].kind not in ("int", "float")):
            raise BadInput(fname, "a range needs a numeric task argument")
        if not isinstance(lohi, list) or len(lohi) != 2:
            raise BadInput(fname, f"must be [lo, hi], got {lohi!r}")
        lo, hi = (_value(fname, group, sub, schema, v, scns, margins) for v in lohi)
        if not lo < hi:
            raise BadInput(fname, f"needs lo < hi, got {lohi!r}")
        ranges[key] = (float(lo), float(hi))

    variants: dict[str, tuple[Variant, ...]] = {}
    for dim, items in _table("design.variants", des.get("variants", {})).items():
        fname = f"design.variants.{dim}"
        if dim in ("scenario", "seed", "case_id", "status") or "." in dim:
            raise BadInput(fname, "a variant dimension needs another name (no dots; not scenario, seed, status)")
        if not isinstance(items, list) or not items:
            raise BadInput(fname, "must be a non-empty array of tables ([[design.variants.NAME]])")
        out = []
        for i, it in enumerate(items):
            f_i = f"{fname}[{i}]"
            _known(f_i, _table(f_i, it), ("label", "args") if task else ("label", "params", "plant"))
            label = it.get("label")
            if not isinstance(label, str) or not label.strip():
                raise BadInput(f"{f_i}.label", f"must be a non-empty string, got {label!r}")
            if task:
                va = {k: _task_arg(f"{f_i}.args.{k}", schema, k, v)
                      for k, v in _table(f"{f_i}.args", it.get("args", {})).items()}  # fmt: skip
                out.append(Variant(label, args=va))
                continue
            vp = {k: _param(f"{f_i}.params.{k}", schema, k, v)
                  for k, v in _table(f"{f_i}.params", it.get("params", {})).items()}  # fmt: skip
            vq = {k: plant_keys.check(f"{f_i}.plant.{k}", k, v)
                  for k, v in _table(f"{f_i}.plant", it.get("plant", {})).items()}  # fmt: skip
            out.append(Variant(label, vp, vq))
        if len({v.label for v in out}) != len(out):
            raise BadInput(fname, "labels must be distinct")
        variants[dim] = tuple(out)

    return kind, samples, design_seed, axes, ranges, variants


def _toml(data: dict[str, Any]) -> str:
    import tomlkit

    try:
        return tomlkit.dumps(data)
    except Exception:  # noqa: BLE001 - only a copy for the results folder
        return "# (spec given as a dictionary that TOML cannot hold)\n"


def _parse_task(data: dict[str, Any], sw: dict[str, Any], task: Any, name: str, desc: str,
                source: str) -> SweepSpec:  # fmt: skip
    """A computation sweep: ``[sweep] task``, ``[task]`` fixed arguments, ``"task.NAME"`` in the design."""
    if not isinstance(task, str):
        raise BadInput("sweep.task", f"must be a task name, got {task!r}")
    schema = tasks.get(task).args
    for k in _SESSION_ONLY:
        if k in sw:
            raise BadInput(f"sweep.{k}", "not in a task sweep (it runs a computation, not bench sessions)")
    for k in ("params", "plant", "scenario"):
        if k in data:
            raise BadInput(k, "not in a task sweep; give the task's arguments in [task]")
    fixed = {k: _task_arg(f"task.{k}", schema, k, v) for k, v in _table("task", data.get("task", {})).items()}
    kind, samples, design_seed, axes, ranges, variants = _design(data, schema, task=True)
    spec = SweepSpec(name=name, description=desc, rig="", rig_data={}, controller="", scenarios=(), duration=None,
                     seeds=(), params={}, plant={}, kind=kind, samples=samples if kind != "grid" else 1,
                     design_seed=design_seed, axes=axes, ranges=ranges, variants=variants,
                     source=source or _toml(data), task=task, task_args=fixed)  # fmt: skip
    given = set(fixed) | {k.split(".", 1)[1] for k in (*axes, *ranges)}
    for a, arg in schema.items():
        in_all_variants = any(all(a in v.args for v in vs) for vs in variants.values())
        if arg.default is None and a not in given and not in_all_variants:
            raise BadInput(f"task.{a}", "is required: give it in [task], as an axis or range, or in every variant")
    n = count(spec)
    if n > MAX_CASES:
        raise BadInput("design", f"{n} cases; at most {MAX_CASES} in one sweep")
    return spec


def count(spec: SweepSpec) -> int:
    """Number of cases the spec expands to."""
    n = spec.samples if spec.task else len(spec.scenarios) * len(spec.seeds) * spec.samples
    for vals in (*spec.axes.values(), *spec.variants.values()):
        n *= len(vals)
    return n


def load(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file."""
    from bench.core.config import read_toml

    p = Path(path)
    data, text = read_toml(p, "a sweep file")
    return parse(data, name=p.stem, source=text)
