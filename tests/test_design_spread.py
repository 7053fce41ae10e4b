"""`bench.commission.design_spread`: the LPV flux observer's sensitivity to its motor model."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.commission.design_spread import change, spread

ROOT = Path(__file__).resolve().parents[1]


def test_change_is_relative_at_each_point() -> None:
    """A 1 % change where the response is small counts as 1 %, not as 1 % of the largest response elsewhere."""
    ref = np.ones((3, 3, 2), dtype=complex)
    ref[2] *= 0.01  # the observer's gain at its top speed is ~100 times smaller
    H = ref.copy()
    H[2, 1, 0] *= 1.01
    assert change(H, ref) == pytest.approx(0.01)
    assert change(ref, ref) == 0.0


@pytest.mark.parametrize("args, field", [(("--param", "J"), "--param"), (("--report", "no-such.json"), "no-such.json"),
                                         (("--rig", "no-such.toml"), "no rig file"),
                                         (("--design", "speed-controller"), "--design")])  # fmt: skip
def test_bad_input_is_one_line_and_exit_2(args: tuple[str, ...], field: str) -> None:
    """Refused before any design: one line naming what is wrong, exit 2, no traceback."""
    cmd = [sys.executable, "-m", "bench.commission.design_spread", "--rig", "rigs/mock.toml", *args]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and field in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr


@pytest.mark.slow  # two syntheses, about 15 s
def test_the_design_is_deterministic() -> None:
    """The same model gives the same observer to the bit: what the spread measures is the model's step, not the
    solver's run-to-run noise."""
    res = spread(str(ROOT / "rigs" / "mock.toml"), "R_r", [0.0])
    assert [d["response_change_max"] for d in res["designs"]] == [0.0, 0.0]


@pytest.mark.slow  # two syntheses of the current controller, about 20 s
def test_the_current_controller_is_measured_too() -> None:
    """--design current-controller: the same comparison over the controller's frozen responses on its δ box; the same
    model gives the same controller to the bit, from the same end scaling of its bisection."""
    res = spread(str(ROOT / "rigs" / "mock.toml"), "R_r", [0.0], design="current-controller")
    assert res["design"] == "current-controller"
    assert [d["response_change_max"] for d in res["designs"]] == [0.0, 0.0]
    # each row says where its bisection ended and how its solution was centred: the same for the same model
    a, b = res["designs"]
    assert len(a["scaling_T"]) == 3 and all(t > 0 for t in a["scaling_T"])
    assert (a["scaling_T"], a["margin_frac"], a["order"]) == (b["scaling_T"], b["margin_frac"], b["order"])
    assert a["margin_frac"] in (0.5, 0.2, 0.1, 0.05) and a["order"] >= 1
