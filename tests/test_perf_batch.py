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
