"""CAN frames over a loopback TCP stream: a python-can bus for emulated rigs across processes.

python-can's ``virtual`` bus only works inside one process and vcan needs a kernel module that
many machines lack. ``interface = "tcp"`` with ``channel = "127.0.0.1:PORT"`` connects the host's
drivers to `bench emulate` in another process; the emulator serves the port
(mock_hw.emulators.links.TcpCanServerBus). It is a transport for emulation only, not a product:
no arbitration or error frames, but ordered delivery, which is all lockstep needs.

Record (16 bytes, little-endian): uint32 id (bit 31: extended), uint8 dlc, uint8 flags (bit0
remote), 2 pad bytes, 8 data bytes. `unpack` refuses (ValueError) a record `pack` cannot have made:
an 11-bit id above 0x7FF or a 29-bit one above 0x1FFFFFFF, other id bits, dlc > 8, unknown flags,
non-zero pad or data bytes beyond dlc. Random bytes pass all of that with a probability of about
6e-11 per record, so garbage on the port is recognised at its first record (and its sender dropped).
"""

from __future__ import annotations

import select
import socket
import struct
import time
from typing import Any

import can

REC = struct.Struct("<IBB2x8s")
EXT = 1 << 31


def pack(msg: can.Message) -> bytes:
    aid = msg.arbitration_id | (EXT if msg.is_extended_id else 0)
    return REC.pack(aid, msg.dlc, 1 if msg.is_remote_frame else 0, bytes(msg.data).ljust(8, b"\0"))


def unpack(rec: bytes) -> can.Message:
    aid, dlc, flags, data = REC.unpack(rec)
    ext = bool(aid & EXT)
    aid &= ~EXT
    if (aid > (0x1FFFFFFF if ext else 0x7FF) or dlc > 8 or flags & ~1 or rec[6:8] != b"\0\0"
            or any(data[dlc:])):  # fmt: skip
        raise ValueError(f"not a tcp CAN record: {rec.hex(' ')}")
    return can.Message(timestamp=time.time(), arbitration_id=aid, is_extended_id=ext,
                       is_remote_frame=bool(flags & 1), dlc=dlc, data=data[:dlc])  # fmt: skip


def parse_channel(channel: str) -> tuple[str, int]:
    host, _, port = str(channel).rpartition(":")
    if host not in ("127.0.0.1", "localhost"):
        raise can.CanInitializationError(f"tcp CAN is loopback only (127.0.0.1:PORT), got {channel!r}")
    return "127.0.0.1", int(port)


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
