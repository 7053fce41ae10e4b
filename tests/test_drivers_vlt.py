"""Inverter and load drivers, byte for byte (pymeasure style: (sent, answered) pairs).

CAN: the driver talks to a scripted device on python-can's virtual bus; every frame the driver
sends is compared with the expected bytes (DBC layout, docs/protocols.md), and the device answers
with literal bytes. Modbus: the driver talks to the emulator's pymodbus server on 127.0.0.1, and
pymodbus' packet trace records the exact ADUs both ways.
"""

from __future__ import annotations

import itertools

import can
import pytest

from bench.core.config import parse
from bench.drivers.canbus import CanLink
from bench.drivers.load import CanLoad, ModbusLoad
from bench.drivers.modbus import ModbusLink
from bench.wire.fc_profile import from_percent_word, to_percent_word
from bench.drivers.vlt import VltInverter
from bench.hal import ST_INV_STALE
from mock_hw.emulators import RigEmulator
from mock_hw.emulators.testing import emulated_data

T = 1.0 / 3000
_n = itertools.count()


def hw(**tables):
    data = emulated_data("virtual", **tables)
    data["limits"]["ride_through"] = min(0.02, data["can"]["heartbeat_timeout"])  # within the drive's watchdog
    data["can"]["channel"] = f"vlt-test-{next(_n)}"
    return parse(data).hw


class Device:
    """The other end of the bus: records what the driver sent, answers with literal frames."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)

    def expect(self, frame_id: int, data: str) -> None:
        msg = self.bus.recv(1.0)
        assert msg is not None, f"expected 0x{frame_id:03X} {data}, got nothing"
        assert (msg.arbitration_id, msg.data.hex(" ")) == (frame_id, data)

    def nothing(self) -> None:
        assert self.bus.recv(0.0) is None

    def answer(self, frame_id: int, data: str) -> None:
        self.bus.send(can.Message(arbitration_id=frame_id, data=bytes.fromhex(data), is_extended_id=False))

    def close(self) -> None:
        self.bus.shutdown()


@pytest.fixture
def can_rig():
    cfg = hw(can={"sync_early": False, "heartbeat_timeout": 0.01})  # a real drive's 10 ms
    link = CanLink(cfg["can"], T)
    inv = VltInverter(link, None, cfg["can"], cfg["modbus"], "can", U_max=400.0, u_dc_nominal=560.0, T_s=T)
    load = CanLoad(link, torque_limit=15.0)
    link.configure()
    inv.configure()
    dev = Device(cfg["can"]["channel"])
    yield link, inv, load, dev
    dev.close()
    link.close()


def test_setpoint_frames_byte_for_byte(can_rig):
    link, inv, load, dev = can_rig
    inv.enable()
    dev.nothing()  # enable alone only arms the flag; the set-point carries it
    inv.set_voltage(complex(10.0, -5.0), 620.0)
    dev.expect(0x100, "f4 01 06 ff 81 4d")  # u_alpha 500 x 0.02 V, u_beta -250, ENABLE, COUNTER 0, OMEGA_U 620 from bit 37
    inv.set_voltage(complex(-0.02, 0.04), -1.2)
    dev.expect(0x100, "ff ff 02 00 e3 ff")  # COUNTER 1 in bits 33-36, OMEGA_U -1 (whole rad/s)
    inv.set_voltage(1000.0 + 0j, float("nan"))  # clipped to U_max = 400 V; a frequency it cannot send: hold (0)
    dev.expect(0x100, "20 4e 00 00 05 00")
    inv.disable()
    dev.expect(0x100, "00 00 00 00 06 00")  # disabled: zero reference, ENABLE 0, sent at once
    link.acquire(0.0)  # a set-point went out this tick: SYNC only
    dev.expect(0x080, "00")
    link.acquire(T)  # nothing was sent in the last tick: keep-alive first, then SYNC
    dev.expect(0x100, "00 00 00 00 08 00")
    dev.expect(0x080, "01")
    for n in range(12):  # the 4-bit rolling counter wraps
        inv.set_voltage(0j)
        dev.expect(0x100, f"00 00 00 00 {2 * ((5 + n) % 16):02x} 00")


def test_sync_and_load_frames_byte_for_byte(can_rig):
    link, inv, load, dev = can_rig
    link.acquire(3 * T)
    dev.expect(0x100, "00 00 00 00 00 00")  # the inverter's keep-alive goes before every SYNC ...
    dev.expect(0x080, "03")  # SYNC, tick mod 256
    inv.set_voltage(0j)  # ... unless it sent a set-point in the tick
    load.set_torque(3.0)
    dev.expect(0x100, "00 00 00 00 02 00")
    dev.expect(0x110, "b8 0b 00")  # 3000 mN m, COUNTER 0 at bits 20..23
    dev.nothing()  # sync_early is off: the next SYNC waits for the next tick
    link.acquire(257 * T)
    dev.expect(0x080, "01")
    link.cfg = {**link.cfg, "sync_early": True}  # emulated rigs: SYNC right after the load, the last write
    inv.set_voltage(0j)
    load.set_torque(-100.0)  # clipped to -15 N m
    dev.expect(0x100, "00 00 00 00 04 00")
    dev.expect(0x110, "68 c5 10")
    dev.expect(0x080, "02")
    link.acquire(258 * T)  # already synced for this tick
    dev.nothing()
    assert load.m_L_ref == -15.0


def test_status_frame_decoded_and_heartbeat_watched(can_rig):
    link, inv, load, dev = can_rig
    inv.acquire(3 * T)
    dev.answer(0x180, "e0 15 01 03 00")  # 560.0 V, ENABLED, heartbeat = tick 3
    st = inv.status()
    assert (st.enabled, st.fault, st.u_dc) == (True, False, 560.0)
    assert not inv.status_bits & ST_INV_STALE
    dev.answer(0x180, "e0 15 02 06 00")  # TRIP
    inv.acquire(6 * T)
    assert inv.status().fault
    dev.answer(0x180, "10 27 04 09 00")  # 1000.0 V, SETPOINT_TIMEOUT (a fault too)
    inv.acquire(9 * T)
    st = inv.status()
    assert st.fault and st.u_dc == 1000.0
    dev.answer(0x180, "e0 15 09 0c 00")  # COUNTER_ERROR alone is a warning, counted
    inv.acquire(12 * T)
    assert not inv.status().fault and inv.stats["counter_errors"] == 1
    inv.status_wait = 0.0
    for k in range(13, 13 + 31):  # no more status frames: stale after heartbeat_timeout (30 ticks)
        inv.acquire(k * T)
        inv.status()
    assert inv.status_bits & ST_INV_STALE
    dev.answer(0x180, "e0 15 01 2d 00")  # heartbeat 45: back
    inv.acquire(45 * T)
    inv.status()
    assert not inv.status_bits & ST_INV_STALE


@pytest.mark.parametrize("frame, name", [
    ("e0 15 02 06 00", ""),  # TRIP, no fault code: the supervisor says the drive did not say which
    ("e0 15 06 06 00", "set-point watchdog"),  # TRIP + SETPOINT_TIMEOUT from a drive without FAULT codes
    ("e0 15 02 06 01", "set-point watchdog"),
    ("e0 15 06 06 02", "control-word timeout"),
    ("e0 15 02 06 03", "over-current"),
    ("e0 15 02 06 04", "DC-link voltage"),
    ("e0 15 02 06 07", "fault code 7"),  # not in the DBC's table: the number
    ("e0 15 01 06 03", ""),  # no TRIP: a code alone is no fault
])
def test_status_frame_names_the_drives_fault(can_rig, frame, name):
    link, inv, load, dev = can_rig
    inv.acquire(6 * T)
    dev.answer(0x180, frame)
    st = inv.status()
    assert (st.fault, st.fault_name) == (bool(name) or frame[7] != "1", name)


def test_the_emulated_drive_reports_which_fault_it_latched():
    """Set-point watchdog and control-word timeout go out as VLT_STATUS.FAULT codes 1 and 2."""
    cfg = parse(emulated_data("virtual"))
    emu = RigEmulator(cfg)
    dev = Device(cfg.hw["can"]["channel"])
    try:
        st = emu.db.get_message_by_name("VLT_STATUS")
        emu.bus_run, emu._last_sp = True, 0  # running on bus set-points, the last one at tick 0
        emu.step(emu.sp_timeout + 3)  # and none since: the watchdog trips
        msg = dev.bus.recv(1.0)
        s = st.decode(msg.data)
        assert (s["TRIP"], s["SETPOINT_TIMEOUT"], str(s["FAULT"])) == (1, 1, "set-point watchdog")
        emu._reset_state()
        emu.plant.inverter.reset_fault()
        emu.bus_run, emu._last_sp_wall = True, 0.0  # the wall-clock control-word timeout (bench emulate)
        emu._control_watchdog()
        emu.step(1)
        s = st.decode(dev.bus.recv(1.0).data)
        assert (s["TRIP"], str(s["FAULT"])) == (1, "control-word timeout")
    finally:
        dev.close()
        emu.close()


def test_percent_scaling():
    assert to_percent_word(400.0, 400.0) == 0x4000
    assert to_percent_word(-400.0, 400.0) == 0xC000  # two's complement
    assert to_percent_word(1e9, 400.0) == 0x7FFF  # saturates
    assert from_percent_word(0xC000, 400.0) == -400.0
    assert from_percent_word(0x2000, 15.0) == 7.5


# --- Modbus, byte for byte ---------------------------------------------------------------------
def mbap(tid: int, pdu: str, unit: int = 1) -> str:
    b = bytes.fromhex(pdu)
    return (tid.to_bytes(2, "big") + b"\x00\x00" + (len(b) + 1).to_bytes(2, "big") + bytes((unit,)) + b).hex(" ")


@pytest.fixture
def emulator():
    data = emulated_data("virtual")
    data["can"]["channel"] = f"vlt-test-{next(_n)}"
    emu = RigEmulator(parse(data))
    yield emu
    emu.close()


def test_modbus_configure_activate_deactivate_bytes(emulator):
    cfg = emulator.host_config().hw
    trace: list[tuple[bool, str]] = []

    def record(sending: bool, data: bytes) -> bytes:
        trace.append((sending, data.hex(" ")))
        return data

    link = CanLink(cfg["can"], T)
    mb = ModbusLink(cfg["modbus"], trace_packet=record)
    inv = VltInverter(link, mb, cfg["can"], cfg["modbus"], "can", U_max=400.0, u_dc_nominal=560.0, T_s=T)
    link.configure()
    try:
        inv.configure()
        inv.activate()
        inv.deactivate()
    finally:
        inv.close()
        link.close()
    expected = [
        # read status word 50200 (wire 50199 = 0xC417): control ready, drive ready, bus control
        (True, mbap(1, "03 c4 17 00 01")), (False, mbap(1, "03 02 02 03")),
        # read DC link, par. 16-30 (wire 16299 = 0x3FAB): 5600 x 0.1 V
        (True, mbap(2, "03 3f ab 00 01")), (False, mbap(2, "03 02 15 e0")),
        # control word 50000 (wire 0xC34F): STOP | RESET = 0x04BC, then RUN = 0x047C (FC06, echoed)
        (True, mbap(3, "06 c3 4f 04 bc")), (False, mbap(3, "06 c3 4f 04 bc")),
        (True, mbap(4, "06 c3 4f 04 7c")), (False, mbap(4, "06 c3 4f 04 7c")),
        # deactivate: STOP = 0x043C
        (True, mbap(5, "06 c3 4f 04 3c")), (False, mbap(5, "06 c3 4f 04 3c")),
    ]  # fmt: skip
    assert trace == expected
    assert emulator.bus_run is False and emulator._ctw == 0x043C


def test_modbus_fault_reset_and_load_module(emulator):
    cfg = emulator.host_config().hw
    mb = ModbusLink(cfg["modbus"])
    mb.connect()
    try:
        emulator.plant.inverter.inject_fault("test")
        assert mb.read(cfg["modbus"]["status_word"])[0] & 0x0008  # STW bit 3: trip
        link = CanLink(cfg["can"], T)
        inv = VltInverter(link, mb, cfg["can"], cfg["modbus"], "can", 400.0, 560.0, T)
        inv.reset_fault()
        assert not mb.read(cfg["modbus"]["status_word"])[0] & 0x0008
        load = ModbusLoad(mb, cfg["modbus"]["load_register"], torque_limit=15.0)
        load.set_torque(7.5)
        assert emulator.plant.load.m_L_ref == 7.5  # 0x2000 = 50 % of 15 N m
        assert mb.read(cfg["modbus"]["load_register"]) == [0x2000]
    finally:
        mb.close()
