"""NARX data collection (6.4.2) through the normal session path, the data-set reader, `bench collect/train narx`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from bench.controllers.excitation import Dithered
from bench.daq import LogReader
from bench.daq.narx import NarxExperiment, excitation_scenario, read_signals
from bench.workflows.narx import collect
from bench.errors import BadInput

ROOT = Path(__file__).resolve().parents[1]


def bench(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout)  # fmt: skip


@pytest.fixture(scope="module")
def short_log(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("narx") / "set.mcap"
    summary, code = collect(NarxExperiment(seed=3, samples=900), out, progress=False)
    assert code == 0, summary["trip_cause"]
    return out


def test_log_has_the_rates_and_the_metadata_to_regenerate_it(short_log):
    r = LogReader(short_log)
    meta = r.metadata()
    exp, ds = meta["narx"]["experiment"], meta["narx"]["dataset"]
    assert exp["seed"] == 3 and exp["samples"] == 900 and exp["omega_max"] == 250.0
    assert exp["i_mR_range"] == [0.8, 2.8] and exp["load_max"] == 8.0 and exp["load_k"] == 0.01
    assert ds["loop_rate_hz"] == 3000.0 and ds["sample_hz"] == 600.0 and ds["decimation"] == 5
    # the controller's gains, dither and filter are in the run record
    p = meta["run"]["controller_params"]
    assert meta["run"]["controller"] == "excitation" and meta["run"]["seed"] == 3
    assert p["seed"] == 3 and p["dither_amplitude"] == 0.8 and p["log_filter_hz"] == 100.0
    assert {"speed_Kp", "speed_Ti", "flux_Km", "current_wc"} <= set(p)
    # the loop ran at 3 kHz for lead-in + data
    t = r.read("/rig")["t"]
    assert np.allclose(np.diff(t), 1 / 3000)
    assert t.size == round(NarxExperiment(seed=3, samples=900).duration * 3000)


def test_reader_decimates_the_filtered_signals_to_600_hz(short_log):
    sig = read_signals(short_log)
    assert len(sig) == 900 and sig.sample_hz == 600.0
    assert np.allclose(np.diff(sig.t), 1 / 600) and sig.t[0] == pytest.approx(0.5)
    np.testing.assert_array_equal(sig.i_tau, sig.i_sq_ref * sig.i_mR)  # i_tau of 6.4.2
    r = LogReader(short_log)
    c = r.read("/ctrl")
    # the logged data-set signals are first-order 100 Hz filters of the controller's signals
    a = 1 - np.exp(-2 * np.pi * 100 / 3000)
    for raw, filt in (("i_mr_hat", "i_mr_f"), ("i_sd_ref", "i_sd_ref_f"), ("i_sq_ref", "i_sq_ref_f")):
        np.testing.assert_allclose(lfilter([a], [1, a - 1], c[raw]), c[filt], atol=1e-9)
    # the dither: held for 5 ticks, within +-0.8 A, both signs
    for col in ("dither_d", "dither_q"):
        d = c[col]
        assert np.abs(d).max() <= 0.8 and d.min() < -0.5 and d.max() > 0.5
        assert np.all(d[1:5] == d[1]) and np.count_nonzero(np.diff(d)) <= d.size // 5 + 1
    # the mock rig's truth gives the measurement-noise evidence, never used for training
    assert sig.omega_true is not None and 0.05 < np.std(sig.omega_r - sig.omega_true) < 2.0


def test_references_are_random_steps_in_the_thesis_ranges_and_follow_the_seed():
    exp = NarxExperiment(seed=11, samples=22000)
    scn = excitation_scenario(exp)
    t = np.arange(0, exp.duration, 1 / 600)
    w = np.array([scn.speed_ref(x) for x in t])
    i = np.array([scn.i_mR_ref(x) for x in t])
    assert np.all(w[t < exp.lead_in] == 0) and np.abs(w).max() <= 250 and w.min() < -150 and w.max() > 150
    assert i.min() >= 0.8 and i.max() <= 2.8
    lengths = np.diff(t[np.flatnonzero(np.diff(w)) + 1])
    assert lengths.min() >= 0.3 - 1e-9 and lengths.max() <= 1.5 + 1 / 600
    assert len(lengths) > 20
    same = excitation_scenario(NarxExperiment(seed=11, samples=22000))
    other = excitation_scenario(NarxExperiment(seed=12, samples=22000))
    assert [same.speed_ref(x) for x in t[::100]] == w[::100].tolist()
    assert [other.speed_ref(x) for x in t[::100]] != w[::100].tolist()


def test_dither_is_reproducible_and_reset_restarts_it():
    class Zero:
        def update(self, *a):
            return 0.0

    d = Dithered(Zero(), 0.8, 3, seed=5)
    a = [d.update() for _ in range(30)]
    d.reset()
    assert [d.update() for _ in range(30)] == a
    assert a[0] == a[1] == a[2] != a[3]


def test_same_seed_same_data_set(tmp_path, short_log):
    out = tmp_path / "again.mcap"
    collect(NarxExperiment(seed=3, samples=900), out, progress=False)
    a, b = read_signals(short_log), read_signals(out)
    for k in ("omega_r", "i_mR", "i_sd_ref", "i_sq_ref"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


def test_same_experiment_runs_through_the_real_drivers(tmp_path):
    """The emulated rig: CAN, serial and Modbus drivers against device emulators, nothing special-cased."""
    out = tmp_path / "emu.mcap"
    summary, code = collect(NarxExperiment(seed=5, samples=300), out, rig="emulated", progress=False)
    assert code == 0, summary["trip_cause"]
    sig = read_signals(out)
    assert len(sig) == 300 and sig.source["rig"] == "emulated"
    assert np.abs(sig.omega_r).max() > 50  # the motor followed the first speed step
    assert np.all(np.isfinite(sig.i_tau))


def test_reader_refuses_logs_that_are_not_narx_data_sets(tmp_path):
    from bench.runtime.session import RunOptions, run

    log = tmp_path / "plain.mcap"
    run(RunOptions(scenario="fig5.7", duration=0.1, log=log, progress=False))
    with pytest.raises(BadInput, match="not a NARX data-set log"):
        read_signals(log)
    with pytest.raises(BadInput, match="no such file"):
        read_signals(tmp_path / "missing.mcap")


@pytest.mark.slow  # 18 s; collect is tested above, training in tests/test_narx.py, the CLI chain in test_readme_chain.py
def test_cli_collect_and_train_write_log_model_and_report(tmp_path):
    from synthesis.narx import load_model

    for seed in (1, 2):
        p = bench("collect", "narx", "--out", str(tmp_path / f"s{seed}.mcap"), "--seed", str(seed), "--samples", "1500",
                  "--no-progress")  # fmt: skip
        assert p.returncode == 0, p.stderr
        info = json.loads(p.stdout)
        assert info["narx"]["samples"] == 1500 and info["trip_cause"] is None
    p = bench("train", "narx", "--train", str(tmp_path / "s1.mcap"), "--val", str(tmp_path / "s2.mcap"), "--out",
              str(tmp_path / "m"), "--max-nfev", "60")  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "LM evaluation" in p.stderr and "validation report" in p.stderr  # progress on stderr
    s = json.loads(p.stdout)
    assert set(s["performance"]) == {"train", "val"} and len(s["sector_table"]) == 4
    for name in ("fig6.6", "fig6.7", "fig6.8", "fig6.9", "fig6.10", "fig6.11", "sectors"):
        assert Path(s["figures"][name]).stat().st_size > 10_000
    rep = json.loads(Path(s["report"]).read_text())
    assert rep["thesis"]["sector_widths"] == [0.0114, 0.0092, 0.0062, 0.0035]
    assert rep["noise_floor"]["val"]["meas_minus_true_rms_rad_s"] > 0
    m = load_model(tmp_path / "m")
    prov = m.meta["provenance"]
    assert prov["train"]["seed"] == 1 and prov["val"]["seed"] == 2
    assert len(prov["train"]["sha256"]) == 64 and prov["train"]["path"].endswith("s1.mcap")
    assert prov["train"]["rig"] == "mock"
    assert m.meta["settings"]["max_nfev"] == 60 and len(m.meta["lft"]["widths"]) == 4


@pytest.mark.parametrize(
    "args, field",
    [
        (["collect", "narx", "--out", "x.mcap", "--samples", "0"], "--samples"),
        (["collect", "narx", "--out", "x.mcap", "-p", "seed=4"], "--param seed"),
        (["collect", "narx", "--out", "x.mcap", "-p", "dither_amplitude=-1"], "dither_amplitude"),
        (["collect", "narx", "--out", "x.mcap", "-p", "bogus=1"], "controller.excitation.bogus"),
        (["train", "narx", "--train", "missing.mcap", "--val", "missing.mcap", "--out", "m"], "missing.mcap"),
        (["train", "narx", "--train", "a", "--val", "b", "--out", "m", "--neurons", "0"], "--neurons"),
        (["train", "narx", "--train", "a", "--val", "b", "--out", "m", "--noise", "-1"], "--noise"),
    ],
)
def test_bad_cli_input_is_one_line_exit_2(tmp_path, args, field):
    args = [str(tmp_path / a) if a.endswith(".mcap") or a in ("m", "a", "b") else a for a in args]
    p = bench(*args)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench: error:") and field in lines[0]
    assert not list(tmp_path.glob("*.mcap"))


@pytest.mark.slow
def test_full_size_identification_chain_on_the_mock_rig(tmp_path):
    """22000 samples per set (6.4.2), the default LM budget: the MLP beats the ARX model as the thesis found."""
    from bench.workflows.narx import collect_and_train
    from synthesis.mlp_lft import mlp_to_lft
    from bench.workflows.narx import load_dataset
    from synthesis.narx import load_model, regressors

    s = collect_and_train(tmp_path)
    p = s["performance"]
    for name in ("train", "val"):
        assert p[name]["mlp"]["J"] < 0.97 * p[name]["arx"]["J"]
    rep = json.loads(Path(s["report"]).read_text())
    for name in ("train", "val"):
        assert rep["free_run"][name]["mlp_rms_rad_s"] < 0.7 * rep["free_run"][name]["arx_rms_rad_s"]
        # one-step errors sit above the measurement noise, and the MLP is closer to the true speed
        f = rep["noise_floor"][name]
        assert f["mlp_vs_true_next_speed_rms_rad_s"] < f["arx_vs_true_next_speed_rms_rad_s"]
    assert all(0 < row["width"] < 0.2 for row in s["sector_table"])
    # the LFT of the trained model reproduces its predictions on the real data
    model = load_model(s["model"]["json"])
    tr = load_dataset(tmp_path / "narx-train-seed1.mcap", model.scaling)
    lft = mlp_to_lft(model, [tr])
    Z, _ = regressors(tr, model.orders)
    pred = model.mlp.predict(Z)
    for k in range(100, 20000, 997):
        x = lft.state_from_history(tr.w[k::-1], tr.i[k - 1 :: -1], tr.d[k - 1 :: -1], tr.tau[k - 1 :: -1])
        x1, _ = lft.step(x, np.array([tr.i[k], tr.d[k], tr.tau[k]]) - lft.u0)
        assert x1[0] + lft.w0 == pytest.approx(pred[k - model.orders.lag + 1], abs=1e-12)
