"""The Sobol study on the batch engine (`bench.workflows.reproductions.sensitivity`), small: 1024 cases, a few seconds.

What could fail: the current model (4.15) uses R_r (through the rotor time constant) and not R_s, so R_r must carry
most of the flux-angle error's variance with an interval clear of zero, and R_s none of it; the speed-tracking error
over the settled ticks is the load step's dip, set by the load. Indices must be consistent: each total index at
least its first-order one (within their intervals), the first-order ones summing to at most about 1.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("numba")
pytest.importorskip("SALib")

from bench.workflows.reproductions import sensitivity as sens  # noqa: E402


@pytest.fixture(scope="module")
def doc() -> dict:
    return sens.study(n=128, batch=512, resamples=300, progress=False)


def test_rr_dominates_the_flux_angle_error_and_rs_does_not_enter(doc: dict) -> None:
    f = doc["indices"]["flux_angle_rms_deg"]["factors"]
    assert max(f, key=lambda k: f[k]["ST"]) == "R_r"
    assert f["R_r"]["S1"] - f["R_r"]["S1_conf"] > 0.2  # the interval excludes zero, by a margin
    assert f["R_r"]["ST"] > 0.5
    assert abs(f["R_s"]["ST"]) < 0.01 and abs(f["R_s"]["S1"]) < 0.02  # the current model has no R_s


def test_the_load_sets_the_speed_tracking_error(doc: dict) -> None:
    f = doc["indices"]["speed_error_settled_rms"]["factors"]
    assert max(f, key=lambda k: f[k]["ST"]) == "load"
    assert f["load"]["S1"] - f["load"]["S1_conf"] > 0.5


def test_indices_are_consistent(doc: dict) -> None:
    assert doc["cases"] == 128 * (len(sens.FACTORS) + 2) and doc["motor_ticks"] == doc["cases"] * 3000
    for key, _ in sens.OUTPUTS:
        f = doc["indices"][key]["factors"]
        assert sum(v["S1"] for v in f.values()) < 1.1
        for v in f.values():
            assert v["ST"] + v["ST_conf"] >= v["S1"] - v["S1_conf"] - 1e-9
            assert -0.05 < v["ST"] < 1.2 and v["S1_conf"] >= 0 and v["ST_conf"] >= 0
        assert doc["indices"][key]["std"] > 0


def test_markdown_and_plot(doc: dict, tmp_path) -> None:  # noqa: ANN001
    md = sens.markdown(doc)
    assert md.count("| R_r (true / nominal) |") == 2 and "±" in md
    png = sens.plot(doc, tmp_path / "s.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_command_line_bad_input_is_one_line_exit_2(tmp_path) -> None:  # noqa: ANN001
    p = subprocess.run([sys.executable, "-m", "bench.workflows.reproductions.sensitivity",
                        "--out", str(tmp_path), "--n", "100"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 2 and "--n" in p.stderr and "power of 2" in p.stderr and "Traceback" not in p.stderr
    assert p.stdout == ""


def test_command_line_writes_json_png_md(tmp_path) -> None:  # noqa: ANN001
    p = subprocess.run([sys.executable, "-m", "bench.workflows.reproductions.sensitivity",
                        "--out", str(tmp_path), "--n", "16",
                        "--resamples", "50"], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["cases"] == 128 and "ETA" in p.stderr
    assert (tmp_path / "sensitivity.png").is_file() and (tmp_path / "sensitivity.md").read_text().startswith("**")
