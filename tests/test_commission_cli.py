"""`bench commission` as a real subprocess on the mock rig: a hidden motor commissioned to GO (the rig
file's [motor] written, close to the truth, the artifacts made for it, the report); a check that
cannot pass (NO-GO, the rig file byte for byte unchanged); bad input; SIGINT mid-way."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from bench.workflows.commission.check import GO, check_scenario, rated_speed
from bench.core.config import load as load_rig
from bench.errors import BadInput

ROOT = Path(__file__).resolve().parents[1]
#: a machine unlike (3.57) behind a rig whose [motor] is still (3.57); the inverter of mock-real, no saturation
HIDDEN = {"L_s": 0.30, "L_r": 0.30, "L_m": 0.285, "R_s": 3.8, "R_r": 4.4}


def _rig(tmp_path: Path, hidden: bool = True) -> Path:
    text = (ROOT / "rigs" / "mock-real.toml").read_text()
    text = text.replace("saturation = true", "saturation = false")
    if hidden:  # appended to [mock.motor], the file's last table
        text += "".join(f"{k} = {v}\n" for k, v in HIDDEN.items())
    p = tmp_path / "lab.toml"
    p.write_text(text)
    assert load_rig(str(p)).motor.L_m == 0.341  # the rig still believes (3.57)
    return p


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


@pytest.mark.slow  # the GO path and the write run in the default suite with --rotating (below)
def test_commission_hidden_motor_go(tmp_path: Path) -> None:
    rig = _rig(tmp_path)
    out = tmp_path / "report"
    p = _bench("commission", "--rig", str(rig), "--out", str(out))
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["go"] and res["verdict"] == "GO"
    motor = tomllib.loads(rig.read_text())["motor"]
    for n, v in HIDDEN.items():  # written, and near the hidden truth (L_s = L_r holds for this machine)
        assert motor[n] == pytest.approx(v, rel=0.02), n
    assert Path(res["written"]["backup"]).read_text() != rig.read_text()
    rep = json.loads((out / "commission.json").read_text())
    for name in ("flux observer", "current controller"):
        s = rep["stages"][name]
        assert s["result"] == "verified" and 1.0 <= s["gap"] < 1.2  # certified: gamma near its lower bound
        art = json.loads(Path(s["artifact"] + ".json").read_text())
        if "motor" in art:  # the design is for the identified motor
            assert art["motor"]["L_m"] == pytest.approx(motor["L_m"], rel=1e-4)
    cl = rep["stages"]["closed loop"]
    assert cl["truth"]["flux_angle_p95_deg"] < GO.flux_angle_p95_deg and cl["exit_code"] == 0
    assert (out / "report.md").read_text().startswith("# Commissioning report: GO")
    assert (out / "closed_loop.png").stat().st_size > 10_000
    assert all(Path(q).exists() for q in rep["stages"]["identify"]["plots"])


@pytest.mark.slow  # the rig file unchanged on a stop: also the SIGINT and shipped-rig tests (default suite)
def test_commission_no_go_leaves_the_rig_file(tmp_path: Path) -> None:
    """rigs/mock-real.toml as it is, main-flux saturation on, the standstill test only (--standstill-only): it
    measures the incremental L_m at its bias flux, about 30 % below the secant L_m at the check's flux, so the
    observer designed for it is off (flux angle about 15 deg, magnitude about 35 %, against the truth): NO-GO
    (exit 1) on the flux criteria a real rig measures (the voltage and the current model 70 % apart), and the rig
    file is unchanged, no backup made."""
    rig = tmp_path / "lab.toml"
    rig.write_text((ROOT / "rigs" / "mock-real.toml").read_text())
    before = rig.read_bytes()
    out = tmp_path / "report"
    p = _bench("commission", "--rig", str(rig), "--out", str(out), "--standstill-only")
    assert p.returncode == 1, p.stderr
    res = json.loads(p.stdout)
    assert not res["go"] and "flux magnitude: voltage vs current model" in res["verdict"]
    assert "truth" not in res["verdict"]  # judged as a real rig would: the truth withheld
    assert "NO-GO" in p.stderr.splitlines()[-1]
    assert rig.read_bytes() == before and not list(tmp_path.glob("*.bak"))
    assert "was not changed" in (out / "report.md").read_text()


@pytest.mark.parametrize("args, field", [(("--rated-speed", "390"), "--rated-speed"),
                                         (("--current-rate", "700"), "--current-rate"),
                                         (("--rotating", "--voltages", "reference"), "--rotating")])  # fmt: skip
def test_commission_bad_input(tmp_path: Path, args: tuple[str, ...], field: str) -> None:
    rig = _rig(tmp_path)
    p = _bench("commission", "--rig", str(rig), "--out", str(tmp_path / "r"), *args)
    assert p.returncode == 2 and field in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_commission_refuses_a_used_folder(tmp_path: Path) -> None:
    rig = _rig(tmp_path)
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "x").write_text("")
    p = _bench("commission", "--rig", str(rig), "--out", str(tmp_path / "r"))
    assert p.returncode == 2 and "--out" in p.stderr


def test_commission_sigint_during_identification(tmp_path: Path) -> None:
    """SIGINT while the motor is being identified: the session's shutdown (exit 130), the log readable,
    the rig file untouched."""
    from bench.daq import LogReader

    rig = _rig(tmp_path)
    before = rig.read_bytes()
    out = tmp_path / "report"
    proc = subprocess.Popen([sys.executable, "-m", "bench", "commission", "--rig", str(rig), "--out", str(out),
                             "-p", "ac_periods=20"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    deadline = time.monotonic() + 60
    while not list(out.glob("identify/*/run.mcap")) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    res = json.loads(stdout)
    assert not res["go"] and "interrupted" in res["verdict"]
    assert rig.read_bytes() == before and not list(tmp_path.glob("*.bak"))
    log = next(out.glob("identify/*/run.mcap"))
    meas, = LogReader(log).read_ticks("/rig")
    assert meas["t"].size > 100


def test_rated_speed_and_scenario() -> None:
    cfg = load_rig("mock")
    w = rated_speed(cfg)
    assert 0 < w <= 0.75 * cfg.limits.omega_max
    assert w * cfg.motor.L_s * 2.5 <= 0.85 * cfg.limits.u_dc_min / 3**0.5 + 1e-9  # within the voltage
    with pytest.raises(BadInput, match="--rated-speed"):
        rated_speed(cfg, 0.95 * cfg.limits.omega_max)
    scn = check_scenario(200.0)
    assert scn.speed_ref(0.0) == 0.0 and scn.speed_ref(scn.duration - 1e-3) == pytest.approx(200.0)


@pytest.mark.slow  # 32 s; the README's commission block (slow too) runs it as written, the rotating
# identification itself is in the default suite (tests/test_rotating_id.py)
def test_commission_rotating_go_on_the_saturated_mock(tmp_path: Path) -> None:
    """The same saturating rig with --rotating: the no-load test gives the secant L_m at the rated flux and
    the ramps J and the friction, so the designs fit the machine at the check's flux: GO, and [motor] carries
    (3.57)'s L_m and the mock's J."""
    rig = tmp_path / "lab.toml"
    rig.write_text((ROOT / "rigs" / "mock-real.toml").read_text())
    out = tmp_path / "report"
    p = _bench("commission", "--rig", str(rig), "--out", str(out), "--rotating")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["go"]
    motor = tomllib.loads(rig.read_text())["motor"]
    true = tomllib.loads((ROOT / "rigs" / "mock-real.toml").read_text())["mock"]["motor"]
    assert "L_m" not in true  # the mock's machine is (3.57) with the saturation curve: L_m = 0.341 H at psi_rated
    assert motor["L_m"] == pytest.approx(0.341, rel=0.03) and motor["J"] == pytest.approx(0.0125, rel=0.05)
    rep = json.loads((out / "commission.json").read_text())
    assert rep["stages"]["closed loop"]["truth"]["flux_angle_p95_deg"] < GO.flux_angle_p95_deg
    assert any("rot_magnetising" in q for q in rep["stages"]["identify"]["plots"])


@pytest.mark.slow
def test_commissioned_vs_true_on_five_hidden_motors() -> None:
    """`bench perf commission --rotating`: every hidden motor commissions to GO, and the flux-angle and speed-
    tracking errors in Fig. 5.7's experiment are within 20 % of the same designs made with the true parameters.
    (From the standstill test alone the flux angle is not: docs/commissioning.md, "Commissioned vs true".)"""
    p = _bench("perf", "commission", "--motors", "5", "--rotating")
    assert p.returncode == 0, p.stderr[-2000:]
    res = json.loads(p.stdout)
    assert res["all_go"] and len(res["rows"]) == 5
    assert max(res["worst_ratio"].values()) <= 1.2


@pytest.mark.parametrize("cmd", [("commission", "--rig", "mock-real", "--out", "{out}"),
                                 ("identify", "--rig", "mock-real", "--write", "--out", "{out}")])  # fmt: skip
def test_a_shipped_rig_file_is_never_written(tmp_path: Path, cmd: tuple[str, ...]) -> None:
    """The rig files shipped with imbench are the source tree's: refused before any test runs, one line, exit 2."""
    before = (ROOT / "rigs" / "mock-real.toml").read_bytes()
    p = _bench(*(c.format(out=tmp_path / "o") for c in cmd))
    assert p.returncode == 2 and "shipped with imbench" in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert (ROOT / "rigs" / "mock-real.toml").read_bytes() == before and not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra, args, field, words", [
    ("", ("--rated-speed", "350"), "--rated-speed", "give at most 320 rad/s"),  # inside 0.9 x, outside the margin
    ("\n[mock.load]\ntorque_limit = 3.5\n", (), "mock.load.torque_limit", "a load torque of 3 N m"),
    ])  # fmt: skip
def test_commission_refuses_a_check_outside_the_margins(tmp_path: Path, extra: str, args: tuple[str, ...],
                                                        field: str, words: str) -> None:  # fmt: skip
    """The closed-loop check's set-points outside the rig's margins: refused before any test runs (exit 2, one
    line naming the field and what is allowed; no report folder made, the rig file as it was)."""
    rig = _rig(tmp_path)
    rig.write_text(rig.read_text() + extra)
    before = rig.read_bytes()
    p = _bench("commission", "--rig", str(rig), "--out", str(tmp_path / "r"), *args)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    line = p.stderr.strip()
    assert len(line.splitlines()) == 1 and field in line and words in line and "outside [-" in line, line
    assert not (tmp_path / "r").exists() and rig.read_bytes() == before
