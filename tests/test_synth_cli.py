"""`bench synth`: the CLI designs, verifies and saves an artifact that loads back; bad options exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from synthesis.artifacts import load_controller

ROOT = Path(__file__).resolve().parents[1]


def bench(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout)  # fmt: skip


@pytest.mark.slow  # 12 s; the same command with --rig (below) also writes and checks a verified artifact
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
    # issue 12: the independent lower bound and the gap travel with the report and the artifact
    assert info["discretisation"] == "full" and info["variant"] == "full"
    assert info["gamma_lower_bound"] <= info["gamma_a"] <= 1.01 * info["gamma_lower_bound"]
    assert info["gammas"] == [info["gamma_lower_bound"], info["gamma_a"], info["gamma"]]
    ctrl, doc = load_controller(out)
    assert doc["meta"]["gamma_lower_bound"] == pytest.approx(info["gamma_lower_bound"])
    assert doc["meta"]["gap"] == pytest.approx(info["gamma_a"] / info["gamma_lower_bound"])
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


def test_synth_uses_the_rigs_motor_and_the_plugin_checks_it(tmp_path: Path) -> None:
    """`--rig` designs for the rig's nominal motor; the LPV observer refuses an artifact for other data."""
    text = (ROOT / "rigs" / "mock.toml").read_text()
    assert "R_r = 3.3" in text
    hot = tmp_path / "hot.toml"
    hot.write_text(text.replace("R_r = 3.3", "R_r = 4.95", 1))  # the [motor] table: nominal model
    out = tmp_path / "fo_hot"
    with ThreadPoolExecutor(1) as pool:  # the refusal needs no synthesis: its process runs alongside
        refusal = pool.submit(bench, "run", "--rig", str(hot), "-p", "observer=lpv", "--duration", "0.2", "--log",
                              str(tmp_path / "no.mcap"), "--no-progress")  # the shipped artifact is for (3.57)
        proc = bench("synth", "flux-observer", "--rig", str(hot), "--out", str(out))
        refused = refusal.result()
    assert proc.returncode == 0, proc.stderr
    _, doc = load_controller(out)
    assert doc["meta"]["motor"]["R_r"] == 4.95 and doc["meta"]["verification"]["passed"] is True
    ok = bench("run", "--rig", str(hot), "-p", "observer=lpv", "-p", f"lpv_artifact={out}", "--duration", "0.2",
               "--log", str(tmp_path / "ok.mcap"), "--no-progress")  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert refused.returncode == 2 and "R_r" in refused.stderr and len(refused.stderr.strip().splitlines()) == 1
