"""python-can conventions: the loopback bus is a registered python-can interface, and `--can-log`
records every frame of a run with python-can's own logger."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can

from mock_hw.emulators import start_emulator
from mock_hw.emulators.testing import emulated_config, emulated_data, write_rig

ROOT = Path(__file__).resolve().parents[1]


def test_tcp_is_a_python_can_interface_and_sees_frames_of_other_nodes():
    import can.interfaces

    assert can.interfaces.BACKENDS["tcp"] == ("bench.drivers.tcpcan", "TcpCanBus")  # entry point can.interface
    emu = start_emulator(emulated_config("tcp"))
    try:
        channel = emu.host_config().hw["can"]["channel"]
        with can.Bus(interface="tcp", channel=channel) as node, can.Bus(interface="tcp", channel=channel) as watcher:
            node.send(can.Message(arbitration_id=0x080, data=[1], is_extended_id=False))  # a SYNC
            seen = [watcher.recv(2.0) for _ in range(2)]
        ids = sorted(m.arbitration_id for m in seen if m is not None)
        assert 0x080 in ids  # the other node's frame, relayed as on a real bus
    finally:
        emu.close()


def test_can_log_records_every_frame_of_a_run(tmp_path):
    rig = write_rig(tmp_path / "rig.toml", emulated_data("tcp"))
    log, can_log = tmp_path / "run.mcap", tmp_path / "bus.asc"
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(rig), "--duration", "0.3", "--no-progress",
                        "--log", str(log), "--can-log", str(can_log)], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    ticks = json.loads(p.stdout)["ticks"]
    counts: dict[int, int] = {}
    syncs: list[int] = []
    for m in can.ASCReader(str(can_log)):
        counts[m.arbitration_id] = counts.get(m.arbitration_id, 0) + 1
        if m.arbitration_id == 0x080:
            syncs.append(m.data[0])
    # one SYNC per tick, in order, none lost (with can.sync_early the next tick's SYNC follows the last
    # write, so one or two more may come after the last tick and at the safe command)
    assert syncs[:ticks] == [k & 0xFF for k in range(ticks)] and len(syncs) <= ticks + 2
    assert counts.get(0x100, 0) >= ticks - 1 and counts.get(0x180, 0) >= ticks // 3 - 1  # set-points, status


def test_can_log_needs_a_bus_another_process_can_watch(tmp_path):
    for rig, words in (("mock", "needs a rig with CAN drivers"),
                       (str(write_rig(tmp_path / "v.toml", emulated_data("virtual"))), "virtual")):  # fmt: skip
        p = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", rig, "--can-log", str(tmp_path / "x.blf")],
                           capture_output=True, text=True, cwd=ROOT, timeout=60)  # fmt: skip
        assert p.returncode == 2 and words in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
