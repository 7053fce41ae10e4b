"""Modbus client for the drive's parameter channel and the analog-output module (pymodbus).

Danfoss FC-profile registers (wire addresses, i.e. register number - 1; all configurable in the
rig file's ``[modbus]`` table):

=============  ======  =====================================================================
control word   49999   CTW, FC profile (bits below)
reference      50009   bus reference 1: u_alpha; 50010: u_beta (customised drive), 0x4000 = U_max
status word    50199   STW, FC profile (bits below)
actual value   50209   main actual value: applied |u_s|, 0x4000 = U_max
DC link        16299   parameter 16-30 DC-link voltage, 0.1 V
=============  ======  =====================================================================

References and actual values are signed 16-bit, two's complement, 0x4000 = 100 %.

Timeouts and reconnection: every request has the ``timeout`` of the rig file and pymodbus'
retries; a failed request raises `ModbusFailure` (the drivers turn it into ST_INV_COMM, or a
configure error). pymodbus reconnects a dropped TCP connection on the next request by itself.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from bench.errors import LinkError

# pymodbus logs connection errors itself; the drivers report them as one-line errors (LinkError,
# ST_INV_COMM), so its own messages would only duplicate them on stderr.
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

# control word (CTW) bits, FC profile
CTW_NO_DC_BRAKE = 1 << 2
CTW_NO_COAST = 1 << 3
CTW_NO_QSTOP = 1 << 4
CTW_NO_HOLD = 1 << 5
CTW_START = 1 << 6  # ramp start (0 = ramp stop)
CTW_RESET = 1 << 7  # fault reset on the rising edge
CTW_DATA_VALID = 1 << 10
CTW_STOP = CTW_NO_DC_BRAKE | CTW_NO_COAST | CTW_NO_QSTOP | CTW_NO_HOLD | CTW_DATA_VALID  # 0x043C
CTW_RUN = CTW_STOP | CTW_START  # 0x047C
CTW_COAST = CTW_STOP & ~CTW_NO_COAST  # 0x0434
# status word (STW) bits, FC profile
STW_CONTROL_READY = 1 << 0
STW_DRIVE_READY = 1 << 1
STW_TRIP = 1 << 3
STW_WARNING = 1 << 7
STW_BUS_CONTROL = 1 << 9
STW_RUNNING = 1 << 11

PERCENT_100 = 0x4000


def to_percent_word(x: float, full: float) -> int:
    """x/full as a 16-bit register, 0x4000 = 100 %, two's complement, saturating."""
    v = int(round(x / full * PERCENT_100))
    v = max(-0x8000, min(0x7FFF, v))
    return v & 0xFFFF


def from_percent_word(w: int, full: float) -> float:
    w &= 0xFFFF
    if w & 0x8000:
        w -= 0x10000
    return w * full / PERCENT_100


class ModbusFailure(RuntimeError):
    pass


class ModbusLink:
    """A pymodbus sync client (TCP or RTU) with the rig file's settings."""

    def __init__(self, cfg: dict[str, Any], trace_packet: Callable[[bool, bytes], bytes] | None = None) -> None:
        self.cfg = cfg
        self.unit = cfg["unit"]
        self._trace = trace_packet
        self.client: Any = None

    def connect(self) -> None:
        from pymodbus.client import ModbusSerialClient, ModbusTcpClient

        cfg = self.cfg
        kw: dict[str, Any] = {"timeout": cfg["timeout"], "retries": 1}
        if self._trace is not None:
            kw["trace_packet"] = self._trace
        if cfg["transport"] == "tcp":
            self.client = ModbusTcpClient(cfg["host"], port=cfg["port"], **kw)
        else:
            self.client = ModbusSerialClient(cfg["serial_port"], baudrate=cfg["baudrate"], parity="E", **kw)
        if not self.client.connect():
            where = f"{cfg['host']}:{cfg['port']}" if cfg["transport"] == "tcp" else cfg["serial_port"]
            raise LinkError("modbus.port" if cfg["transport"] == "tcp" else "modbus.serial_port",
                            f"cannot connect to {where} (is the drive, or `bench emulate`, there?)")

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None

    def read(self, address: int, count: int = 1) -> list[int]:
        if self.client is None:
            raise ModbusFailure("not connected")
        try:
            rr = self.client.read_holding_registers(address, count=count, device_id=self.unit)
        except Exception as exc:  # noqa: BLE001 - pymodbus raises several types
            raise ModbusFailure(f"read {address}: {exc}") from None
        if rr.isError():
            raise ModbusFailure(f"read {address}: {rr}")
        return list(rr.registers)

    def write(self, address: int, values: list[int]) -> None:
        if self.client is None:
            raise ModbusFailure("not connected")
        try:
            if len(values) == 1:
                rr = self.client.write_register(address, values[0], device_id=self.unit)
            else:
                rr = self.client.write_registers(address, values, device_id=self.unit)
        except Exception as exc:  # noqa: BLE001
            raise ModbusFailure(f"write {address}: {exc}") from None
        if rr.isError():
            raise ModbusFailure(f"write {address}: {rr}")
