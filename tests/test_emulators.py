"""Whole sessions: the real drivers against the emulators, in-process and across processes.

`bench run --rig <emulated>` runs the same controllers as the mock rig over CAN (loopback TCP or
python-can virtual), a socket:// serial link and Modbus TCP, all on 127.0.0.1; lockstep on SYNC
makes it deterministic and close to the in-process mock rig.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bench.daq import LogReader
from bench.runtime.loop import TIMING_FIELDS
from bench.runtime.session import RunOptions, run
from mock_hw.emulators.links import free_ports
from mock_hw.emulators.rig import RigEmulator
from mock_hw.emulators.testing import emulated_data, write_rig

ROOT = Path(__file__).resolve().parents[1]


def bench(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout)  # fmt: skip


def session(tmp_path: Path, rig: str, name: str, **kw) -> tuple[dict, LogReader]:
    log = tmp_path / f"{name}.mcap"
    summary, code = run(RunOptions(rig=rig, log=log, progress=False, **kw))
    assert code == 0, summary.get("trip_cause")
    return summary, LogReader(log)


def test_bench_run_emulated_cli_end_to_end(tmp_path):
    rig = write_rig(tmp_path / "emu.toml", emulated_data("tcp"))
    log = tmp_path / "run.mcap"
    p = bench("run", "--rig", str(rig), "--duration", "1.2", "--log", str(log))
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["ticks"] == 3600 and out["trip_cause"] is None and out["deadline_misses"] == 0
    r = LogReader(log)
    meas, truth = r.read("/rig"), r.read("/truth")
    assert not np.any(meas["status"])  # no stale, lost, CRC, ... on loopback
    assert r.metadata()["rig"]["can"]["interface"] == "tcp"
    t = meas["t"]
    assert abs(np.mean(truth["omega_r"][t > 1.1]) - 100.0) < 1.0  # demo: 100 rad/s reached and held
    assert np.all(meas["u_dc"] == 560.0)  # DC link from the drive's status frames


def test_emulated_runs_are_deterministic_and_match_the_mock_rig(tmp_path):
    rig = write_rig(tmp_path / "emu.toml", emulated_data("virtual"))
    s1, r1 = session(tmp_path, str(rig), "a", scenario="fig5.7", duration=0.8, seed=3)
    s2, r2 = session(tmp_path, str(rig), "b", scenario="fig5.7", duration=0.8, seed=3)
    for topic in ("/rig", "/truth"):
        a, b = r1.read(topic), r2.read(topic)
        assert all(np.array_equal(a[f], b[f]) for f in a if f not in TIMING_FIELDS), topic
    sm, rm = session(tmp_path, "mock", "m", scenario="fig5.7", duration=0.8, seed=3)
    te, tm = r1.read("/truth"), rm.read("/truth")
    # the same plant and noise; only the CAN set-point resolution (0.02 V, 1 mN m) differs
    assert np.max(np.abs(te["omega_r"] - tm["omega_r"])) < 0.5
    assert np.max(np.abs(te["i_s_re"] - tm["i_s_re"])) < 0.2
    assert s1["load_steps"]["count"] == sm["load_steps"]["count"] >= 1


def _auto_rig_on_free_ports(path: Path) -> tuple[Path, tuple[int, int, int]]:
    """An emulated (tcp CAN) rig file on three free loopback ports that attaches to a running `bench emulate`."""
    data = emulated_data("tcp")
    ports = p_can, p_ser, p_mb = free_ports(3)
    data["can"]["channel"] = f"127.0.0.1:{p_can}"
    data["serial"]["port"] = f"socket://127.0.0.1:{p_ser}"
    data["modbus"]["port"] = p_mb
    data["emulator"]["autostart"] = "auto"  # finds the running emulator
    return write_rig(path, data), ports


@pytest.mark.realtime
def test_bench_emulate_and_bench_run_in_two_processes(tmp_path):
    rig, (p_can, p_ser, p_mb) = _auto_rig_on_free_ports(tmp_path / "two.toml")
    emu = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(rig), "--duration", "60"],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        hello = json.loads(emu.stdout.readline())
        assert hello["serial"] == f"socket://127.0.0.1:{p_ser}" and hello["can"]["channel"] == f"127.0.0.1:{p_can}"
        for n in range(2):  # the emulator serves one session after the other, each from rest at t = 0
            p = bench("run", "--rig", str(rig), "--duration", "0.5", "--log", str(tmp_path / f"r{n}.mcap"))
            assert p.returncode == 0, p.stderr
            assert json.loads(p.stdout)["ticks"] == 1500
        r0, r1 = LogReader(tmp_path / "r0.mcap"), LogReader(tmp_path / "r1.mcap")
        assert "/truth" not in r0.topics()  # the plant lives in the other process
        assert np.array_equal(r0.read("/rig")["u_s_ref_re"], r1.read("/rig")["u_s_ref_re"])
    finally:
        emu.send_signal(signal.SIGINT)
        out, err = emu.communicate(timeout=20)
    assert emu.returncode == 0, err
    stats = json.loads(out.strip().splitlines()[-1])["stats"]
    # 2 x 1500 ticks, plus the SYNC that sync_early sends after the last tick of each session
    assert stats["syncs"] == stats["frames"] == 2 * 1501 and stats["sessions"] == 2


def test_calibrate_writes_offsets_back(tmp_path):
    data = emulated_data("tcp")
    data["mock"] = {"currents": {"offset": [0.01, -0.02, 0.005]}, "voltages": {"offset": [-0.03, 0.0, 0.02]}}
    rig = write_rig(tmp_path / "cal.toml", data)
    p = bench("calibrate", "--rig", str(rig), "--samples", "900")
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["written"] and res["samples"] == 900
    from bench.core.config import load

    fe = load(str(rig)).hw["frontend"]
    # noise 2 mV rms / sqrt(900) and one 4.9 mV LSB of quantisation
    assert fe["offset_i"] == pytest.approx((0.01, -0.02, 0.005), abs=1e-3)
    assert fe["offset_u"] == pytest.approx((-0.03, 0.0, 0.02), abs=1e-3)
    # with the offsets written, the drivers read zero current at standstill (before: 20 mA on phase a)
    from bench.hal import SAFE_COMMAND
    from bench.runtime.compose import build_rig

    cfg = load(str(rig))
    rig_ = build_rig(cfg, seed=5)
    with rig_:
        samples = []
        for k in range(600):
            samples.append(rig_.read(k * cfg.T_s).i_s)
            rig_.write(SAFE_COMMAND)
    assert abs(np.mean(samples)) < 2e-3


def test_calibrate_refuses_a_mock_rig():
    p = bench("calibrate", "--rig", "mock")
    assert p.returncode == 2 and p.stderr.startswith("bench: error: rig.driver: bench calibrate needs a driver rig")


def test_emulate_refuses_a_mock_rig():
    p = bench("emulate", "--rig", "mock", "--duration", "0.1")
    assert p.returncode == 2 and "rig.driver" in p.stderr and len(p.stderr.strip().splitlines()) == 1


@pytest.mark.realtime
def test_realtime_emulated_run_smoke(tmp_path):
    """Real-time mode works end to end (timing numbers are in docs/RESULTS.md section 2)."""
    data = emulated_data("virtual", limits={"stale_ticks": 1000, "burst_count": 1000}, can={"heartbeat_timeout": 5.0})
    rig = write_rig(tmp_path / "rt.toml", data)
    log = tmp_path / "rt.mcap"
    t0 = time.monotonic()
    summary, code = run(RunOptions(rig=str(rig), log=log, progress=False, realtime=True, duration=0.5))
    assert time.monotonic() - t0 >= 0.5
    assert summary["ticks"] > 300  # how many depends on the machine's load: no timing asserted here
    assert LogReader(log).summary()["topics"]["/rig"]["messages"] == summary["ticks"]


def _emulated_drive_running() -> RigEmulator:
    """An in-process emulated drive put in RUN over Modbus, one enabled set-point at tick 0, at tick 1."""
    import can

    from bench.wire.fc_profile import CTW_RESET, CTW_RUN, CTW_STOP
    from mock_hw.emulators.testing import emulated_config

    emu = RigEmulator(emulated_config("virtual", can={"heartbeat_timeout": 0.01},  # a 10 ms watchdog
                                      limits={"ride_through": 0.01}))
    ctw = emu.mb["control_word"]
    emu._write_register(ctw, CTW_STOP | CTW_RESET)
    emu._write_register(ctw, CTW_RUN)
    emu.step(0)
    data = emu.m_sp.encode({"U_ALPHA": 10.0, "U_BETA": 0.0, "ENABLE": 1, "COUNTER": 0, "OMEGA_U": 0})
    emu.handle(can.Message(arbitration_id=emu.m_sp.frame_id, data=data, is_extended_id=False))
    emu.step(1)  # the bridge takes the enable at the next sample
    assert emu.plant.inverter.status().enabled and not emu.plant.inverter.status().fault
    return emu


def test_drive_setpoint_watchdog_counts_sync_ticks():
    """Lockstep: no set-point for more than can.heartbeat_timeout (10 ms = 30 SYNC ticks) coasts the
    drive and latches a fault (docs/protocols.md, drive watchdog); 30 ticks are still tolerated."""
    emu = _emulated_drive_running()
    try:
        assert emu.sp_timeout == 30
        for k in range(2, 31):
            emu.step(k)
        assert not emu.plant.inverter.status().fault
        emu.step(31)
        st = emu.plant.inverter.status()
        assert st.fault and not st.enabled and emu.sp_timeout_flag
    finally:
        emu.close()


def test_drive_control_word_timeout_on_the_wall_clock():
    """Real time (`bench emulate`): emulator.control_timeout seconds without a set-point in RUN coast the
    drive, also with no SYNC at all (a host killed with SIGKILL); a fresh set-point resets the clock."""
    emu = _emulated_drive_running()
    try:
        emu._last_sp_wall = time.monotonic() - 0.5 * emu.control_timeout
        emu._control_watchdog()
        assert not emu.plant.inverter.status().fault
        emu._last_sp_wall = time.monotonic() - 1.01 * emu.control_timeout
        emu._control_watchdog()
        st = emu.plant.inverter.status()
        assert st.fault and not st.enabled and emu.stats["control_timeouts"] == 1
    finally:
        emu.close()


def test_a_backlog_after_the_emulators_own_stall_is_no_silence_of_the_host():
    """The wall-clock watchdog measures the host's silence. Frames that queued while the emulator itself was not
    scheduled (a busy machine) are handled before it looks, even with a SYNC at the head of the backlog; a bus
    that then stays quiet trips it."""
    import can

    emu = _emulated_drive_running()
    host = can.Bus(interface="virtual", channel=emu.cfg.hw["can"]["channel"])
    try:
        emu._last_sp_wall = time.monotonic() - 2.0 * emu.control_timeout  # the host's last set-point, handled late
        syncs, setpoints = emu.stats["syncs"], emu.stats["setpoints"]
        host.send(can.Message(arbitration_id=emu.m_sync.frame_id, data=bytes([2]), is_extended_id=False))
        sp = emu.m_sp.encode({"U_ALPHA": 10.0, "U_BETA": 0.0, "ENABLE": 1, "COUNTER": 1, "OMEGA_U": 0})
        host.send(can.Message(arbitration_id=emu.m_sp.frame_id, data=sp, is_extended_id=False))
        emu.serve_once(0.5, realtime=True)  # the SYNC
        emu.serve_once(0.5, realtime=True)  # the set-point
        assert (emu.stats["syncs"], emu.stats["setpoints"]) == (syncs + 1, setpoints + 1)
        assert not emu.plant.inverter.status().fault
        emu._last_sp_wall = time.monotonic() - 1.01 * emu.control_timeout  # ... and then nothing
        emu.serve_once(0.01, realtime=True)
        assert emu.plant.inverter.status().fault and emu.stats.get("control_timeouts") == 1
    finally:
        host.shutdown()
        emu.close()


@pytest.mark.realtime
def test_random_bytes_on_the_can_port_do_not_trip_a_real_time_run(tmp_path):
    """`bench emulate` and a real-time `bench run` in two processes while a third node floods the CAN
    port with random bytes: the emulator drops that node at its first record (docs/protocols.md), so
    the run ends normally. A loop stall of the loaded machine may still end it; never a drive fault."""
    import os
    import socket
    import threading

    rig, (p_can, p_ser, p_mb) = _auto_rig_on_free_ports(tmp_path / "garbage.toml")
    emu = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(rig), "--duration", "60"],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    stop = threading.Event()
    sent = [0, 0]  # connections, bytes

    def flood() -> None:
        while not stop.is_set():
            try:
                with socket.create_connection(("127.0.0.1", p_can), timeout=1) as s:
                    sent[0] += 1
                    while not stop.is_set():
                        s.sendall(os.urandom(4096))
                        sent[1] += 4096
                        time.sleep(0.005)
            except OSError:  # dropped by the emulator: come back with more
                time.sleep(0.005)

    try:
        json.loads(emu.stdout.readline())
        t = threading.Thread(target=flood, daemon=True)
        t.start()
        p = bench("run", "--rig", str(rig), "--realtime", "--duration", "2", "--log", str(tmp_path / "g.mcap"),
                  "--no-progress")  # fmt: skip
    finally:
        stop.set()
        emu.send_signal(signal.SIGINT)
        out, err = emu.communicate(timeout=20)
    cause = json.loads(p.stdout)["trip_cause"] if p.stdout else p.stderr
    assert p.returncode == 0 or "loop stall" in cause, cause  # the stall trip, or a trip just after one
    stats = json.loads(out.strip().splitlines()[-1])["stats"]
    assert sent[0] >= 5 and stats["garbage_clients"] >= 5 and stats["bad_frames"] == 0, (sent, stats)


@pytest.mark.realtime
def test_bench_run_attaches_only_to_an_emulator_of_its_own_user(tmp_path):
    """`bench emulate` keeps its secret in this user's runtime folder and answers challenges with it; a run
    of another user (another runtime folder: no token file, or one whose secret is not the emulator's), or
    a foreign program on the port, is refused in one line (more in tests/test_one_session.py)."""
    import os
    import socket

    rig, (p_can, p_ser, p_mb) = _auto_rig_on_free_ports(tmp_path / "mine.toml")
    mine, theirs = tmp_path / "rt-mine", tmp_path / "rt-theirs"

    def run_as(runtime: Path, name: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(rig), "--duration", "0.1", "--log",
                               str(tmp_path / f"{name}.mcap")], capture_output=True, text=True, cwd=tmp_path,
                              timeout=120, env={**os.environ, "IMBENCH_RUNTIME_DIR": str(runtime)})  # fmt: skip

    emu = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(rig), "--duration", "60"],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env={**os.environ, "IMBENCH_RUNTIME_DIR": str(mine)})  # fmt: skip
    try:
        json.loads(emu.stdout.readline())
        token = mine / f"emulate-{p_mb}.token"
        info = json.loads(token.read_text())
        assert mine.stat().st_mode & 0o777 == 0o700 and token.stat().st_mode & 0o777 == 0o600
        assert info["pid"] == emu.pid and len(bytes.fromhex(info["secret"])) == 32
        ok = run_as(mine, "mine")
        assert ok.returncode == 0, ok.stderr
        other = run_as(theirs, "theirs")  # the same emulator seen by another user: no token file of theirs
        lines = other.stderr.strip().splitlines()
        assert other.returncode == 2 and len(lines) == 1 and lines[0].startswith("bench: error: emulator.autostart: "
                                                                               "something answers"), other.stderr
        (theirs / token.name).write_text(json.dumps({**info, "secret": "5a" * 32}))  # a live pid, another secret
        wrong = run_as(theirs, "wrong")
        assert wrong.returncode == 2 and "does not prove it knows the session secret" in wrong.stderr, wrong.stderr
        assert not (tmp_path / "theirs.mcap").exists() and not (tmp_path / "wrong.mcap").exists()
    finally:
        emu.send_signal(signal.SIGINT)
        emu.communicate(timeout=20)
    assert not token.exists()  # withdrawn when the emulator ends
    with socket.create_server(("127.0.0.1", p_mb)) as srv:  # any other program on the port, a live token file
        token.write_text(json.dumps({"pid": os.getpid(), "start": None, "secret": "00" * 32}))
        foreign = run_as(mine, "foreign")
        srv.close()
    assert foreign.returncode == 2 and "emulator.autostart" in foreign.stderr, foreign.stderr


@pytest.mark.parametrize("which", ["can", "serial", "modbus"])
def test_a_port_another_program_holds_is_one_line_naming_it(tmp_path, which):
    """Any of the three ports held by an unrelated program: `bench emulate` and `bench run` (emulators
    in-process) exit 2 with one line saying the port is in use - not an AttributeError of the half-made
    emulator's close(), not an emulator that took the other program for its own Modbus server."""
    import socket

    data = emulated_data("tcp")
    ports = dict(zip(("can", "serial", "modbus"), free_ports(3)))
    data["can"]["channel"] = f"127.0.0.1:{ports['can']}"
    data["serial"]["port"] = f"socket://127.0.0.1:{ports['serial']}"
    data["modbus"]["port"] = ports["modbus"]
    rig = write_rig(tmp_path / "busy.toml", data)  # autostart = "always"
    with socket.create_server(("127.0.0.1", ports[which])):
        for cmd in (["emulate", "--rig", str(rig), "--duration", "1"],
                    ["run", "--rig", str(rig), "--duration", "0.1", "--log", str(tmp_path / "x.mcap")]):  # fmt: skip
            p = bench(*cmd)
            lines = p.stderr.strip().splitlines()
            assert p.returncode == 2 and len(lines) == 1, (which, cmd[0], p.stderr)
            assert lines[0].startswith("bench: error: emulator: cannot serve") and "in use" in lines[0], lines[0]
            assert f"127.0.0.1:{ports[which]}" in lines[0], lines[0]
    assert not (tmp_path / "x.mcap").exists()


def test_a_half_made_emulator_closes_what_it_opened():
    """RigEmulator.__init__ failing on its last port closes the ports it had opened (they are free again)."""
    import socket

    data = emulated_data("tcp")
    ports = free_ports(3)
    data["can"]["channel"], data["serial"]["port"] = f"127.0.0.1:{ports[0]}", f"socket://127.0.0.1:{ports[1]}"
    data["modbus"]["port"] = ports[2]
    from bench.core.config import parse

    cfg = parse(data)
    with socket.create_server(("127.0.0.1", ports[2])):
        with pytest.raises(OSError, match="in use"):
            RigEmulator(cfg)
    for port in ports[:2]:  # both could be bound again: nothing leaked
        with socket.create_server(("127.0.0.1", port)):
            pass
