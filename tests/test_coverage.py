"""The coverage study of bench identify's intervals (bench.workflows.commission.coverage) as a real subprocess: JSON on
stdout, progress with an ETA on stderr, every reported interval scored against the hidden truth; on a linear fleet motor
every interval holds the truth. The 100-motor study is a documented command (docs/results/identify-intervals.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.workflows.commission.coverage import intervals, summarise, table, truth_of, wilson
from bench.workflows.commission.fleet import draw_fleet

ROOT = Path(__file__).resolve().parents[1]
KEYS = {"inverse_gamma.R_s", "inverse_gamma.L_sigma", "inverse_gamma.R_R", "inverse_gamma.L_M", "thesis.L_s",
        "thesis.L_m", "thesis.R_r", "sat_point.L_m", "sat_point.L_M", "sat_point.L_sigma", "R_s_free.R_s",
        "R_s_free.L_sigma", "R_s_free.R_R", "R_s_free.L_M"}  # fmt: skip


def _study(out: Path, motors: int, *extra: str) -> tuple[dict, str]:
    p = subprocess.run([sys.executable, "-m", "bench.workflows.commission.coverage",
                        "--motors", str(motors), "--out", str(out),
                        *extra], capture_output=True, text=True, cwd=ROOT, timeout=900)  # fmt: skip
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout), p.stderr


def test_one_linear_motor(tmp_path: Path) -> None:
    """Fleet motor m000 (5.5 kW, linear): every interval bench identify reports is scored, each holds the truth."""
    res, err = _study(tmp_path, 1)
    assert "identifications: 1/1 (100%)" in err and "ETA" in err
    full = json.loads(Path(res["json"]).read_text())
    row = full["rows"][0]
    assert row["motor"] == "m000" and row["kind"] == "linear" and not row["refused"] and row["log"] is None
    assert set(row["intervals"]) == KEYS
    for key, x in row["intervals"].items():
        assert x["inside"], (key, x)
        assert abs(x["error_rel"]) <= x["half_rel"] < 0.05, key
    s = res["summary"]["linear"]["quantities"]
    assert all(q["coverage"] == 1.0 and q["n"] == 1 for q in s.values())
    again, err2 = _study(tmp_path, 1)  # done motors are not run again
    assert "identifications: 1/1" in err2 and again["summary"] == res["summary"]


def test_rotating_intervals_scored_and_fitted_again_from_the_logs(tmp_path: Path) -> None:
    """--rotating on m000: the rotating test's intervals (L_m at the rated flux, J, friction) are scored beside the
    standstill ones and hold the truth; --from-logs fits both kept logs again to the same scores."""
    res, _ = _study(tmp_path, 1, "--rotating", "--keep-logs")
    assert "then rotating" in res["study"]
    row = json.loads(Path(res["json"]).read_text())["rows"][0]
    rot = {f"rotating.{n}" for n in ("L_m_rated", "J", "B_visc", "m_coulomb")}
    assert set(row["intervals"]) == KEYS | rot and Path(row["log_rotating"]).exists()
    for key in rot:
        assert row["intervals"][key]["inside"], (key, row["intervals"][key])
    p = subprocess.run([sys.executable, "-m", "bench.workflows.commission.coverage", "--motors", "1", "--from-logs",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=900)  # fmt: skip
    assert p.returncode == 0, p.stderr
    again = json.loads((tmp_path / "coverage-refit.json").read_text())["rows"][0]
    assert again["intervals"] == row["intervals"]


@pytest.mark.slow
def test_four_motors_linear_and_saturating(tmp_path: Path) -> None:
    """m000-m003: linear, mild, linear, strong. Every interval of the linear ones holds the truth; on the saturating
    ones the saturation warning is there and the test bias's L_m interval holds the incremental L_m there."""
    res, _ = _study(tmp_path, 4)
    rows = json.loads(Path(res["json"]).read_text())["rows"]
    for r in rows:
        if r["kind"] == "linear":
            assert all(x["inside"] for x in r["intervals"].values()), r["motor"]
            assert not r["bias_dependent"]
        else:
            assert r["bias_dependent"] and any(w.startswith("saturation:") for w in r["warnings"])
            for key in ("inverse_gamma.L_M", "thesis.L_m", "thesis.L_s"):
                assert r["intervals"][key]["inside"], (r["motor"], key)


def test_scoring_pieces() -> None:
    """The truth on a saturating motor is the incremental L_m at each bias; the table marks shares below 90 %."""
    m = draw_fleet(2, 0)[1]
    assert m.kind == "mild"
    val = {"value": 1.0, "ci95": [0.9, 1.1]}
    res = {"inverse_gamma": {n: val for n in ("R_s", "L_sigma", "R_R", "L_M")},
           "thesis_L_s_eq_L_r": {n: val for n in ("L_s", "L_m", "R_r", "L_r", "R_s")},
           "saturation": {"test_bias_A": 4.0, "points": [{"bias_A": 2.0, "L_m": val, "L_M": val, "L_sigma": val},
                                                        {"bias_A": 4.0, "L_m": val, "L_M": val, "L_sigma": val}]},
           "ac": {"R_s_free_check": {n: val for n in ("R_s", "L_sigma", "R_R", "L_M")}},
           "conditions": {"ac_bias_A": 4.0, "sat_bias_A": 2.0}}  # fmt: skip
    assert set(intervals(res)) == KEYS
    tr = truth_of(m, res)
    assert tr["thesis.L_m"] < tr["sat_point.L_m"] < m.sat_curve().L_m0  # incremental: lower at the higher bias
    assert tr["inverse_gamma.R_s"] == m.true.R_s
    lo, hi = wilson(95, 100)
    assert lo < 0.95 < hi and 0.88 < lo and hi < 0.99
    rows = [{"kind": "linear", "intervals": {"a.x": {"inside": k < 8, "z": 0.5, "half_rel": 0.01, "error_rel": 0.0}}}
            for k in range(10)]  # fmt: skip
    s = summarise(rows)
    assert s["linear"]["quantities"]["a.x"]["coverage"] == 0.8 and not s["linear"]["quantities"]["a.x"]["pass"]
    assert "**80 %**" in table({"summary": s}, ("linear",))
