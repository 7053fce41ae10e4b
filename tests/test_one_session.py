"""One session per rig, and an emulator that cannot be impersonated - on real processes.

* A rig's devices are locked by the session that opened them (bench.drivers.riglock): a second session,
  of any command that opens the rig, is refused in one line naming the holder's pid, exit 2, and the
  first runs on untouched; the lock goes with the holder's process, however it dies.
* `bench emulate` serves one controller: a second node that sends on its CAN link, or writes its drive
  registers over Modbus, is refused.
* `bench run` attaches only to an emulator that proves it knows the secret of this user's token file
  (challenge-response): a program serving everything it read from the real emulator is refused, and the
  token file a killed emulator left behind is removed.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bench.core.config import load as load_rig
from bench.daq import LogReader
from bench.runtime.loop import TIMING_FIELDS
from mock_hw.emulators.links import free_ports
from mock_hw.emulators.rig import _AUTH_END, CHALLENGE_REGISTER
from mock_hw.emulators.testing import emulated_data, write_rig

ROOT = Path(__file__).resolve().parents[1]


def _rig(tmp_path: Path, name: str = "rig.toml") -> tuple[Path, dict, dict[str, str]]:
    """An emulated (tcp CAN) rig file on free ports that attaches to a running `bench emulate`, its driver
    tables (defaults filled in), and the environment of a user whose runtime folder is under tmp_path."""
    data = emulated_data("tcp")
    p_can, p_ser, p_mb = free_ports(3)
    data["can"]["channel"] = f"127.0.0.1:{p_can}"
    data["serial"]["port"] = f"socket://127.0.0.1:{p_ser}"
    data["modbus"]["port"] = p_mb
    data["emulator"]["autostart"] = "auto"
    env = {**os.environ, "IMBENCH_RUNTIME_DIR": str(tmp_path / "runtime")}
    path = write_rig(tmp_path / name, data)
    return path, load_rig(str(path)).hw, env


def _bench(env: dict[str, str], *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout, env=env)  # fmt: skip


def _emulate(rig: Path, env: dict[str, str]) -> subprocess.Popen:
    emu = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(rig), "--duration", "120"],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip
    json.loads(emu.stdout.readline())  # serving
    return emu


def _stop(emu: subprocess.Popen) -> dict:
    emu.send_signal(signal.SIGINT)
    out, err = emu.communicate(timeout=30)
    assert emu.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])["stats"]


def _one_line(p: subprocess.CompletedProcess) -> str:
    """The refusal: exit 2, one line on stderr (after the stage lines of `bench commission`, "[  t s] ...")."""
    lines = [ln for ln in p.stderr.strip().splitlines() if not ln.startswith("[")]
    assert p.returncode == 2 and len(lines) == 1, (p.returncode, p.stderr)
    return lines[0]


def _wait_for_sync(sock: socket.socket, timeout: float = 60.0) -> None:
    """Read tcp CAN records until a SYNC relayed from the controlling host arrives."""
    from bench.wire.tcpcan import REC, unpack

    sock.settimeout(timeout)
    buf = b""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        data = sock.recv(4096)
        assert data, "the emulator closed a listening node"
        buf += data
        while len(buf) >= REC.size:
            msg, buf = unpack(buf[: REC.size]), buf[REC.size:]
            if msg.arbitration_id == 0x080:
                return
    raise AssertionError("no SYNC relayed")


@pytest.mark.realtime
def test_a_second_session_is_refused_and_the_first_runs_on_untouched(tmp_path):
    """`bench emulate`, run A in lockstep; while A ticks: run B is refused naming A's pid (exit 2, one line),
    a second CAN node that sends a SYNC is dropped, a second Modbus client's STOP|RESET is refused (busy).
    A ends normally with the log a run of its own gives (same seed, bit for bit)."""
    from pymodbus.client import ModbusTcpClient

    from bench.wire.tcpcan import pack

    import can

    rig, data, env = _rig(tmp_path)
    p_can = int(data["can"]["channel"].rpartition(":")[2])
    emu = _emulate(rig, env)
    try:
        a = subprocess.Popen([sys.executable, "-m", "bench", "run", "--rig", str(rig), "--scenario", "fig5.7",
                              "--duration", "8", "--seed", "4", "--log", str(tmp_path / "a.mcap"), "--no-progress"],
                             cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip
        with socket.create_connection(("127.0.0.1", p_can), timeout=5) as node:
            _wait_for_sync(node)  # A controls the drive and ticks
            # a node that sends on the bus while A controls it: dropped at its first frame
            node.sendall(pack(can.Message(arbitration_id=0x080, data=[0], is_extended_id=False)))
            node.settimeout(10)
            while node.recv(65536):  # what was relayed before the drop, then the close
                pass
        b = _bench(env, "run", "--rig", str(rig), "--realtime", "--duration", "8", "--log", str(tmp_path / "b.mcap"))
        line = _one_line(b)
        assert line.startswith("bench: error: can.channel: ") and "in use by another session" in line, line
        assert f"pid {a.pid} " in line and "bench run --rig" in line and "since 20" in line, line
        assert a.poll() is None, "A ended before B was refused: the test did not test anything"
        rogue = ModbusTcpClient("127.0.0.1", port=data["modbus"]["port"], timeout=2)
        assert rogue.connect()
        try:
            status = rogue.read_holding_registers(data["modbus"]["status_word"], count=1, device_id=1)
            assert not status.isError()  # reading is allowed
            rr = rogue.write_register(data["modbus"]["control_word"], 0x04BC, device_id=1)  # STOP | fault reset
            assert rr.isError() and rr.exception_code == 6, rr  # device busy: A holds the drive
        finally:
            rogue.close()
        out, err = a.communicate(timeout=180)
        assert a.returncode == 0, err
        assert json.loads(out)["trip_cause"] is None
        assert not (tmp_path / "b.mcap").exists()
        c = _bench(env, "run", "--rig", str(rig), "--scenario", "fig5.7", "--duration", "8", "--seed", "4", "--log",
                   str(tmp_path / "c.mcap"), "--no-progress")  # fmt: skip
        assert c.returncode == 0, c.stderr
    finally:
        stats = _stop(emu)
    assert stats["refused_controllers"] == 1 and stats["refused_writes"] == 1 and stats["sessions"] == 2, stats
    ra, rc = LogReader(tmp_path / "a.mcap").read("/rig"), LogReader(tmp_path / "c.mcap").read("/rig")
    assert all(np.array_equal(ra[f], rc[f]) for f in ra if f not in TIMING_FIELDS)


HOLD = """
import sys, time
from bench.core.config import load
from bench.drivers.riglock import RigLock
cfg = load(sys.argv[1])
RigLock(cfg.hw, cfg.name).acquire()
print("held", flush=True)
time.sleep(120)
"""


def test_every_command_that_opens_the_rig_is_refused_while_another_holds_it(tmp_path):
    """run, calibrate, identify, tune, collect on a held driver rig: one line naming the holder, exit 2,
    nothing written; once the holder is killed (SIGKILL: the kernel drops its lock) the rig is free."""
    rig, data, env = _rig(tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(rig)], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                              env=env)  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        folder = tmp_path / "runtime"
        assert folder.stat().st_mode & 0o777 == 0o700
        assert {p.stat().st_mode & 0o777 for p in folder.iterdir()} == {0o600} and len(list(folder.iterdir())) == 3
        out = tmp_path / "out"
        r = ["--rig", str(rig)]
        for cmd in (["run", *r, "--duration", "0.1", "--log", str(out / "r.mcap")],
                    ["calibrate", *r, "--dry-run"],
                    ["identify", *r, "--out", str(out / "id")],
                    ["commission", *r, "--dry-run", "--out", str(out / "com")],
                    ["tune", "speed", *r, "--out", str(out / "tune")],
                    ["collect", "narx", *r, "--samples", "1000", "--out", str(out / "narx.mcap")]):  # fmt: skip
            line = _one_line(_bench(env, *cmd))
            assert "in use by another session: pid " + str(holder.pid) in line, (cmd, line)
        assert not out.exists() or not any(out.rglob("*.mcap")), list(out.rglob("*"))
    finally:
        holder.kill()
        holder.wait()
    ok = _bench(env, "run", "--rig", str(rig), "--duration", "0.1", "--log", str(tmp_path / "free.mcap"))
    assert ok.returncode == 0, ok.stderr  # (its in-process emulators: no `bench emulate` runs)


FAKE = """
import json, sys, time, asyncio
from mock_hw.emulators.links import ModbusTcpEndpoint
port, stolen = int(sys.argv[1]), {int(k): v for k, v in json.loads(sys.argv[2]).items()}
async def action(fc, start, address, count, registers, values):
    for a, v in stolen.items():  # serve what was read from the real emulator, whatever was written
        if 0 <= a - start < len(registers):
            registers[a - start] = v
ModbusTcpEndpoint(port, 1, list(stolen), action)
print("serving", flush=True)
time.sleep(120)
"""


@pytest.mark.realtime
def test_an_emulator_that_replays_what_it_read_is_refused(tmp_path):
    """A client reads every register the real emulator serves (and asks it a challenge of its own); the
    emulator is killed (SIGKILL: its token file stays); a fake serving what was read is refused: first for the
    stale token file (removed), then - the file put back naming a live pid - because it cannot answer a new
    challenge. Nothing the emulator serves holds its secret."""
    from pymodbus.client import ModbusTcpClient

    rig, data, env = _rig(tmp_path)
    mb = data["modbus"]
    emu = _emulate(rig, env)
    token = tmp_path / "runtime" / f"emulate-{mb['port']}.token"
    try:
        assert token.stat().st_mode & 0o777 == 0o600
        secret = bytes.fromhex(json.loads(token.read_text())["secret"])
        spy = ModbusTcpClient("127.0.0.1", port=mb["port"], timeout=2)
        assert spy.connect()
        assert not spy.write_registers(CHALLENGE_REGISTER, list(range(1, 9)), device_id=1).isError()
        served = [mb["control_word"], mb["reference"], mb["reference"] + 1, mb["status_word"], mb["actual_value"],
                  mb["dc_link"], mb["load_register"], *range(CHALLENGE_REGISTER, _AUTH_END)]  # fmt: skip
        stolen = {}
        for a in served:
            rr = spy.read_holding_registers(a, count=1, device_id=1)
            assert not rr.isError(), (a, rr)
            stolen[a] = rr.registers[0]
        spy.close()
        dump = b"".join(v.to_bytes(2, "big") for v in stolen.values())
        assert any(stolen[a] for a in range(CHALLENGE_REGISTER + 8, _AUTH_END))  # it did answer the spy's nonce
        assert all(dump.find(secret[i:i + 4]) < 0 for i in range(0, len(secret) - 3))  # no 4 bytes of the secret
    finally:
        emu.kill()
        emu.wait()
    kept = token.read_text()
    fake = subprocess.Popen([sys.executable, "-c", FAKE, str(mb["port"]), json.dumps(stolen)], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True, env=env)  # fmt: skip
    try:
        assert fake.stdout.readline().strip() == "serving"
        run = ["run", "--rig", str(rig), "--duration", "0.1", "--log", str(tmp_path / "x.mcap")]
        line = _one_line(_bench(env, *run))
        assert line.startswith("bench: error: emulator.autostart: something answers") and "is gone" in line, line
        assert not token.exists()  # the stale file went
        info = json.loads(kept)  # the same secret, with a live pid (as if the pid were taken again)
        token.write_text(json.dumps({**info, "pid": fake.pid, "start": None}))
        line = _one_line(_bench(env, *run))
        assert "does not prove it knows the session secret" in line, line
        assert not (tmp_path / "x.mcap").exists()
    finally:
        fake.kill()
        fake.wait()


@pytest.mark.realtime
def test_a_token_file_left_by_a_killed_emulator_is_removed_at_the_next_start(tmp_path):
    rig, data, env = _rig(tmp_path)
    folder = tmp_path / "runtime"
    first = _emulate(rig, env)
    first.kill()
    first.wait()
    other = folder / "emulate-1.token"  # another port's, of a process that is gone too
    other.write_text(json.dumps({"pid": first.pid, "start": None, "secret": "00" * 32}))
    token = folder / f"emulate-{data['modbus']['port']}.token"
    assert json.loads(token.read_text())["pid"] == first.pid  # left behind
    second = _emulate(rig, env)
    try:
        assert json.loads(token.read_text())["pid"] == second.pid and not other.exists()
        p = _bench(env, "run", "--rig", str(rig), "--duration", "0.2", "--log", str(tmp_path / "r.mcap"))
        assert p.returncode == 0, p.stderr
    finally:
        stats = _stop(second)
    assert stats["sessions"] == 1 and not token.exists()


@pytest.mark.realtime
def test_a_lockstep_run_that_pauses_does_not_trip_the_emulated_drives_wall_clock_watchdog(tmp_path):
    """`bench emulate` keeps a drive's wall-clock control-word timeout (0.1 s). A lockstep run tells it its clock
    (its SYNC ticks): stopped for 0.5 s of wall time mid-run (SIGSTOP, as a loaded machine may), it goes on and
    ends normally. The same pause in a run that says it is on the wall clock trips the drive, as it must."""
    import time

    rig, data, env = _rig(tmp_path)
    emu = _emulate(rig, env)
    try:
        codes = {}
        for mode in ("--lockstep", "--realtime"):
            out = tmp_path / mode.strip("-")
            run = subprocess.Popen([sys.executable, "-m", "bench", "run", "--rig", str(rig), mode, "--scenario",
                                    "fig5.7", "--duration", "6", "--out", str(out), "--no-progress"], cwd=ROOT,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip
            deadline = time.monotonic() + 60
            while not list(out.glob("*/run.mcap")) and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(1.0)  # ticking
            run.send_signal(signal.SIGSTOP)
            time.sleep(0.5)
            run.send_signal(signal.SIGCONT)
            _, err = run.communicate(timeout=120)
            summary = json.loads(next(out.glob("*/summary.json")).read_text())
            codes[mode] = (run.returncode, summary["trip_cause"] or "")
        assert codes["--lockstep"] == (0, ""), codes
        code, cause = codes["--realtime"]
        assert code == 1 and ("control-word timeout" in cause or cause.startswith("loop stall")), codes
    finally:
        _stop(emu)
