"""`bench identify --write` ended by faults, each a real subprocess (real signals, a real log-writer
process): a torque turns the shaft mid-test, a failed switch drives an over-current, the voltage
headroom runs out, SIGINT and SIGTERM, a stalled log writer; and a warming motor refused after the
fit. Every one: the exit code of the rest of bench, the safe command from the trip's tick on, a log
that reads to the fault, summary.json, and the rig file byte for byte as it was (no backup either)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from bench.daq import LogReader
from harness.fault_matrix import writer_pid

ROOT = Path(__file__).resolve().parents[1]
# a short test: 2 DC levels per polarity, one multisine period (about 3.6 s of loop time)
SHORT = ("-p", "dc_levels=2", "-p", "dc_settle=0.2", "-p", "dc_average=0.05", "-p", "ac_periods=1",
         "-p", "ac_settle=0.2", "-p", "check_settle=0.15", "-p", "check_average=0.05")  # fmt: skip
LONG = ("-p", "ac_periods=30")  # about 44 s of loop time: a signal surely lands inside the loop


def _rig_copy(tmp: Path, name: str = "mock") -> Path:
    rig = tmp / "rig" / f"{name}.toml"
    rig.parent.mkdir()
    rig.write_bytes((ROOT / "rigs" / f"{name}.toml").read_bytes())
    return rig


def _args(rig: Path, out: Path, *extra: str) -> list[str]:
    return ["identify", "--rig", str(rig), "--out", str(out), "--write", *extra]


def _script(patch: str, args: list[str]) -> list[str]:
    """``python -c``: `bench identify` with a fault planted in the process (the mock plant, the DC load)."""
    body = "import sys\n" + textwrap.dedent(patch) + f"\nfrom bench.cli import main\nmain({args!r})\n"
    return [sys.executable, "-c", body]


def _popen(cmd: list[str]) -> subprocess.Popen:
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})  # fmt: skip


def _ticking(out: Path, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """Wait until the run's log holds ticks (the loop runs)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        for log in out.glob("*/run.mcap"):
            try:
                if LogReader(log).summary()["topics"].get("/rig", {}).get("messages", 0) > 0:
                    return
            except Exception:  # noqa: BLE001 - not there yet, or mid-write
                pass
        time.sleep(0.05)
    raise AssertionError("the loop did not start")


def _ended_safely(proc: subprocess.Popen, rig: Path, before: bytes, code: int, cause: str) -> dict:
    """The common checks; returns the JSON the command printed."""
    out, err = proc.communicate(timeout=180)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    res = json.loads(out)
    assert cause in res["tripped"], res["tripped"]
    assert "inverse_gamma" not in res and "written" not in res  # nothing identified, nothing written
    run = res["run"]
    summary = json.loads(Path(run["summary"]).read_text())
    assert summary["exit_code"] == code and cause in summary["trip_cause"]
    (rows,) = LogReader(run["log"]).read_ticks("/rig")
    assert len(rows["tick"]) == summary["ticks"] > 0 and np.all(np.diff(rows["tick"]) == 1)
    tripped = rows["tripped"].astype(bool)
    assert tripped.any(), "the trip is in the log"
    k = int(np.argmax(tripped))
    after = slice(k, None)  # the safe command from the trip's own tick on
    assert not rows["enable"][after].any() and np.all(rows["u_s_ref_re"][after] == 0.0)
    assert np.all(rows["u_s_ref_im"][after] == 0.0) and np.all(rows["m_l_ref"][after] == 0.0)
    assert rig.read_bytes() == before and sorted(p.name for p in rig.parent.iterdir()) == [rig.name]
    assert err.count("TRIPPED") + err.count("INTERRUPTED") == 1
    return res


def test_torque_turns_the_shaft_mid_test(tmp_path: Path) -> None:
    """The DC load machine puts 3 N m on the shaft at t = 1 s (someone turns it, a brake lets go under
    load): the test trips within the few encoder counts it allows, at once."""
    rig = _rig_copy(tmp_path)
    before = rig.read_bytes()
    patch = """
        import dataclasses
        import bench.workflows.commission.identify as ident
        _scenario = ident.scenario
        def scenario(plan):
            return dataclasses.replace(_scenario(plan), load=lambda t, w: 3.0 if t >= 1.0 else 0.0)
        ident.scenario = scenario
    """
    proc = _popen(_script(patch, _args(rig, tmp_path / "runs", *SHORT)))
    res = _ended_safely(proc, rig, before, 1, "shaft moved")
    assert 1.0 < res["run"]["trip_time"] < 1.05  # 4 counts at 240 rad/s^2: about 9 ms
    # and the log of a tripped test is no identification log: one line, exit 2
    p = subprocess.run([sys.executable, "-m", "bench", "identify", "--from-log", res["run"]["log"], "--out",
                        str(tmp_path / "refit")], cwd=ROOT, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "tripped at t = 1.0" in p.stderr, p.stderr


def test_failed_switch_over_current(tmp_path: Path) -> None:
    """From t = 1 s a failed switch adds 200 V along phase a (more than the current controller's u_max can
    oppose): the current rises by ~3 A a tick and the test trips on the current it did not ask for."""
    rig = _rig_copy(tmp_path)
    before = rig.read_bytes()
    patch = """
        from mock_hw.inverter import Inverter
        _latch = Inverter.latch
        n = [0]
        def latch(self, i_s=0j):
            n[0] += 1
            u = _latch(self, i_s)
            return u + 200.0 if n[0] > 3000 and self.on else u
        Inverter.latch = latch
    """
    proc = _popen(_script(patch, _args(rig, tmp_path / "runs", *SHORT)))
    res = _ended_safely(proc, rig, before, 1, "above the test's limit")
    assert 1.0 < res["run"]["trip_time"] < 1.01


def test_voltage_headroom(tmp_path: Path) -> None:
    """u_max = 10 V cannot drive 4 A through 5 ohm: a trip within a few ticks of the limit, one line."""
    rig = _rig_copy(tmp_path)
    before = rig.read_bytes()
    proc = _popen([sys.executable, "-m", "bench", *_args(rig, tmp_path / "runs", *SHORT, "-p", "u_max=10")])
    res = _ended_safely(proc, rig, before, 1, "voltage headroom exceeded")
    assert res["run"]["trip_time"] < 0.2


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_mid_test(tmp_path: Path, sig: int, code: int) -> None:
    rig = _rig_copy(tmp_path)
    before = rig.read_bytes()
    out = tmp_path / "runs"
    proc = _popen([sys.executable, "-m", "bench", *_args(rig, out, *LONG)])
    _ticking(out, proc)
    time.sleep(0.5)
    proc.send_signal(sig)
    res = _ended_safely(proc, rig, before, code, "interrupted")
    assert 0 < res["run"]["trip_time"] < 40  # inside the loop


def test_writer_stall(tmp_path: Path) -> None:
    """The log writer stopped (SIGSTOP) with a ring of 0.05 s: the loop, which in lockstep waits at most
    5 s for room, declares the writer stalled and trips; the writer resumes and the log is complete."""
    rig = _rig_copy(tmp_path)
    before = rig.read_bytes()
    out = tmp_path / "runs"
    proc = _popen([sys.executable, "-m", "bench", *_args(rig, out, *LONG, "--log-buffer", "0.05")])
    _ticking(out, proc)
    pid = writer_pid(proc.pid, timeout=30.0)
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(7.0)
    finally:
        os.kill(pid, signal.SIGCONT)
    _ended_safely(proc, rig, before, 1, "log")


def test_warming_motor_is_refused(tmp_path: Path) -> None:
    """rigs/mock-warm.toml (thermal time compressed 100x): R_s rises by a few % during the test. The fit
    runs and is printed, but the result is refused (exit 1, one line), and --write writes nothing."""
    rig = _rig_copy(tmp_path, "mock-warm")
    before = rig.read_bytes()
    p = subprocess.run([sys.executable, "-m", "bench", *_args(rig, tmp_path / "runs")], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)  # fmt: skip
    assert p.returncode == 1, p.stderr
    res = json.loads(p.stdout)
    assert res["warming"]["dR_s_rel"] > 0.01 and res["written"] is None
    refused = [line for line in p.stderr.splitlines() if line.startswith("bench: REFUSED:")]
    assert len(refused) == len(res["refused"]) >= 1 and "warming" in refused[-1]
    assert "inverse_gamma" in res  # the fit itself is there to read
    assert rig.read_bytes() == before and sorted(x.name for x in rig.parent.iterdir()) == [rig.name]


def test_supervisor_counts_no_rotation_in_a_chattering_vector() -> None:
    """The encoder-stuck check at standstill: a voltage vector that flips along one axis, or jumps between
    the hard-sign dead-time patterns 120 degrees apart (the current loop chattering around zero current, as
    the standstill test did on a 3 us / 2 V inverter), is no rotating field and does not trip; a field the
    drive turns (100 rad/s) with a frozen counter still does, after enc_stuck_time."""
    import cmath
    import math

    from bench.hal import Measurement, phase_values
    from bench.core.supervisor import Limits, Supervisor

    T = 1.0 / 3000.0

    def run(u_of_k: object) -> str | None:
        sup = Supervisor(Limits(), 4096, 1 << 16, 2, T)
        sup.enable_cmd = True  # the loop commands the drive on, as in a test
        for k in range(int(0.5 / T)):
            ua, ub, uc = phase_values(u_of_k(k))  # type: ignore[operator]
            ia, ib, ic = phase_values(2.0 + 0j)
            m = Measurement(k * T, ia, ib, ic, ua, ub, uc, 7, -1, 560.0, True, False, (0, 0, 0), (0, 0, 0))
            if sup.check_measurement(m):
                return sup.cause
        return None

    assert run(lambda k: 20.0 * (-1) ** k) is None  # flips along alpha
    assert run(lambda k: 20.0 * cmath.exp(-2j * math.pi / 3 * k)) is None  # 120-degree jumps, a "1 kHz field"
    cause = run(lambda k: 20.0 * cmath.exp(1j * 100.0 * k * T))
    assert cause is not None and cause.startswith("encoder stuck") and "0.200 s" in cause
