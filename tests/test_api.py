"""bench.run, the Python entry point: from a plain script without a `__main__` guard, Python arguments, Python
names in its refusals, and an exception for a run that did not start."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

import bench
from bench.api import CLI_OPTIONS, RunFailed, python_input
from bench.errors import BadInput

SCRIPT = textwrap.dedent('''
    import json
    import bench

    first = bench.run("demo", duration=0.2, seed=1, log="runs/a.mcap")
    try:
        bench.run("demo", duration=0.2, log="runs/a.mcap")
    except bench.BadInput as exc:
        refused = str(exc)
    second = bench.run("demo", duration=0.3, seed=2, log="runs/a.mcap", force=True)
    ticks = bench.LogReader(second["log"]).read("/rig")["t"].size
    print(json.dumps({"first": first["ticks"], "refused": refused, "second": second["ticks"], "rows": ticks}))
''')  # no `if __name__ == "__main__":`: the writer and progress processes must not run it again


def test_a_script_without_a_main_guard_runs_refuses_and_overwrites_with_force(tmp_path):
    (tmp_path / "script.py").write_text(SCRIPT)
    p = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout.strip().splitlines()[-1])  # the script ran once: one line
    assert len(p.stdout.strip().splitlines()) == 1, p.stdout
    assert out["first"] == 600 and out["second"] == out["rows"] == 900  # 0.2 s, then 0.3 s at 3 kHz
    assert out["refused"].startswith("run(log=...): runs/a.mcap exists; pass force=True"), out["refused"]
    summary = json.loads((tmp_path / "runs" / "a.summary.json").read_text())
    assert summary["seed"] == 2 and summary["exit_code"] == 0
    assert "--" not in out["refused"]


def test_a_failed_start_raises_run_failed_with_the_summary(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    import bench.runtime.session
    from bench.daq import LogWriterError

    def broken(*args, **kwargs):
        raise LogWriterError("writer process failed to start")

    monkeypatch.setattr(bench.runtime.session, "open_log", broken)
    with pytest.raises(bench.RunFailed) as info:
        bench.run("demo", duration=0.1, log="runs/b.mcap", progress=False)
    exc = info.value
    assert exc.exit_code == 1 and not exc.started
    assert exc.cause.startswith("start-up failed: LogWriterError") and "did not start" in str(exc)
    assert exc.summary["ticks"] == 0
    assert json.loads((tmp_path / "runs" / "b.summary.json").read_text())["trip_cause"] == exc.cause


def test_check_false_returns_a_tripped_runs_summary_and_check_true_raises(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # an over-speed trip at 5 rad/s (injected: half the scenario's largest speed reference); Fig. 5.7 runs at 10
    args = dict(rig="mock", duration=1.0, log_enabled=False, inject_fault="over-speed")
    summary = bench.run("fig5.7", check=False, **args)
    assert summary["exit_code"] == 1 and summary["trip_cause"].startswith("over-speed")
    with pytest.raises(RunFailed, match="the run ended early: over-speed") as info:
        bench.run("fig5.7", **args)
    assert info.value.started and info.value.exit_code == 1 and info.value.summary["ticks"] > 0


def test_refusals_name_python_parameters(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.json").write_text("{}")
    with pytest.raises(BadInput) as info:
        bench.run("demo", duration=0.1, summary="s.json", progress=False)
    assert str(info.value) == "run(summary=...): s.json exists; pass force=True to overwrite it"
    assert info.value.field == "summary"
    with pytest.raises(BadInput, match=r"^run\(log_buffer=\.\.\.\): must be in"):
        bench.run("demo", log_buffer=0.0)
    with pytest.raises(TypeError, match="no_such_option"):
        bench.run("demo", no_such_option=1)
    assert not (tmp_path / "runs").exists()  # nothing was made


def test_the_option_table_covers_the_run_commands_options():
    from bench.cli import run as run_command

    options = {opt for p in run_command.params for opt in p.opts if opt.startswith("-")}
    missing = options - set(CLI_OPTIONS) - {"--help", "--scenario-arg", "-p", "--param"}
    assert not missing, missing
    # a field of a rig file or a command in backticks is left as written
    exc = python_input(BadInput("limits.I_max", "make one with `bench synth flux-observer --rig RIG`"))
    assert str(exc) == "limits.I_max: make one with `bench synth flux-observer --rig RIG`"


def test_import_bench_stays_cheap():
    code = ("import sys, bench; "
            "print(sorted(m for m in ('bench.runtime.session', 'numpy', 'bench.api') if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.stdout.strip() == "[]", p.stdout + p.stderr
