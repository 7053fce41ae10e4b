"""`bench synth`: the CLI designs, verifies and saves an artifact that loads back; bad options exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from synthesis.artifacts import load_controller

ROOT = Path(__file__).resolve().parents[1]


def bench(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout)  # fmt: skip


def test_synth_flux_observer_writes_verified_artifact(tmp_path: Path) -> None:
    out = tmp_path / "fo"
    proc = bench("synth", "flux-observer", "--omega-max", "200", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    # progress: one line per stage on stderr
    for stage in ("bisection", "construction", "verification"):
        assert f"flux observer: {stage}" in proc.stderr
    assert info["verification"]["passed"] is True
    assert info["gamma"] > info["gamma_a"] > 0
    ctrl, doc = load_controller(out)
    assert doc["meta"]["design"] == "flux_observer" and doc["meta"]["rate_hz"] == 3000.0
    assert doc["meta"]["solver"]["solver"] == "CLARABEL"
    # the saved observer, frozen at a speed inside the range, is a stable discrete system
    assert ctrl.dt == 1.0 / 3000.0
    for w in (-200.0, 0.0, 150.0):
        assert np.max(np.abs(ctrl.frozen(np.array([[w / 200.0]])).poles())) < 1.0


def test_synth_bad_option_is_one_line_exit_2(tmp_path: Path) -> None:
    proc = bench("synth", "flux-observer", "--rate", "5", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--rate" in lines[0]
    assert not (tmp_path / "x.npz").exists()
