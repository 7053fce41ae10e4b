"""The runtime LPV current controller (bench.controllers.lpv_current) inside the FOC, and its reproductions."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.controllers.base import ControllerContext
from bench.controllers.foc import I_MR_FLOOR, FocController
from bench.controllers.lpv_current import LPVCurrentController, LPVCurrentLaw, artifact_path
from bench.errors import BadInput
from bench.params import T_S_DEFAULT, MotorParams
from synthesis.artifacts import load_controller
from synthesis.construct import LPVRuntime

M = MotorParams()
ROOT = Path(__file__).resolve().parents[1]


def ctx() -> ControllerContext:
    return ControllerContext(T_s=T_S_DEFAULT, motor=M, I_max=10.0, counts_per_rev=4096, enc_modulus=2**16)


@pytest.mark.parametrize("rate", [600.0, 3000.0])
def test_runtime_equals_the_synthesis_runtime(rate):
    """Python-complex per-tick law == synthesis.construct.LPVRuntime (numpy, (5.36) + 5.4.4), with Δ jumping
    every sample over the box, and == the frozen (5.63) at constant Δ."""
    p = artifact_path(rate)
    law = LPVCurrentLaw(p)
    ctrl, _ = load_controller(p)
    ref = LPVRuntime(ctrl)
    rng = np.random.default_rng(7)
    for _ in range(300):
        y = complex(*rng.normal(size=2))
        d = rng.uniform(-1, 1, 2)
        u = law.step(y, d[0], d[1])
        u_ref = ref.step([y], np.diag(d))[0]
        assert abs(u - u_ref) <= 1e-9 * max(1.0, abs(u_ref))
    # constant Δ: the frozen state space (5.63)
    law.reset()
    S = ctrl.frozen(np.diag([0.4, -0.7]))
    x = np.zeros(S.n_states, complex)
    for k in range(50):
        y = complex(math.sin(0.3 * k), math.cos(0.1 * k))
        u_f = (S.C @ x + S.D[:, 0] * y)[0]
        x = S.A @ x + S.B[:, 0] * y
        assert abs(law.step(y, 0.4, -0.7) - u_f) <= 1e-9 * max(1.0, abs(u_f))


def test_start_up_singularity_is_floored_and_clipped():
    """δ_2 = i_sq/î_mR at î_mR = 0: the floor (as the FOC's (4.5)) then clipping keep Δ in the box."""
    c = LPVCurrentController(artifact_path(600.0), M)
    assert I_MR_FLOOR > 0
    u = c.update(0j, complex(0.0, 5.0), 0.0, 0.0, 300.0)
    assert math.isfinite(abs(u)) and abs(u) <= 300.0
    assert c.clipped and c.delta2 == pytest.approx(10.0)
    u = c.update(0j, complex(0.0, 0.5), 900.0, 2.0, 300.0)
    assert c.clipped and c.delta1 == pytest.approx(800.0) and c.delta2 == pytest.approx(0.25)
    c.update(0j, complex(0.0, 0.05), 10.0, 0.0, 300.0)  # 0.05/0.1 = 0.5: inside, not clipped
    assert not c.clipped and c.delta2 == pytest.approx(0.5)


def test_voltage_limit_is_enforced():
    c = LPVCurrentController(artifact_path(3000.0), M)
    u = c.update(complex(0, 10.0), 0j, 0.0, 2.0, 50.0)  # a 10 A error asks for far more than 50 V
    assert abs(u) == pytest.approx(50.0) and c.saturated


def test_foc_runs_the_lpv_law_at_its_rate():
    """current_controller = lpv: the divisor follows from the artifact (600 Hz → every 5th tick of 3 kHz)."""
    from bench.hal import Measurement

    c = FocController(ctx(), current_controller="lpv", lpv_current_rate=600.0)
    assert c._div[2] == 5
    seen = []
    for k in range(30):
        m = Measurement(k * T_S_DEFAULT, 1.0, -0.5, -0.5, 0, 0, 0, 3 * k, -1, 560.0, True, False, (0, 0, 0), (0, 0, 0))
        c.step(m, 50.0, 1.0)
        seen.append(c.u_sr)
    changes = [k for k in range(1, 30) if seen[k] != seen[k - 1]]
    assert changes and all(k % 5 == 0 for k in changes)
    assert FocController(ctx(), current_controller="lpv", lpv_current_rate=3000.0)._div[2] == 1


@pytest.mark.parametrize("params, field", [
    ({"current_controller": "hinf"}, "controller.foc.current_controller"),
    ({"current_controller": "lpv", "lpv_current_rate": 1000.0}, "controller.foc.lpv_current_rate"),
    ({"current_controller": "lpv", "lpv_current_artifact": "/nonexistent/cc"}, "controller.foc.lpv_current_artifact"),
])  # fmt: skip
def test_bad_current_controller_params(params, field):
    with pytest.raises(BadInput) as exc:
        FocController(ctx(), **params)
    assert str(exc.value).startswith(field)


@pytest.mark.parametrize("rate", [600.0, 3000.0])
def test_closed_loop_on_mock_rig_from_zero_flux(rate):
    """FOC with the LPV current loop on the mock rig: start-up from zero flux (lead-in), speed steps with
    load; no trip, the flux builds, and the currents follow their references."""
    from bench.workflows.reproductions.common import simulate
    from bench.core.scenarios import T_MAGNETISE, get

    r = simulate(get("demo"), {"current_controller": "lpv", "lpv_current_rate": rate}, duration=1.3)
    assert r.trip_cause is None
    d = r.data
    t = d["/rig/t"]
    assert d["/truth/i_m_re"][0] == 0.0 and d["/truth/i_m_im"][0] == 0.0  # really from zero flux
    late = t > T_MAGNETISE
    i_m = np.hypot(d["/truth/i_m_re"], d["/truth/i_m_im"])
    assert abs(np.mean(i_m[late]) - 2.5) < 0.1
    e_q = (d["/ctrl/i_sq"] - d["/ctrl/i_sq_ref"])[late]
    e_d = (d["/ctrl/i_sd"] - d["/ctrl/i_sd_ref"])[late]
    assert np.sqrt(np.mean(e_q**2)) < 0.6 and np.sqrt(np.mean(e_d**2)) < 0.4
    e_w = (d["/rig/omega_r_ref"] - d["/truth/omega_r"])[t > 1.15]  # back at 100 rad/s after the 4 N m step at 1.0 s
    assert np.max(np.abs(e_w)) < 1.0


def test_fig6_1_simulation_tracks_the_steps():
    """6.2.3 in four steps: the 600 Hz loop on the nonlinear motor tracks the steps (after 20 samples,
    where the 600 V limit is not active)."""
    from bench.workflows.reproductions.lpv_current import STEP_SAMPLES, _settled_rms, simulate_fig6_1

    d = simulate_fig6_1(n_steps=4, seed=2)
    free = d["saturated"] == 0
    assert len(d["t"]) == 4 * STEP_SAMPLES and np.mean(free) > 0.9
    assert _settled_rms(d["i_sq"] - d["i_sq_ref"], 20, free) < 0.5
    assert _settled_rms(d["i_sd"] - d["i_sd_ref"], 20, free) < 0.5
    assert np.max(np.abs(d["delta1"])) <= 800.0 and np.max(np.abs(d["delta2"])) <= 10.0


def test_step_metrics_of_a_first_order_response():
    """Rise time 10-90 % of 1 − e^{−t/τ} is τ ln 9; no overshoot; the RMS error is that of the exponential."""
    from bench.workflows.reproductions.lpv_current import _step_metrics

    T, tau = 1e-4, 2e-3
    t = np.arange(0, 0.1, T)
    ref = np.where(t >= 0.05, 3.0, 1.0)
    y = np.where(t >= 0.05, 1.0 + 2.0 * (1 - np.exp(-(t - 0.05) / tau)), 1.0)
    m = _step_metrics(t, ref, y, np.zeros_like(t), 0.1 * np.ones_like(t), 0.05, 0.05, 1.0)
    assert m["rise_time_ms"] == pytest.approx(1e3 * tau * math.log(9), abs=0.15)
    assert m["overshoot_pct"] == 0.0 and m["coupling_A"] == pytest.approx(0.1)
    assert m["rms_error_A"] == pytest.approx(2.0 * math.sqrt(tau / (2 * 0.05)), rel=0.05)


def test_synth_current_controller_bad_option_is_one_line_exit_2(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "bench", "synth", "current-controller", "--rate", "5", "--out",
                           str(tmp_path / "x")], capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--rate" in lines[0]
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow
def test_synth_current_controller_cli_writes_verified_artifact(tmp_path):
    out = tmp_path / "cc"
    proc = subprocess.run([sys.executable, "-m", "bench", "synth", "current-controller", "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    for stage in ("bisection", "construction", "verification"):
        assert f"current controller: {stage}" in proc.stderr
    ctrl, doc = load_controller(out)
    assert doc["meta"]["verification"]["passed"] and doc["meta"]["rate_hz"] == 600.0
    assert doc["meta"]["solver"]["solver"] == "CLARABEL" and "created_utc" in doc
    sd = doc["meta"]["sampled_data"]  # issue 12: the sampled-data report of a new design (9 x 5 δ grid)
    assert sd["grid"]["delta1"][2] == 9 and sd["controller_frame"]["ratio_to_gamma"] > 3.0


@pytest.mark.slow
def test_reproductions_write_png_and_numbers(tmp_path):
    from bench.workflows import reproduce

    r, _ = reproduce.reproduce("fig6.1", tmp_path)
    assert (tmp_path / "fig6.1.png").stat().st_size > 10_000 and (tmp_path / "fig6.1.json").exists()
    assert r["rms_error_unsaturated_after_20_samples_A"]["i_sq"] < 0.5
    c, _ = reproduce.reproduce("current-compare", tmp_path)
    assert (tmp_path / "current-compare.png").stat().st_size > 10_000
    assert all(v["trip"] is None for v in c["cases"].values())


def test_artifact_for_other_motor_data_is_refused() -> None:
    """The shipped artifact was designed for (3.57); a rig with a hot rotor in its nominal model must not use it."""
    with pytest.raises(BadInput, match="R_r"):
        LPVCurrentController(artifact_path(600.0), M.with_(R_r=1.5 * M.R_r))
