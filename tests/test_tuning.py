"""Relay-feedback tuning (bench.workflows.tuning, bench.controllers.relay): the analysis on synthetic data, the
relay experiment on the mock rig against the speed loop's linear model, the ZN PI in closed loop."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.errors import BadInput
from bench.runtime.session import RunOptions, run
from bench.workflows.tuning import relay_analysis, tune_speed

ROOT = Path(__file__).resolve().parents[1]
T_S = 1.0 / 3000.0


def speed_loop_model(w: float, *, J: float = 0.0125, B: float = 1e-3, Z_p: int = 2, w_cc: float = 1000.0,
                     tau: float = 0.003) -> complex:  # fmt: skip
    """Torque reference -> filtered encoder speed of the FOC, built from its parts (not from the log):
    current loop L/(1+L), L = w_cc e^{-1.5 s T_s}/s (PI with pole-zero cancellation, one-sample delay
    plus hold); mechanics Z_p/(J s + B) (electrical speed); count difference = speed half a sample
    ago; the FOC's discrete first-order filter (bench.core.encoder)."""
    s = 1j * w
    L = w_cc * np.exp(-1.5 * s * T_S) / s
    a = 1.0 - math.exp(-T_S / tau)
    filt = a / (1.0 - (1.0 - a) * np.exp(-s * T_S))
    return complex(Z_p / (J * s + B) * L / (1.0 + L) * np.exp(-0.5 * s * T_S) * filt)


def test_analysis_recovers_known_response() -> None:
    """A square-wave relay output and a speed with a known first harmonic, harmonics and noise."""
    rng = np.random.default_rng(1)
    T_u, d, G = 0.0155, 4.0, 0.24 * np.exp(-1j * math.radians(165.0))
    t = np.arange(0.0, 1.5, T_S)
    w = 2 * math.pi / T_u
    m = d * np.sign(np.sin(w * t) + 1e-12)
    c_m = 4 * d / math.pi  # first harmonic of the square wave, in phase with sin
    omega = (abs(G) * c_m * np.sin(w * t + np.angle(G)) + 0.3 * np.sin(3 * w * t + 0.4)
             + 0.2 * rng.standard_normal(t.size) + 2.0)  # fmt: skip
    res = relay_analysis(t, omega, m, d=d, eps=0.5, t_from=0.1)
    assert res.T_u == pytest.approx(T_u, rel=5e-3)
    assert res.K_u == pytest.approx(1 / abs(G), rel=0.02)
    assert res.phase_deg == pytest.approx(-165.0, abs=1.5)
    assert res.speed_Kp == pytest.approx(0.45 * res.K_u) and res.speed_Ti == pytest.approx(res.T_u / 1.2)
    assert res.warnings == ()


def test_analysis_needs_whole_periods() -> None:
    t = np.arange(0.0, 0.02, T_S)
    with pytest.raises(BadInput, match="relay"):
        relay_analysis(t, np.sin(400 * t), np.sign(np.sin(400 * t)), d=1.0, eps=0.0)


@pytest.fixture(scope="module")
def hires_rig(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The mock rig with a 2^18-line encoder: the loop without the 1024-line quantisation."""
    text = (ROOT / "rigs" / "mock.toml").read_text().replace('name = "mock"', 'name = "mock-hires"')
    path = tmp_path_factory.mktemp("rig") / "hires.toml"
    path.write_text(text + "\n[mock.encoder]\nlines = 262144\nmodulus = 1073741824\n")
    return path


@pytest.mark.parametrize("rig,d,eps,tol_mag,tol_deg", [("hires", 2.0, 0.1, 0.05, 2.0), ("hires", 8.0, 2.0, 0.05, 2.0),
                                                       ("mock", 4.0, 0.5, 0.08, 5.0)])  # fmt: skip
def test_relay_on_mock_rig_matches_speed_loop_model(tmp_path: Path, hires_rig: Path, rig: str, d: float, eps: float,
                                                    tol_mag: float, tol_deg: float) -> None:  # fmt: skip
    out = tune_speed(str(hires_rig) if rig == "hires" else rig, params={"relay_amplitude": d, "relay_hysteresis": eps},
                     out_dir=tmp_path)  # fmt: skip
    r = out["relay"]
    G = speed_loop_model(r["omega_u"])
    assert r["n_periods"] > 30
    assert r["K_u"] == pytest.approx(1 / abs(G), rel=tol_mag)
    assert r["phase_deg"] == pytest.approx(math.degrees(np.angle(G)), abs=tol_deg)
    assert Path(out["plot"]).stat().st_size > 10_000 and Path(out["json"]).exists()
    if rig == "mock":
        # the describing function 4d/(pi a) is far off on the 1024-line encoder (why it is not used)
        assert r["K_u_df"] > 2 * r["K_u"]


def test_ziegler_nichols_pi_closes_the_loop(tmp_path: Path) -> None:
    """The ZN PI from the relay experiment holds fig5.7 and rejects its load steps better than the
    slower hand tuning (ZN aims at quarter-amplitude decay: high gain)."""
    zn = tune_speed("mock", out_dir=tmp_path)["suggested_params"]
    runs = {}
    for name, p in {"zn": zn, "hand": {}}.items():
        summary, code = run(RunOptions(scenario="fig5.7", params=p, log=tmp_path / f"{name}.mcap", progress=False))
        assert code == 0 and summary["trip_cause"] is None
        runs[name] = summary
    assert runs["zn"]["speed_error_settled"]["rms"] < 1.0
    assert runs["zn"]["load_steps"]["peak_deviation_max"] < runs["hand"]["load_steps"]["peak_deviation_max"]


def test_cli_bad_amplitude_is_one_line_exit_2() -> None:
    proc = subprocess.run([sys.executable, "-m", "bench", "tune", "speed", "--amplitude", "0"], capture_output=True,
                          text=True, cwd=ROOT, timeout=60)  # fmt: skip
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--amplitude" in lines[0]


def test_cli_prints_the_command_that_uses_the_gains(tmp_path: Path) -> None:
    """`bench tune speed` ends with the `bench run -p speed_Kp=... -p speed_Ti=...` line, and that command runs
    with the suggested gains."""
    import json
    import shlex

    proc = subprocess.run([sys.executable, "-m", "bench", "tune", "speed", "--out", str(tmp_path)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    line = proc.stderr.strip().splitlines()[-1]
    assert line == f"bench: to run with these gains: {res['command']}"
    cmd = shlex.split(res["command"])
    assert cmd[:2] == ["bench", "run"]
    run = subprocess.run([sys.executable, "-m", "bench", *cmd[1:], "--duration", "0.3", "--no-progress", "--out",
                          str(tmp_path)], capture_output=True, text=True, cwd=tmp_path, timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stderr
    used = json.loads(Path(json.loads(run.stdout)["summary"]).read_text())["controller_params"]
    for k in ("speed_Kp", "speed_Ti"):
        assert abs(used[k] - res["suggested_params"][k]) <= 1e-3 * res["suggested_params"][k]
