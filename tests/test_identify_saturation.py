"""The standstill test's saturation check: the multisine on a second DC bias (sat_bias) gives the incremental L_m
there; on a saturating machine it differs from the L_m at the test's own bias (ac_bias), and `bench identify` says
so in one line on stderr and in the JSON's warnings, reports the L_m(bias) points, and `--write` writes nothing
(exit 2, the rig file untouched) without --rotating. On a linear machine: the points, and no message. Real
subprocesses of `bench identify` on the default mock (linear), rigs/mock-real.toml and a strongly saturating
motor (psi_sat 0.95 Wb, exponent 5)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.workflows.commission.identify import saturated_write_refusal, saturation_check

ROOT = Path(__file__).resolve().parents[1]


def _bench(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", "identify", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)  # fmt: skip


def _strong(tmp: Path) -> Path:
    text = (ROOT / "rigs" / "mock-real.toml").read_text().replace('name = "mock-real"', 'name = "strong"')
    assert "psi_sat = 1.1 " in text and "sat_exp = 7.0" in text
    path = tmp / "strong.toml"
    path.write_text(text.replace("psi_sat = 1.1 ", "psi_sat = 0.95 ").replace("sat_exp = 7.0", "sat_exp = 5.0"))
    return path


def _points(sat: dict) -> dict[float, dict]:
    assert [x["bias_A"] for x in sat["points"]] == [1.0, 2.0]
    for x in sat["points"]:
        lo, hi = x["L_m"]["ci95"]
        assert lo < x["L_m"]["value"] < hi and x["flux_Wb"] > 0 and x["residual_rms_rel"] < 0.03
    return {x["bias_A"]: x for x in sat["points"]}


def _saturating(p: subprocess.CompletedProcess, res: dict, low: float) -> None:
    sat = res["saturation"]
    pts = _points(sat)
    assert sat["bias_dependent"] and sat["test_bias_A"] == 2.0
    assert pts[1.0]["L_m"]["value"] > low * pts[2.0]["L_m"]["value"]  # incremental L_m falls with the flux
    assert pts[1.0]["L_m"]["ci95"][0] > pts[2.0]["L_m"]["ci95"][1]
    line = [w for w in res["warnings"] if w.startswith("saturation:")]
    assert len(line) == 1 and "\n" not in line[0] and "--rotating" in line[0]
    assert f"{pts[2.0]['L_m']['value']:.3g} H at 2 A, {pts[1.0]['L_m']['value']:.3g} H at 1 A" in line[0]
    assert sum("saturation:" in x for x in p.stderr.splitlines()) == 1


def test_linear_mock_no_message(tmp_path: Path) -> None:
    """The default mock is linear: the same L_m at 1 A and 2 A within a few %, no warning, exit 0."""
    p = _bench("--out", str(tmp_path), cwd=ROOT)
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    sat = res["saturation"]
    pts = _points(sat)
    assert not sat["bias_dependent"] and sat["message"] is None and abs(sat["difference_rel"]) < 0.03
    assert pts[2.0]["flux_Wb"] == pytest.approx(2 * pts[1.0]["flux_Wb"], rel=0.03)
    assert res["warnings"] == [] and "saturation" not in p.stderr
    assert res["conditions"]["sat_bias_A"] == 1.0


def test_mock_real_saturation_message(tmp_path: Path) -> None:
    """rigs/mock-real.toml (psi_sat 1.1 Wb, exponent 7): incremental L_m about 0.24 H at 2 A, 0.40 H at 1 A."""
    p = _bench("--rig", "mock-real", "--out", str(tmp_path), cwd=ROOT)
    assert p.returncode == 0, p.stderr
    _saturating(p, json.loads(p.stdout), 1.4)


def test_strong_saturation_write_refused(tmp_path: Path) -> None:
    """psi_sat 0.95 Wb, exponent 5, --write: exit 2 with one line naming --rotating, the rig file untouched, no
    backup; the identification (points, warning) is in identify.json all the same."""
    rig = _strong(tmp_path)
    before = rig.read_bytes()
    p = _bench("--rig", str(rig), "--out", str(tmp_path / "runs"), "--write", cwd=ROOT)
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1, p.stderr
    assert lines[0].startswith("bench: error: --write: not written: the incremental L_m depends on the flux")
    assert "--rotating" in lines[0]
    assert rig.read_bytes() == before and not list(tmp_path.glob("*.bak"))
    res = json.loads(next((tmp_path / "runs").glob("*/identify.json")).read_text())
    assert res["written"] is None
    _saturating(subprocess.CompletedProcess([], 0, "", res["saturation"]["message"]), res, 2.0)


def _fit_stub(L_m: float, half: float, bias: float) -> tuple:
    class F:
        residual_rms = 0.002

    th = {"L_m": {"value": L_m, "ci95": [L_m - half, L_m + half]}}
    ig = {"L_M": {"value": L_m, "ci95": [L_m - half, L_m + half]}, "L_sigma": {"value": 0.02, "ci95": [0.02, 0.02]}}
    return bias, F(), (ig, th)


@pytest.mark.parametrize("L1, h1, L2, h2, dep", [
    (0.34, 0.002, 0.341, 0.002, False),  # linear
    (0.34, 0.002, 0.35, 0.002, False),  # 3 % apart, outside the intervals: below the 5 % tolerance
    (0.34, 0.03, 0.37, 0.03, False),  # 8.5 % apart, inside the intervals
    (0.238, 0.005, 0.405, 0.006, True),  # mock-real
])  # fmt: skip
def test_saturation_check_rule(L1: float, h1: float, L2: float, h2: float, dep: bool) -> None:
    sat = saturation_check([_fit_stub(L1, h1, 2.0), _fit_stub(L2, h2, 1.0)])
    assert sat["bias_dependent"] is dep and (sat["message"] is not None) is dep
    assert [x["bias_A"] for x in sat["points"]] == [1.0, 2.0]
    assert sat["points"][0]["flux_Wb"] == pytest.approx(L2)
    assert sat["points"][1]["flux_Wb"] == pytest.approx(L2 + 0.5 * (L1 + L2))
    why = saturated_write_refusal({"saturation": sat})
    assert (why is not None) is dep
    assert saturated_write_refusal({"saturation": sat, "rotating": {}}) is None  # the rotating test's L_m
    assert saturated_write_refusal({"saturation": None}) is None  # no check (sat_bias = 0, an older log)
