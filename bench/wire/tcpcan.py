"""CAN frames as records on a loopback TCP stream: the codec of `bench.drivers.tcpcan.TcpCanBus` and of the
emulator's server (`mock_hw.emulators.links.TcpCanServerBus`).

Record (16 bytes, little-endian): uint32 id (bit 31: extended), uint8 dlc, uint8 flags (bit0
remote), 2 pad bytes, 8 data bytes. `unpack` refuses (ValueError) a record `pack` cannot have made:
an 11-bit id above 0x7FF or a 29-bit one above 0x1FFFFFFF, other id bits, dlc > 8, unknown flags,
non-zero pad or data bytes beyond dlc. Random bytes pass all of that with a probability of about
6e-11 per record, so garbage on the port is recognised at its first record (and its sender dropped).
"""

from __future__ import annotations

import struct
import time

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
