"""`bench perf batch`'s peers (skipped with a reason where not installed) and its plot."""

from __future__ import annotations

import sys

import pytest

from bench.perf import batch as perf_batch, peers


def test_peer_not_installed_is_skipped_with_the_reason(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "gym_electric_motor", None)  # import raises ImportError
    out = peers.measure("gym-electric-motor", steps=10)
    assert "us_per_step" not in out
    assert "not installed" in out["skipped"] and "peers" in out["skipped"]


def test_peer_in_a_fresh_process_gives_a_rate() -> None:
    pytest.importorskip("motulator")
    out = peers.run("motulator", steps=30)
    assert out["peer"] == "motulator" and out["steps"] == 30
    assert 0 < out["us_per_step"] < 1e6 and out["steps_per_s"] == pytest.approx(1e6 / out["us_per_step"])


def test_a_broken_interpreter_is_a_skip_not_a_crash(tmp_path) -> None:  # noqa: ANN001
    fake = tmp_path / "python"
    fake.write_text("#!/bin/sh\necho 'no such module' >&2\nexit 3\n")
    fake.chmod(0o755)
    out = peers.run("motulator", steps=10, python=str(fake))
    assert out["skipped"].startswith("failed") and "no such module" in out["skipped"]


def test_plot_draws_rows_scalar_and_peers(tmp_path) -> None:  # noqa: ANN001
    rows = [{"cases": n, "motor_ticks_per_s": 1e5 * n**0.5, "motor_ticks_per_cpu_s": 2e5 * n**0.5} for n in (1, 10)]
    doc = {"batch": rows, "scenario": "fig5.7", "duration_s": 0.5, "cpus": 2, "load_average_before": [1.0, 1, 1],
           "scalar_before": {"motor_ticks_per_s": 2e4}, "scalar_after": {"motor_ticks_per_s": 3e4},
           "peers": [{"peer": "p", "steps_per_s": 5e3, "step_s": 1e-4}, {"peer": "q", "skipped": "not installed"}]}
    png = perf_batch.plot(doc, tmp_path / "b.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


def test_bench_perf_batch_cli_writes_json_and_plot(tmp_path) -> None:  # noqa: ANN001
    """`bench perf batch` as a user runs it (a real process, a few seconds): the rows, the scalar engine, the load averages and
    per-CPU-second rates (what a rerun on an idle machine needs), the plot; a missing plot folder is exit 2."""
    import json
    import subprocess

    png = tmp_path / "b.png"
    p = subprocess.run([sys.executable, "-m", "bench", "perf", "batch", "--sizes", "1,3", "--duration", "0.05",
                        "--no-peers", "--plot", str(png)], capture_output=True, text=True, timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert [r["cases"] for r in doc["batch"]] == [1, 3] and doc["peers"] == []
    assert all(r["motor_ticks"] == r["cases"] * 150 and r["motor_ticks_per_cpu_s"] > 0 for r in doc["batch"])
    assert len(doc["load_average_before"]) == 3 and len(doc["load_average_after"]) == 3
    assert [s["engine"] for s in doc["side_by_side"]][-1].startswith("scalar")
    assert doc["plot"] == str(png) and png.read_bytes()[:4] == b"\x89PNG"
    bad = subprocess.run([sys.executable, "-m", "bench", "perf", "batch", "--plot", str(tmp_path / "no" / "b.png")],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert bad.returncode == 2 and "--plot" in bad.stderr and "Traceback" not in bad.stderr
