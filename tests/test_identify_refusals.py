"""Bad input to `bench identify` and `bench commission` as real subprocesses: exit 2, one line naming the field,
refused before any test runs, and nothing left behind (no run folder, no OUT folder). No identification runs
here: every case is refused up front."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.core.config import RIGS_DIR

BIG = "9" * 400


def _bench(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=cwd, capture_output=True, text=True, timeout=120)


def _refused(p: subprocess.CompletedProcess, field: str) -> str:
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1, (p.returncode, p.stderr)
    assert lines[0].startswith(f"bench: error: {field}"), lines[0]
    return lines[0]


@pytest.fixture
def rig(tmp_path: Path) -> Path:
    """A writable copy of the mock rig (commission writes [motor] on GO; nothing runs here)."""
    p = tmp_path / "lab.toml"
    p.write_text((RIGS_DIR / "mock.toml").read_text())
    return p


STANDSTILL = "controller.standstill_id."
ROTATING = "controller.rotating_id."
CASES = [  # (arguments after the command, the field the one line names, words it says)
    (("-p", "dc_current=abc"), STANDSTILL + "dc_current", "must be a number in (0, 50] A"),
    (("-p", "="), "--param", "expected NAME=VALUE"),
    (("-p", "==1"), "--param", "expected NAME=VALUE"),
    (("-p", "=1=2"), "--param", "expected NAME=VALUE"),
    (("-p", f"dc_current={BIG}"), STANDSTILL + "dc_current", "an integer of 400 digits"),
    (("-p", "dc_current=nan"), STANDSTILL + "dc_current", "got nan"),  # was blamed on "duration"
    (("-p", "dc_current=1e-320"), STANDSTILL + "dc_current", "not subnormal"),  # failed after the 12 s test
    (("-p", "ac_bias=-5e-324"), STANDSTILL + "ac_bias", "not subnormal"),
    (("-p", "lpv_speed_artifact=/etc/passwd"), STANDSTILL + "lpv_speed_artifact", "unknown parameter"),
    (("-p", "bogus=1"), STANDSTILL + "bogus", "unknown parameter"),
    (("-r", "omega_test=100"), "--rotating-param", "-r needs --rotating"),  # was ignored
    (("--rotating", "-r", "bogus=1"), ROTATING + "bogus", "unknown parameter"),  # came after the standstill test
    (("--rotating", "-r", "lpv_speed_artifact=/etc/passwd"), ROTATING + "lpv_speed_artifact", "unknown parameter"),
    (("--rotating", "-r", "omega_test=1e-320"), ROTATING + "omega_test", "not subnormal"),
    (("--rotating", "-r", "omega_test=300"), ROTATING + "omega_test", "must be <= 280 rad/s"),  # the rig's limit
    (("--rotating", "-r", "flux_lo=1.3"), ROTATING + "flux_lo", "must be below flux_hi"),
    (("--rotating", "-r", "model_R_s=3"), "--rotating-param model_R_s", "set by the standstill test"),
    (("--rotating", "-r", "=1"), "--rotating-param", "expected NAME=VALUE"),
    (("-p", "psi_rated=0.95"), "--param psi_rated", "use -r psi_rated=0.95"),  # the rotating test's, given to -p
    (("--rotating", "-r", "dc_current=3"), "--rotating-param dc_current", "use -p dc_current=3"),
]  # fmt: skip
# bench commission runs the rotating test by default on the mock rig: -r needs it not to be switched off
COMMISSION_CASES = [(("--standstill-only", *a) if a[0] == "-r" else a, f, w) for a, f, w in CASES
                    if a[0] != "-p" or "bogus" in a[1] or "nan" in a[1] or "lpv" in a[1] or "psi" in a[1]]  # fmt: skip


@pytest.mark.parametrize("args, field, words", CASES, ids=lambda x: " ".join(x) if isinstance(x, tuple) else None)
def test_identify_refuses_before_the_test(tmp_path, rig, args, field, words):
    p = _bench(tmp_path, "identify", "--rig", str(rig), "--out", "runs", *args)
    assert words in _refused(p, field)
    assert sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]  # no runs/, no run folder


@pytest.mark.parametrize("args, field, words", COMMISSION_CASES,
                         ids=lambda x: " ".join(x) if isinstance(x, tuple) else None)  # fmt: skip
def test_commission_refuses_before_out_is_made(tmp_path, rig, args, field, words):
    p = _bench(tmp_path, "commission", "--rig", str(rig), "--out", "report", *args)
    assert words in _refused(p, field)
    assert sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]  # no OUT (it used to be left empty)


def test_commission_out_that_cannot_be_made(tmp_path, rig):
    p = _bench(tmp_path, "commission", "--rig", str(rig), "--out", "/proc/self/x")  # exited 3 (an OSError)
    assert "cannot make the folder /proc/self/x" in _refused(p, "--out")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]


def test_identify_from_log_refuses_rotating_parameters(tmp_path):
    p = _bench(tmp_path, "identify", "--from-log", "run.mcap", "-r", "omega_test=100")
    assert "-r needs --rotating" in _refused(p, "--rotating-param")
    assert list(tmp_path.iterdir()) == []
