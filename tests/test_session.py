"""Whole bench sessions on the mock rig: thesis scenarios, determinism, artefacts, CLI listings."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.core.config import load as load_rig
from bench.daq import LogReader
from bench.runtime.loop import TIMING_FIELDS
from bench.core.scenarios import T_MAGNETISE
from bench.runtime.session import RunOptions, run

ROOT = Path(__file__).resolve().parents[1]


def session(tmp_path: Path, scenario: str, seed: int = 0, name: str = "run", **kw) -> tuple[dict, LogReader]:
    log = tmp_path / f"{name}.mcap"
    summary, code = run(RunOptions(scenario=scenario, seed=seed, log=log, progress=False, **kw))
    assert code == 0, summary.get("trip_cause")
    return summary, LogReader(log)


def test_fig5_7_speed_follows_and_rejects_load_steps(tmp_path):
    s, r = session(tmp_path, "fig5.7")
    truth, ref, cmd = r.read("/truth"), r.read("/rig"), r.read("/rig")
    t = r.read("/rig")["t"]
    assert s["ticks"] == round((T_MAGNETISE + 2.0) * 3000)
    # 6 load steps of 3 N m after the lead-in, every one detected and rejected
    assert s["load_steps"]["count"] >= 5
    assert s["load_steps"]["peak_deviation_max"] < 7.0  # a 3 N m step must not stall the motor at 10 rad/s
    assert s["load_steps"]["recovery_time_1rad_s_mean"] < 0.15
    # the integral action removes the error before each next load step (1/3 s later)
    for t_end in T_MAGNETISE + np.arange(1, 6) / 3.0:
        window = (t > t_end - 0.03) & (t < t_end - 0.001)
        assert abs(np.mean(ref["omega_r_ref"][window] - truth["omega_r"][window])) < 1.0
    # the load really was applied at the shaft
    loaded = cmd["m_l_ref"] > 2.9
    assert np.median(truth["m_l"][loaded]) == pytest.approx(3.0, abs=0.05)
    # and the flux is kept at its reference
    i_m = np.hypot(truth["i_m_re"], truth["i_m_im"])
    assert np.all(np.abs(i_m[t > T_MAGNETISE] - 2.5) < 0.05)


@pytest.mark.slow  # 13 s: the whole Fig. 5.8 sweep; the shorter scenarios above check the same loop
def test_fig5_8_stepwise_sweep_tracks_every_level(tmp_path):
    s, r = session(tmp_path, "fig5.8")
    truth, ref = r.read("/truth"), r.read("/rig")
    t = r.read("/rig")["t"]
    levels = 0
    for k in range(41):  # the end of each 0.6 s dwell: mean speed over one load period (0.2 s)
        t_end = T_MAGNETISE + 0.6 * (k + 1)
        window = (t >= t_end - 0.2) & (t < t_end)
        err = np.mean(ref["omega_r_ref"][window] - truth["omega_r"][window])
        assert abs(err) < 1.0, (k, err)
        levels += 1
    assert levels == 41
    assert s["speed_error_settled"]["max_abs"] < 8.0
    # field orientation holds through the reversals: true flux within 2 % of the reference
    i_m = np.hypot(truth["i_m_re"], truth["i_m_im"])
    assert np.max(np.abs(i_m[t > T_MAGNETISE] - 2.5)) < 0.05


def test_same_seed_same_log_other_seed_other_noise(tmp_path):
    _, a = session(tmp_path, "fig5.7", seed=5, name="a", duration=0.6)
    _, b = session(tmp_path, "fig5.7", seed=5, name="b", duration=0.6)
    _, c = session(tmp_path, "fig5.7", seed=6, name="c", duration=0.6)
    for topic in ("/rig", "/ctrl", "/truth"):
        ra, rb = a.read(topic), b.read(topic)
        for f in ra:
            if f not in TIMING_FIELDS:  # wall-clock timing is the only thing allowed to differ
                assert np.array_equal(ra[f], rb[f]), (topic, f)
    assert not np.array_equal(a.read("/rig")["raw_i_a"], c.read("/rig")["raw_i_a"])
    assert a.read("/rig")["tick"].tolist() == list(range(1800))


def test_bare_bench_run_writes_run_folder(tmp_path):
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--duration", "0.5", "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    folder = Path(out["log"]).parent
    assert folder.parent == tmp_path
    assert {f.name for f in folder.iterdir()} == {"run.mcap", "summary.json", "run.png"}
    summary = json.loads((folder / "summary.json").read_text())
    for key in ("ticks", "duration", "realtime_factor", "deadline_misses", "speed_error", "trip_cause"):
        assert key in summary
    assert summary["ticks"] == 1500
    assert (folder / "run.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_listings_and_inspect(tmp_path):
    def bench(*args):
        p = subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert p.returncode == 0, p.stderr
        return p.stdout

    assert "fig5.7" in bench("scenarios") and "fig5.8" in bench("scenarios")
    assert "foc" in bench("controllers") and "speed_Kp" in bench("controllers")
    s, _ = session(tmp_path, "demo", duration=0.3)
    text = bench("inspect", s["log"])
    assert "scenario demo" in text and "/truth" in text and "rig.toml, summary.json" in text and len(text.splitlines()) < 15
    info = json.loads(bench("inspect", "--json", s["log"]))
    assert info["topics"]["/truth"][:2] == ["log_time", "i_s_re"] or "i_s_re" in info["topics"]["/truth"]
    assert info["metadata"]["run"]["seed"] == 0
    png = tmp_path / "p.png"
    bench("plot", s["log"], "--out", str(png))
    assert png.stat().st_size > 10_000


def test_plot_title_says_which_parts_ran():
    from bench.daq.plots import describe_run

    meta = {"run": {"description": "Fig. 5.9", "controller": "foc", "seed": 2,
                    "controller_params": {"observer": "jl", "current_controller": "lpv", "speed_controller": "pi",
                                          "speed_source": "estimate", "speed_estimator": "kubota"}},
            "rig": {"rig": {"name": "mock"}}}  # fmt: skip
    title = describe_run(meta)
    assert title.startswith("Fig. 5.9\n") and "observer jl" in title and "current lpv" in title
    assert "sensorless (kubota)" in title and "rig mock" in title and "seed 2" in title


def test_run_folder_and_title_say_what_distinguishes_the_run(tmp_path):
    """Two runs of the same scenario with different -p or another artifact get different folder names,
    and the plot title names the changed parameters and the artifact."""
    from bench.daq.plots import describe_run
    from bench.runtime.session import run_name

    plain = run_name("demo", "foc", {}, 0)
    tuned = run_name("demo", "foc", {"speed_Kp": 0.3, "current_wc": 800}, 0)
    own = run_name("demo", "foc", {"speed_controller": "lpv", "lpv_speed_artifact": "runs/sc"}, 0)
    shipped = run_name("demo", "foc", {"speed_controller": "lpv"}, 0)
    assert plain == "demo-foc-seed0" and run_name("demo", "foc", {"speed_Kp": 0.6}, 0) == plain  # a default
    assert "speed_Kp=0.3" in tuned and "current_wc=800" in tuned
    assert "lpv_speed_artifact=sc" in own and own != shipped and "/" not in own
    many = run_name("demo", "foc", {f"jl_K{i}_re": float(i + 1) for i in range(2)} | {
        "observer": "jl", "speed_estimator": "kubota", "speed_source": "estimate", "speed_Kp": 0.31,
        "sensorless_speed_Kp": 0.2, "kubota_lambda_c": 2000.0}, 0)  # fmt: skip
    assert len(many) < 60 and "params-" in many
    meta = {"run": {"scenario": "demo", "controller": "foc", "seed": 0,
                    "controller_params": {"observer": "current_model", "speed_controller": "lpv",
                                          "lpv_speed_artifact": "/tmp/x/sc", "speed_Kp": 0.3}},
            "rig": {"rig": {"name": "mock"}}}  # fmt: skip
    title = describe_run(meta)
    assert "speed lpv [sc]" in title and "speed_Kp=0.3" in title
    meta["run"]["controller_params"] = {"observer": "current_model", "speed_controller": "lpv"}
    assert "speed lpv;" in describe_run(meta).replace(")", ";") and "parameters" not in describe_run(meta)
    # through the CLI: the folder of a tuned run says so
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--duration", "0.2", "--no-progress", "--out",
                        str(tmp_path), "-p", "speed_Kp=0.3"], capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "-demo-foc-speed_Kp=0.3-seed0" in Path(json.loads(p.stdout)["log"]).parent.name


def test_bench_plot_after_the_run_wrote_its_png(tmp_path):
    """`bench run --log X.mcap` writes X.png; `bench plot X.mcap` then writes X-2.png (never replaces
    X.png without --force), and with --force replaces X.png."""
    def bench(*args):
        return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=tmp_path,
                              timeout=120)  # fmt: skip

    p = bench("run", "--duration", "0.2", "--no-progress", "--log", "a.mcap")
    assert p.returncode == 0, p.stderr
    first = (tmp_path / "a.png").read_bytes()
    p = bench("plot", "a.mcap")
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "a-2.png" and (tmp_path / "a-2.png").stat().st_size > 10_000
    assert (tmp_path / "a.png").read_bytes() == first
    assert bench("plot", "a.mcap").stdout.strip() == "a-3.png"
    p = bench("plot", "a.mcap", "--out", "a.png")
    assert p.returncode == 2 and "--force" in p.stderr
    p = bench("plot", "a.mcap", "--force")
    assert p.returncode == 0 and p.stdout.strip() == "a.png"


def test_an_artifact_for_other_motor_data_names_the_command_for_this_rig(tmp_path):
    """The shipped LPV designs are for the mock rig's motor: on a rig with other motor data each is refused
    with one line that gives the `bench synth ... --rig THIS-RIG` command."""
    rig = tmp_path / "my lab.toml"
    text = (ROOT / "rigs" / "mock.toml").read_text()
    assert "\nR_s = 5.0\n" in text
    rig.write_text(text.replace("\nR_s = 5.0\n", "\nR_s = 5.5\n", 1))
    for param, command in (("observer=lpv", "bench synth flux-observer"),
                           ("current_controller=lpv", "bench synth current-controller"),
                           ("speed_controller=lpv", "bench synth speed-controller")):  # fmt: skip
        p = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(rig), "-p", param, "--duration", "0.1",
                            "--no-progress", "--out", str(tmp_path / "runs")], capture_output=True, text=True,
                           cwd=tmp_path, timeout=60)  # fmt: skip
        assert p.returncode == 2, p.stderr
        assert len(p.stderr.strip().splitlines()) == 1 and "other motor data (R_s" in p.stderr
        assert f"{command} " in p.stderr and f"--rig '{rig}'" in p.stderr, p.stderr
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", "mock", "-p", "observer=lpv", "-p",
                        f"lpv_artifact={ROOT / 'bench' / 'nonexistent'}", "--duration", "0.1", "--no-progress"],
                       capture_output=True, text=True, cwd=tmp_path, timeout=60)  # fmt: skip
    assert p.returncode == 2 and "RIG" not in p.stderr  # other refusals are untouched


def test_bench_run_takes_the_compiled_engines_where_they_pay_and_keeps_a_choice(tmp_path):
    """Real time or >= 25 s simulated: the compiled plant and FOC (bit-identical, numba's start-up paid back); a short
    lockstep run the reference; -p engine=python and a rig file's [mock] engine are kept."""
    pytest.importorskip("numba")
    from bench.runtime.session import COMPILED_FROM, default_engines

    cfg = load_rig("mock")
    assert "engine" not in cfg.mock
    c, p, note = default_engines(cfg, "foc", {}, 2.0, realtime=False)
    assert c is cfg and p == {} and note is None
    for duration, realtime in ((2.0, True), (COMPILED_FROM, False)):  # (the session start warmed numba's cache)
        c, p, note = default_engines(cfg, "foc", {}, duration, realtime)
        assert c.mock["engine"] == "auto" and p == {"engine": "auto"} and note is None
    c, p, _ = default_engines(dataclasses.replace(cfg, mock={**cfg.mock, "engine": "python"}), "foc",
                              {"engine": "python"}, 30.0, True)  # fmt: skip
    assert c.mock["engine"] == "python" and p == {"engine": "python"}
    assert default_engines(cfg, "relay_tune", {}, 30.0, False)[1] == {}  # a plugin without the parameter
    summary, code = run(RunOptions(scenario="fig5.7", duration=COMPILED_FROM, log_enabled=False, progress=False))
    assert code == 0 and summary["engines"] == {"plant": "compiled", "controller": "compiled"}
