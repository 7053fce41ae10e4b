"""Computation sweeps (`bench.workflows.sweep.tasks`): synthesis and training jobs as tasks of the sweep engine.

Fig. 5.5's grid (`sweeps/fig5.5.toml`) and the pipeline's NARX candidates run through the same engine as
the session sweeps; a task's row must hold what calling the computation directly gives.
"""

from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from bench.workflows.sweep import spec, table, tasks
from bench.workflows.sweep.cases import expand
from bench.workflows.sweep.engine import run_sweep

ROOT = Path(__file__).resolve().parents[1]
FIG5_5 = ROOT / "sweeps" / "fig5.5.toml"
TASK = {"sweep": {"task": "flux_observer_gamma"}}  # tests/test_sweep.py checks bad task specs too


def test_the_fig5_5_sweep_file_expands_to_the_thesis_grid_for_three_curves():
    sp = spec.load(FIG5_5)
    cases = expand(sp)
    assert sp.task == "flux_observer_gamma" and len(cases) == 30
    curves = {c.labels["curve"] for c in cases}
    assert curves == {"full", "thesis reading", "diagonal re-balancing"}
    by = {(c.labels["curve"], c.args["omega_r_max"]): c.args for c in cases}
    assert by[("thesis reading", 200.0)]["variant"] == "partial" and by[("full", 200.0)]["variant"] == "full"
    assert by[("diagonal re-balancing", 10.0)]["numerics"] == "diagonal"
    assert all(a["f_s"] == 3000.0 and a["sigma_i"] == 1e-4 for a in by.values())  # 5.6.2's set-up by default


def test_a_bad_task_file_exits_2_with_one_line_and_writes_nothing(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(FIG5_5.read_text().replace('"task.omega_r_max"', '"task.omega_max"'))
    p = subprocess.run([sys.executable, "-m", "bench", "sweep", str(bad), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, cwd=tmp_path, timeout=120)  # fmt: skip
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [p.stderr.strip()]
    assert "design.axes.task.omega_max" in p.stderr and "unknown task argument" in p.stderr
    assert not (tmp_path / "out").exists()


def test_a_flux_task_row_equals_the_direct_computation_and_resumes(tmp_path):
    """One Fig. 5.5 point through the engine (local cluster, 1 worker) = `gamma_curve` called here.

    At 400 rad/s (one of the quickest bisections)."""
    from synthesis.models.flux_observer import gamma_curve

    sp = spec.parse({**TASK, "task": {"omega_r_max": 400.0}})
    out = tmp_path / "out"
    with ThreadPoolExecutor(1) as pool:  # the direct computation here while the Dask worker process does its own
        direct_f = pool.submit(gamma_curve, [400.0])
        res = run_sweep(sp, out, workers=1, progress=False)
        (direct,) = direct_f.result()
    assert (res["ran"], res["ok"], res["error"], res["sim_seconds_per_wall_second"]) == (1, 1, 0, None)
    (row,) = table.read(out / table.RESULTS)
    for k in ("gamma_a", "gamma_lower_bound", "gap"):
        assert row[f"out.{k}"] == pytest.approx(direct[k], rel=1e-9), k
    assert row["out.gamma_lower_bound"] <= row["out.gamma_a"] <= 1.01 * row["out.gamma_lower_bound"]
    assert (out / "tasks" / row["case_id"]).is_dir()
    again = run_sweep(sp, out, workers=1, progress=False)
    assert (again["skipped"], again["ran"]) == (1, 0)


def test_a_raising_task_is_recorded_as_an_error_row(tmp_path, monkeypatch):
    def boom(work, **args):
        raise ValueError("LMI infeasible at every gamma")

    monkeypatch.setitem(tasks.TASKS, "flux_observer_gamma", tasks.TASKS["flux_observer_gamma"].__class__(
        "flux_observer_gamma", "x", tasks.TASKS["flux_observer_gamma"].args, boom))  # fmt: skip
    (case,) = expand(spec.parse({**TASK, "task": {"omega_r_max": 10.0}}))
    row = tasks.run_task(case, str(tmp_path))
    assert row["status"] == "error" and row["error"] == "ValueError: LMI infeasible at every gamma"
    assert row["task.omega_r_max"] == 10.0 and row["case_wall_time"] >= 0


def test_task_report_plots_fig5_5_and_tabulates_every_case(tmp_path):
    rows = []
    for i, (curve, w, g, lb) in enumerate([("full", 10.0, 2.0e-5, 1.99e-5), ("full", 200.0, 2.1e-5, 1.99e-5),
                                            ("thesis reading", 10.0, 1.0e-4, 0.99e-4)]):  # fmt: skip
        rows.append({"case_id": f"c{i}", "index": i, "task": "flux_observer_gamma", "label.curve": curve,
                     "task.omega_r_max": w, "task.variant": "full", "status": "ok", "error": None,
                     "out.gamma_a": g, "out.gamma_lower_bound": lb, "case_wall_time": 1.0})  # fmt: skip
    table.write(tmp_path / table.RESULTS, rows)
    from bench.workflows.sweep.report import report

    written = report(tmp_path)
    assert [p.name for p in written] == ["fig5.5.png", "report.md"]
    assert (tmp_path / "fig5.5.png").stat().st_size > 5000
    md = (tmp_path / "report.md").read_text()
    assert "3 cases of task `flux_observer_gamma`" in md and md.count("| full |") == 2
    assert "| thesis reading | 10 | 0.0001 | 9.9e-05 |" in md
