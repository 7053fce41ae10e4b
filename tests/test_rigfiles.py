"""Rig files for driver rigs: shipped files load, bad ones give one-line errors naming the field,
the transport budget refuses what a transport cannot carry, calibration write-back keeps the file."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from bench.core import config
from bench.errors import BadInput
from mock_hw.emulators.testing import emulated_data, write_rig

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["mock", "emulated", "lab-example"])
def test_shipped_rig_files_load(name):
    cfg = config.load(name)
    assert cfg.rate_hz == 3000
    if name != "mock":
        assert cfg.driver == "drivers" and cfg.hw["ports"]["inverter"] == "vlt"
        assert cfg.as_dict()["can"]["sync_id"] == 0x080


def test_defaults_are_filled_and_documented():
    data = {"rig": {"driver": "drivers"}}
    cfg = config.parse(data)
    for section, rules in config.SCHEMA.items():
        assert set(cfg.hw[section]) == set(rules)
    assert cfg.hw["modbus"]["control_word"] == 49999  # FC profile 50000, wire address - 1
    assert cfg.hw["frontend"]["offset_i"] == (0.0, 0.0, 0.0)
    assert cfg.limits.U_max == 400.0


@pytest.mark.parametrize(
    "tables, field, text",
    [
        ({"can": {"bitrate": 2_000_000}}, "can.bitrate", "must be an integer in 10000..1e+06, got 2000000"),
        ({"can": {"interface": 3}}, "can.interface", "must be a string"),
        ({"can": {"load_id": 0x100}}, "can.load_id", "already used by can.setpoint_id"),
        ({"can": {"sync_id": 0x800}}, "can.sync_id", "0..2047"),
        ({"can": {"speed": 1}}, "can.speed", "unknown field; allowed: interface"),
        ({"ports": {"load": "brake"}}, "ports.load", "must be one of 'load_can', 'load_modbus'"),
        ({"ports": {"currents": "lem"}}, "ports.currents", "must be one of 'frontend'"),
        ({"serial": {"timeout": -1}}, "serial.timeout", "must be a number in"),
        ({"modbus": {"transport": "udp"}}, "modbus.transport", "'tcp', 'rtu'"),
        ({"frontend": {"offset_i": [0.1, 0.2]}}, "frontend.offset_i", "list of 3 numbers"),
        ({"frontend": {"lines": 1024, "modulus": 1000}}, "frontend.modulus", "must be >= 4*lines = 4096"),
        ({"frontend": {"adc_bits": 24}}, "frontend.adc_bits", "8..16"),
        ({"limits": {"U_max": -5.0}}, "limits.U_max", "must be in [1, 1500]"),
        # denormals: > 0, yet zero to every equation; a positive quantity has a sane lower end
        ({"limits": {"max_stall": 5e-324}}, "limits.max_stall", "must be in [0.001, 10], got 5e-324"),
        ({"limits": {"u_dc_min": 5e-324}}, "limits.u_dc_min", "must be in [1, 1500], got 5e-324"),
        ({"motor": {"R_s": 5e-324}}, "motor.R_s", "must be in [0.001, 1000], got 5e-324"),
        ({"mock": {"motor": {"R_r": 5e-324}}}, "mock.motor.R_r", "in [0.001, 1000], got 5e-324"),
        ({"mock": {"load": {"tau": 5e-324}}}, "mock.load.tau", "in [1e-05, 10], got 5e-324"),
        ({"limits": {"stale_ticks": 2.5}}, "limits.stale_ticks", "must be an integer"),
        ({"emulator": {"autostart": "yes"}}, "emulator.autostart", "'auto', 'always', 'never'"),
        ({"emulator": {"faults": {"kind": "drop"}}}, "emulator.faults", "array of tables"),
    ],
)
def test_bad_driver_tables_name_the_field(tables, field, text):
    data = emulated_data("virtual", **tables)
    with pytest.raises(BadInput) as exc:
        config.parse(data)
    assert exc.value.field == field
    assert text in exc.value.problem
    assert "\n" not in str(exc.value)


def test_driver_tables_on_a_mock_rig_are_refused():
    with pytest.raises(BadInput, match=r"^can: only used with rig.driver = \"drivers\""):
        config.parse({"rig": {"driver": "mock"}, "can": {}})


def test_modbus_rtu_setpoints_refused_at_3khz_with_what_it_carries():
    data = emulated_data("virtual", inverter={"setpoints": "modbus"}, modbus={"transport": "rtu", "baudrate": 115200})
    with pytest.raises(BadInput) as exc:
        config.parse(data)
    assert exc.value.field == "rig.rate_hz"
    # FC16 (13 + 8 characters of 11 bits) + 2 x 1.75 ms silence = 5.5 ms -> 181 Hz
    assert str(exc.value) == ("rig.rate_hz: 3000 Hz is more than Modbus RTU at 115200 baud (set-point FC16 x2 "
                              "registers: 5.51 ms/tick) can carry: at most 181 Hz (see modbus.baudrate)")  # fmt: skip
    data["rig"]["rate_hz"] = 150
    assert config.parse(data).rate_hz == 150  # and what it can carry is accepted


def test_can_budget_refuses_a_slow_bus():
    data = emulated_data("virtual", can={"bitrate": 500_000})
    with pytest.raises(BadInput, match=r"CAN at 500000 bit/s, 90% bus load, 300 bits/tick worst case "
                                       r"\(SYNC \+ VLT_SETPOINT \+ LOAD_TORQUE \+ VLT_STATUS/3\) can carry: "
                                       r"at most 1500 Hz \(see can.bitrate\)"):  # fmt: skip
        config.parse(data)
    data["can"]["status_divider"] = 30  # fewer status frames do not make 3 kHz fit either
    with pytest.raises(BadInput, match="at most 1675 Hz"):
        config.parse(data)


def test_serial_budget():
    data = emulated_data("virtual", serial={"baudrate": 115200})
    with pytest.raises(BadInput, match=r"serial at 115200 baud, 28-byte frames can carry: at most 411 Hz"):
        config.parse(data)


def test_budget_numbers():
    assert config.can_frame_bits(8) == 135  # the textbook worst case of an 8-byte standard frame
    assert config.can_frame_bits(0) == 55
    assert config.modbus_rtu_transaction_s(8, 8, 9600) == pytest.approx(16 * 11 / 9600 + 2 * 3.5 * 11 / 9600)


def test_bad_fault_table_is_one_line(tmp_path):
    from bench.runtime.compose import build_rig

    cfg = config.parse(emulated_data("virtual", emulator={"faults": [{"kind": "explode", "at": 0.1}]}))
    with pytest.raises(BadInput, match=r"^emulator.faults\[0\].kind: must be one of drop, corrupt"):
        build_rig(cfg, 0)


def test_bad_rig_file_via_cli_is_one_line_exit_2(tmp_path):
    data = emulated_data("virtual", can={"bitrate": 125_000})
    p = write_rig(tmp_path / "slow.toml", data)
    r = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(p)], capture_output=True, text=True,
                       cwd=ROOT, timeout=60)  # fmt: skip
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench: error: rig.rate_hz: 3000 Hz is more than CAN at 125000")


@pytest.mark.realtime
def test_unreachable_device_is_one_line_exit_2(tmp_path):
    data = emulated_data("virtual", emulator={"autostart": "never"}, serial={"port": "socket://127.0.0.1:1"},
                         modbus={"port": 1})  # fmt: skip
    p = write_rig(tmp_path / "absent.toml", data)
    r = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(p), "--duration", "0.1", "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, timeout=60)  # fmt: skip
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench: error: modbus.port: cannot connect to 127.0.0.1:1")
    assert "Traceback" not in r.stderr
    assert not list(tmp_path.glob("*/run.mcap"))  # no run folder or empty log left behind


def test_write_offsets_keeps_comments_and_other_fields(tmp_path):
    p = tmp_path / "rig.toml"
    src = (ROOT / "rigs" / "lab-example.toml").read_text()
    p.write_text(src)
    config.write_offsets(p, (0.01, -0.02, 0.0), (0.1, 0.2, 0.3))
    text = p.read_text()
    assert text.count("offset_i =") == 1 and "# LEM LA 25-NP style, 1:1000" in text
    data = tomllib.loads(text)
    assert data["frontend"]["offset_i"] == [0.01, -0.02, 0.0] and data["frontend"]["offset_u"] == [0.1, 0.2, 0.3]
    assert data["frontend"]["burden"] == 500.0 and data["can"]["channel"] == "can0"
    q = tmp_path / "bare.toml"  # no [frontend] table yet
    q.write_text('[rig]\ndriver = "drivers"\n')
    config.write_offsets(q, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    assert config.load(str(q)).hw["frontend"]["offset_i"] == (1.0, 2.0, 3.0)


def test_write_offsets_on_a_multi_line_array_keeps_the_file_readable(tmp_path):
    """bench calibrate edited rig files line by line; a multi-line offset array crashed it (issue 14)."""
    p = tmp_path / "rig.toml"
    src = (ROOT / "rigs" / "lab-example.toml").read_text()
    src = src.replace("offset_u = [0.0, 0.0, 0.0]\n", 'offset_u = [\n  0.0,   # phase a\n  0.0,\n  0.0,\n]  # old\n', 1)
    p.write_text(src)
    assert tomllib.loads(src)["frontend"]["offset_u"] == [0.0, 0.0, 0.0]
    config.write_offsets(p, (0.01, -0.02, 0.0), (0.1, 0.2, 0.3))
    text = p.read_text()
    data = tomllib.loads(text)
    assert data["frontend"]["offset_u"] == [0.1, 0.2, 0.3] and text.count("offset_u") == 1
    assert "# LEM LA 25-NP style, 1:1000" in text and "# old" in text  # comments kept
    assert config.load(str(p)).hw["frontend"]["offset_i"] == (0.01, -0.02, 0.0)


def test_the_emulated_rigs_ports_lie_outside_the_ephemeral_range():
    """An outgoing connection of any program takes a port of ip_local_port_range; the emulators'
    fixed ports must not be among them (and neither the defaults a rig file falls back to)."""
    lo, hi = 32768, 60999  # Linux's default
    proc = Path("/proc/sys/net/ipv4/ip_local_port_range")
    if proc.exists():
        lo, hi = map(int, proc.read_text().split())
    cfg = config.load(str(ROOT / "rigs" / "emulated.toml"))
    ports = [int(cfg.hw["can"]["channel"].rsplit(":", 1)[1]), int(cfg.hw["serial"]["port"].rsplit(":", 1)[1]),
             cfg.hw["modbus"]["port"]]  # fmt: skip
    defaults = [config.SCHEMA["modbus"]["port"][1], int(config.SCHEMA["serial"]["port"][1].rsplit(":", 1)[1])]
    assert all(0 < p < lo or p > hi for p in ports + defaults), (ports, defaults, (lo, hi))
