"""The controller plugin of docs/plugins.md (examples/controller-plugin), found through its entry point
as an installed package would be, runs against the mock rig; its run plot falls back to |i_s| from /rig
(it logs none of FOC's currents), and a run's plot marks the operator's requests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = ROOT / "examples" / "controller-plugin"


def _installed(tmp_path: Path) -> dict[str, str]:
    """The environment of a process in which the example is 'installed': its module on the path and a
    dist-info with the entry point from its pyproject.toml (what `pip install -e` would write)."""
    import tomllib

    eps = tomllib.loads((PLUGIN / "pyproject.toml").read_text())["project"]["entry-points"]["imbench.controllers"]
    info = tmp_path / "site" / "imbench_vf-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: imbench-vf\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text("[imbench.controllers]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()))
    path = os.pathsep.join([str(ROOT), str(PLUGIN), str(tmp_path / "site")])
    return {**os.environ, "PYTHONPATH": path}


def test_example_plugin_is_listed_and_runs_on_the_mock_rig(tmp_path):
    env = _installed(tmp_path)

    def bench(*args):
        return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=tmp_path,
                              env=env, timeout=120)  # fmt: skip

    listed = bench("controllers", "vf")
    assert listed.returncode == 0 and "boost" in listed.stdout and "*" in listed.stdout, listed.stderr
    bad = bench("run", "--controller", "vf", "-p", "boost=-1", "--no-progress")
    assert bad.returncode == 2 and "controller.vf.boost" in bad.stderr and "[0, 50]" in bad.stderr
    p = bench("run", "--controller", "vf", "--scenario", "fig5.7", "--no-progress", "--log", "vf.mcap")
    assert p.returncode == 0, p.stderr
    from bench.daq import LogReader
    from bench.daq.plots import run_figure

    r = LogReader(tmp_path / "vf.mcap")
    ctrl, truth = r.read("/ctrl"), r.read("/truth")
    assert [f for f in ctrl if f != "log_time"] == ["omega_s", "theta", "u_amp"]
    late = r.read("/rig")["t"] > 1.0
    assert abs(np.mean(ctrl["omega_s"][late]) - 10.0) < 1e-9  # the stator frequency follows the reference
    assert 0.0 < np.mean(truth["omega_r"][late]) < 10.0  # and the rotor slips behind it under the load
    fig = run_figure(tmp_path / "vf.mcap")
    current = fig.axes[2]
    labels = [ln.get_label() for ln in current.lines]
    assert labels == [r"$|i_s|$ (measured)"]
    i_s = current.lines[0].get_ydata()
    assert 1.0 < np.median(i_s) < 6.0  # about the magnetising current plus the load's


def test_run_plot_marks_parameter_changes_overrides_marks_and_the_stop(tmp_path):
    from test_operator import _schedule_log  # a log holding a schedule of applied requests

    from bench.daq.plots import event_marks, run_figure
    from bench.runtime.session import RunOptions, run

    log = _schedule_log(tmp_path / "sched.mcap", [
        {"tick": 1500, "kind": "set", "name": "speed_Kp", "old": 0.6, "new": 0.9},
        {"tick": 2400, "kind": "set", "name": "omega_r_ref_override", "old": "off", "new": 50.0},
        {"tick": 3000, "kind": "mark", "note": "before the stop"},
        {"tick": 3100, "kind": "set", "name": "speed_Kp", "new": 1e9, "status": "refused: range"},
        {"tick": 4500, "kind": "stop"},
    ])  # fmt: skip
    summary, code = run(RunOptions(duration=5.0, replay_params=log, log=tmp_path / "replay.mcap", progress=False))
    assert code == 0, summary
    from bench.daq import LogReader

    marks = event_marks(LogReader(tmp_path / "replay.mcap").events())
    assert [(round(t * 3000), kind) for t, _, kind in marks] == [(1500, "set"), (2400, "override"), (3000, "mark"),
                                                                 (4500, "stop")]  # fmt: skip
    assert marks[0][1] == "speed_Kp 0.6 -> 0.9" and marks[2][1] == "mark: before the stop"
    fig = run_figure(tmp_path / "replay.mcap")
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == [m[1] for m in marks]
    for ax in fig.axes[:4]:  # a line per request in every panel
        xs = sorted({float(ln.get_xdata()[0]) for ln in ax.lines if len(ln.get_xdata()) == 2})
        assert all(any(abs(x - t) < 1e-9 for x in xs) for t, _, _ in marks)
    assert Path(summary["plot"]).stat().st_size > 10_000
    # a note is a client's text: dollars and line breaks are drawn as they are, never as mathtext
    odd = event_marks([{"t": 1.0, "kind": "mark", "status": "applied", "note": "cost $5\nthen $x, $y"}])
    assert odd == [(1.0, r"mark: cost \$5 then \$x, \$y", "mark")]
    fig.axes[0].annotate(odd[0][1], xy=(1.0, 0.5))
    fig.savefig(tmp_path / "odd.png")  # renders (an unbalanced $ would raise in mathtext)
