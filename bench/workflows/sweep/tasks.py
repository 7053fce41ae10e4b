"""Computation tasks on the sweep engine: synthesis and training jobs instead of bench sessions.

A sweep file with ``[sweep] task = "NAME"`` runs the registered task once per point of its design
(``"task.ARG"`` axes, ranges and ``args`` of variants; fixed values in ``[task]``) on the same Dask
engine as the session sweeps: resume by case hash, one retry for a dead worker, errors recorded,
``results.parquet``, progress. Tasks:

* ``flux_observer_gamma``: one point of Fig. 5.5, γ_a(ω_r,max) of the LPV flux observer (Thm 5.15 with
  bisection, 5.6.2) with its independent lower bound (`synthesis.lower_bound`);
* ``narx_candidate``: one candidate of the systematic chain (6.4.2): train the NARX MLP with one
  initialisation spread, then γ_a of the Fig. 6.13 set-up for its LFT (the pipeline's selection rule).

A task is a function of its arguments and a work folder (its own, ``DIR/tasks/CASE_ID``) returning a flat
dict of numbers and strings; a task that raises is recorded as an error row.
"""

from __future__ import annotations

import json
import math
import os
import socket
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.errors import BadInput, allowed
from bench.core.plotstyle import pyplot


@dataclass(frozen=True)
class Arg:
    """One task argument: kind ``float``/``int``/``str``/``path``, default (None: required), range or choices."""

    kind: str
    default: Any = None
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple[str, ...] = ()
    unit: str = ""

    def check(self, name: str, v: Any) -> Any:
        if self.kind in ("float", "int"):
            ok_type = isinstance(v, int) if self.kind == "int" else isinstance(v, (int, float))
            if isinstance(v, bool) or not ok_type or not math.isfinite(v) or not self.lo <= v <= self.hi:
                what = "an integer" if self.kind == "int" else "a number"
                raise BadInput(name, f"must be {what} in [{self.lo:g}, {self.hi:g}]{' ' + self.unit if self.unit else ''}, "
                                     f"got {v!r}")  # fmt: skip
            return int(v) if self.kind == "int" else float(v)
        if not isinstance(v, str) or not v:
            raise BadInput(name, f"must be a non-empty string, got {v!r}")
        if self.choices and v not in self.choices:
            raise BadInput(name, f"must be one of {allowed(self.choices)}, got {v!r}")
        if self.kind == "path" and not Path(v).exists():
            raise BadInput(name, f"{v!r} does not exist")
        return str(Path(v).resolve()) if self.kind == "path" else v


@dataclass(frozen=True)
class Task:
    name: str
    summary: str
    args: dict[str, Arg]
    fn: Callable[..., dict[str, Any]]  # fn(work_dir: Path, **args) -> outputs
    plot: Callable[[list[dict[str, Any]], Path], list[Path]] | None = None  # rows, folder -> PNGs (report)


# --- the tasks ------------------------------------------------------------------------------------
def _flux_observer_gamma(work: Path, omega_r_max: float, variant: str, numerics: str, sigma_i: float,
                         sigma_u: float, f_s: float) -> dict[str, Any]:  # fmt: skip
    """γ_a and the lower bound at one ω_r,max (one point of Fig. 5.5)."""
    from synthesis.models.flux_observer import gamma_curve

    import warnings

    kw: dict[str, Any] = {}
    if numerics == "diagonal":  # the earlier numerics: diagonal re-balancing, no escape (docs/results/synthesis.md)
        kw = {"rescale": "diagonal", "rescale_iters": 6}
    with warnings.catch_warnings():  # the solver's "inaccurate" notes: every candidate is re-checked
        warnings.simplefilter("ignore")
        (r,) = gamma_curve([omega_r_max], sigma_i, sigma_u, 1.0 / f_s, variant=variant, **kw)
    return {k: r[k] for k in ("gamma_a", "gamma_lower_bound", "gap", "n_solves")}


THESIS_GAMMA = 3e-4  # 5.6.2: γ = 1.1 γ_a = 0.0003 at ω_r,max = 200


def plot_fig5_5(curves: dict[str, list[dict[str, Any]]], path: Path) -> Path:
    """Fig. 5.5 from rows of the ``flux_observer_gamma`` task: γ_a (and its lower bound, where the rows
    have one) against ω_r,max, one curve per label, with the thesis' point."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    styles = ("o-", "s-", "x--", "^-", "v-")
    for k, (label, rows) in enumerate(curves.items()):
        rows = sorted(rows, key=lambda r: r["omega_r_max"])
        W = [r["omega_r_max"] for r in rows]
        color = f"C{k}" if "diagonal" not in label else "grey"
        ax.plot(W, [r["gamma_a"] for r in rows], styles[k % len(styles)], color=color, label=f"γ_a, {label}")
        if "diagonal" not in label:  # the bound is the same problem's; drawn once per reading
            ax.plot(W, [r["gamma_lower_bound"] for r in rows], ":", color=color, lw=2, label=f"lower bound, {label}")
    ax.plot([200], [THESIS_GAMMA / 1.1], "k*", ms=12, label="thesis γ_a = 0.0003/1.1 at 200 rad/s")
    ax.set_xlabel("ω_r,max [rad/s, electrical]")
    ax.set_ylabel("γ_a")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Fig. 5.5: achievable l2 gain of the LPV flux observer")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_flux_observer_gamma(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """Fig. 5.5 from the finished points: one curve per variant label (else per variant and numerics)."""
    curves: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if r["status"] != "ok":
            continue
        labels = [v for k, v in r.items() if k.startswith("label.")]
        name = ", ".join(labels) if labels else f"{r['task.variant']}, {r['task.numerics']}"
        curves.setdefault(name, []).append({"omega_r_max": r["task.omega_r_max"], "gamma_a": r["out.gamma_a"],
                                            "gamma_lower_bound": r["out.gamma_lower_bound"]})  # fmt: skip
    return [plot_fig5_5(curves, out / "fig5.5.png")] if curves else []


def _narx_candidate(work: Path, train_log: str, val_log: str, init_spread: float, max_nfev: int) -> dict[str, Any]:
    """Train one NARX candidate (6.4.2) and compute γ_a of its Fig. 6.13 set-up (the selection rule)."""
    import warnings

    from bench.workflows.narx import train
    from synthesis.models.speed_controller import gamma_a_of_model  # cvxpy: imported with a first NARX task

    s = train(Path(train_log), Path(val_log), work / "model", max_nfev=max_nfev, init_spread=init_spread,
              report_dir=work / "report", progress=lambda m: None)  # fmt: skip
    out = {"model": str(work / "model"), "report": s["report"],
           "rms_val": s["performance"]["val"]["mlp"]["rms_rad_s"],
           "rms_train": s["performance"]["train"]["mlp"]["rms_rad_s"],
           "arx_rms_val": s["performance"]["val"]["arx"]["rms_rad_s"],
           "lm_wall_s": s["training"]["wall_time"], "figures": json.dumps(s["figures"])}  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = gamma_a_of_model(work / "model")
    out.update(gamma_a=g["gamma_a"], gamma_lti=g["gamma_lti"], widths=",".join(f"{w:.6g}" for w in g["widths"]))
    return out


TASKS: dict[str, Task] = {
    "flux_observer_gamma": Task(
        "flux_observer_gamma", "γ_a(ω_r,max) of the LPV flux observer and its lower bound (Fig. 5.5)",
        {"omega_r_max": Arg("float", None, 1.0, 2000.0, unit="rad/s"),
         "variant": Arg("str", "full", choices=("full", "partial")),
         "numerics": Arg("str", "current", choices=("current", "diagonal")),
         "sigma_i": Arg("float", 1e-4, 1e-9, 1.0), "sigma_u": Arg("float", 1e-4, 1e-9, 1.0),
         "f_s": Arg("float", 3000.0, 100.0, 100_000.0, unit="Hz")},
        _flux_observer_gamma, _plot_flux_observer_gamma),
    "narx_candidate": Task(
        "narx_candidate", "one NARX candidate: LM training and γ_a of its Fig. 6.13 set-up (6.4.2)",
        {"train_log": Arg("path"), "val_log": Arg("path"), "init_spread": Arg("float", 1.0, 1e-6, 100.0),
         "max_nfev": Arg("int", 3000, 1, 1_000_000)},
        _narx_candidate),
}  # fmt: skip


def get(name: str, field_name: str = "sweep.task") -> Task:
    if name not in TASKS:
        raise BadInput(field_name, f"unknown task {name!r}; allowed: {allowed(sorted(TASKS))}")
    return TASKS[name]


# --- cases ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TaskCase:
    index: int
    case_id: str
    task: str
    args: dict[str, Any]  # every argument, defaults filled in
    labels: dict[str, str] = field(default_factory=dict)

    def inputs(self) -> dict[str, Any]:
        row: dict[str, Any] = {"case_id": self.case_id, "index": self.index, "task": self.task}
        row.update({f"label.{k}": v for k, v in self.labels.items()})
        row.update({f"task.{k}": v for k, v in self.args.items()})
        return row


def run_task(case: TaskCase, work_dir: str | None = None) -> dict[str, Any]:
    """One results row: inputs, status ``ok`` and the task's outputs, or ``error``; never raises."""
    t0 = time.perf_counter()
    row = case.inputs()
    task = TASKS[case.task]
    work = Path(work_dir or ".") / case.case_id
    try:
        work.mkdir(parents=True, exist_ok=True)
        out = task.fn(work, **case.args)
        row.update({"status": "ok", "error": None, "error_detail": None})
        row.update({f"out.{k}": v for k, v in out.items()})
    except Exception as exc:  # noqa: BLE001 - the sweep goes on; the row says what happened
        row.update({"status": "error", "error": f"{type(exc).__name__}: {exc}",
                    "error_detail": traceback.format_exc(limit=-3)})  # fmt: skip
    row["case_wall_time"] = time.perf_counter() - t0
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row
