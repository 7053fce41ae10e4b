"""CAN frames over a loopback TCP stream: a python-can bus for emulated rigs across processes.

python-can's ``virtual`` bus only works inside one process and vcan needs a kernel module that
many machines lack. ``interface = "tcp"`` with ``channel = "127.0.0.1:PORT"`` connects the host's
drivers to `bench emulate` in another process; the emulator serves the port
(mock_hw.emulators.links.TcpCanServerBus). It is a transport for emulation only, not a product:
no arbitration or error frames, but ordered delivery, which is all lockstep needs.

The records are `bench.wire.tcpcan`'s.
"""

from __future__ import annotations

import select
import socket
import time
from typing import Any

import can

from bench.wire.tcpcan import REC, pack, parse_channel, unpack


class TcpCanBus(can.BusABC):
    """Client side: the host's end of a loopback TCP CAN link."""

    def __init__(self, channel: str, connect_timeout: float = 2.0, **kwargs: Any) -> None:
        self.channel_info = f"tcp CAN {channel}"
        addr = parse_channel(channel)
        try:
            self._sock = socket.create_connection(addr, timeout=connect_timeout)
        except OSError as exc:
            raise can.CanInitializationError(f"cannot connect to {channel}: {exc}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(None)  # blocking; recv only after select says readable
        self._buf = bytearray()
        super().__init__(channel=channel, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        try:
            self._sock.sendall(pack(msg))
        except OSError as exc:
            raise can.CanOperationError(f"tcp CAN send failed: {exc}") from None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        end = None if timeout is None else time.perf_counter() + timeout
        buf = self._buf
        while len(buf) < REC.size:
            left = None if end is None else max(0.0, end - time.perf_counter())
            if not select.select([self._sock], [], [], left)[0]:
                return None, False
            try:
                data = self._sock.recv(65536)
            except OSError as exc:
                raise can.CanOperationError(f"tcp CAN receive failed: {exc}") from None
            if not data:
                raise can.CanOperationError("tcp CAN peer closed the connection")
            buf += data
        rec = bytes(buf[: REC.size])
        del buf[: REC.size]
        return unpack(rec), False

    def shutdown(self) -> None:
        try:
            self._sock.close()
        finally:
            super().shutdown()
