"""Modbus client for the drive's parameter channel and the analog-output module (pymodbus).

The registers and the FC profile's words: `bench.wire.fc_profile`.

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
