"""A block of ticks into an MCAP file at once: one tick's messages are one numpy record, a block one write.

mcap's ``Writer.add_message`` costs some 4 µs of Python per message (a Message object, five
``struct.pack`` calls, a message-index tuple, statistics): with three topics per tick that was about
nine tenths of the log writer's CPU per row. A tick's messages all have a fixed size (flat CDR), so
the MCAP Message records of a whole block of ticks are one numpy structured array (`RowLayout`):
opcode, record length, channel id, the CDR header and the padding come from a template; sequence,
log and publish time and the values are a few column assignments (runs of adjacent fields of one
type are assigned together). `BlockWriter.add_rows` hands the block to the writer's open chunk in one
write, keeps the message indexes and statistics ``add_message`` would keep, and closes a chunk after
the same message ``add_message`` would: the file is byte for byte the one written message by message
(tests/test_daq.py).

`BlockWriter` works inside mcap's ``Writer`` (its chunk builder and statistics, private to mcap 1.x).
Where an mcap release lays them out otherwise, ``blocks`` is False and `BlockWriter.add_rows` adds
message by message through the public ``add_message``: slower, never wrong.
"""

from __future__ import annotations

import struct
from typing import Any, Sequence

import numpy as np
from mcap.opcode import Opcode
from mcap.records import MessageIndex, Statistics
from mcap.writer import Writer

from .schema import Topic

__all__ = ["BlockWriter", "RowLayout"]

_MSG_HEAD = 1 + 8 + 2 + 4 + 8 + 8  # opcode, record length, channel id, sequence, log time, publish time


class RowLayout:
    """The MCAP Message records of one tick (one per topic, in topic order) as a numpy structured dtype.

    ``pack(t_ns, vals, first_seq)`` -> the records of ``len(t_ns)`` ticks: ``vals`` is ``(n, ncols)``
    float64 (the ring's rows), cast to each field's type as numpy casts (integers truncate, nonzero is
    True); sequence = row index (uint32, wraps).
    """

    def __init__(self, topics: Sequence[Topic], channel_ids: Sequence[int]) -> None:
        if len(topics) != len(channel_ids):
            raise ValueError("one channel id per topic")
        names: list[str] = []
        formats: list[Any] = []
        offsets: list[int] = []
        template = bytearray()
        self.runs: list[tuple[str, int, int]] = []  # (field, first column, end column) of value runs
        self.msg_slices: list[tuple[int, int]] = []  # per topic: its CDR message's bytes within a row
        self.rec_offsets: list[int] = []
        self.rec_sizes: list[int] = []
        self.channel_ids = [int(c) for c in channel_ids]
        base = col = 0
        for j, (tp, cid) in enumerate(zip(topics, self.channel_ids)):
            cdr = tp.dtype()
            size = cdr.itemsize
            data0 = base + _MSG_HEAD
            template += struct.pack("<BQH", Opcode.MESSAGE, _MSG_HEAD - 9 + size, cid) + bytes(20)
            template += bytes(size)  # the CDR message: zero padding between its fields
            template[data0 : data0 + 4] = b"\x00\x01\x00\x00"  # CDR_LE encapsulation header
            for name, off, fmt in (("seq", 11, "<u4"), ("time", 15, ("<u8", (2,)))):  # log time, publish time
                names.append(f"{name}{j}")
                formats.append(fmt)
                offsets.append(base + off)
            run: list[Any] = []  # [type, CDR offset, first column, length]
            for fname, _ in tp.fields:
                ftype, off = cdr.fields[fname][:2]
                if run and run[0] == ftype and off == run[1] + run[3] * ftype.itemsize:
                    run[3] += 1
                else:
                    if run:
                        self._add_run(names, formats, offsets, data0, j, run)
                    run = [ftype, off, col, 1]
                col += 1
            self._add_run(names, formats, offsets, data0, j, run)
            self.msg_slices.append((data0, data0 + size))
            self.rec_offsets.append(base)
            self.rec_sizes.append(_MSG_HEAD + size)
            base += _MSG_HEAD + size
        self.ncols = col
        self.row_bytes = base
        self.dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": base})
        self.template = np.frombuffer(bytes(template), np.uint8)
        # per message of a row: where its record starts and ends within the row
        self._starts = np.asarray(self.rec_offsets, np.int64)
        self._ends = self._starts + np.asarray(self.rec_sizes, np.int64)

    def _add_run(self, names: list[str], formats: list[Any], offsets: list[int], data0: int, j: int,
                 run: list[Any]) -> None:  # fmt: skip
        ftype, off, c0, k = run
        names.append(f"v{j}_{len(self.runs)}")
        formats.append(ftype if k == 1 else (ftype, (k,)))
        offsets.append(data0 + off)
        self.runs.append((names[-1], c0, c0 + k))

    def pack(self, t_ns: np.ndarray, vals: np.ndarray, first_seq: int) -> np.ndarray:
        """``(n,)`` records of this layout; ``.view(np.uint8)`` is the bytes of their messages, tick-major."""
        n = len(t_ns)
        rows = np.tile(self.template, n).view(self.dtype)
        seq = np.arange(first_seq, first_seq + n, dtype=np.int64).astype(np.uint32)  # wraps at 2**32
        t2 = np.asarray(t_ns)[:, None]
        for j in range(len(self.channel_ids)):
            rows[f"seq{j}"] = seq
            rows[f"time{j}"] = t2
        for name, c0, c1 in self.runs:
            rows[name] = vals[:, c0] if c1 == c0 + 1 else vals[:, c0:c1]
        return rows

    def message(self, rows: np.ndarray, k: int, j: int) -> bytes:
        """The CDR message of topic ``j`` in tick ``k`` of ``rows`` (from `pack`)."""
        a, b = self.msg_slices[j]
        return rows[k : k + 1].view(np.uint8)[a:b].tobytes()


class _BlockIndex(MessageIndex):
    """A chunk's message index of one channel, held as arrays of (log time, offset) pairs."""

    def __init__(self, channel_id: int) -> None:
        super().__init__(channel_id=channel_id, records=[])
        self.parts: list[np.ndarray] = []

    def write(self, stream: Any) -> None:
        parts = self.parts + ([np.array(self.records, np.uint64).reshape(-1, 2)] if self.records else [])
        body = np.concatenate(parts).astype("<u8") if parts else np.empty((0, 2), "<u8")
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(body.size * 8)
        stream.write(body.tobytes())
        stream.finish_record()


class BlockWriter(Writer):
    """mcap's ``Writer`` plus `add_rows`: many fixed-size messages in one call (module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        cb = getattr(self, "_Writer__chunk_builder", None)
        self.blocks = (
            cb is not None
            and isinstance(getattr(self, "_Writer__statistics", None), Statistics)
            and isinstance(getattr(self, "_Writer__chunk_size", None), int)
            and callable(getattr(self, "_Writer__maybe_finalize_chunk", None))
            and all(hasattr(cb, a) for a in ("record_writer", "message_indices", "num_messages",
                                             "message_start_time", "message_end_time"))
            and callable(getattr(cb.record_writer, "write", None))
        )  # fmt: skip

    def add_rows(self, layout: RowLayout, rows: np.ndarray) -> None:
        """The messages of ``rows`` (`RowLayout.pack`), tick-major, as ``add_message`` one by one would add them."""
        n, m = len(rows), len(layout.channel_ids)
        if n == 0:
            return
        if not self.blocks:
            t = rows["time0"][:, 0].tolist()
            seq = rows["seq0"].tolist()
            for k in range(n):
                for j, cid in enumerate(layout.channel_ids):
                    self.add_message(cid, t[k], layout.message(rows, k, j), t[k], seq[k])
            return
        data = rows.view(np.uint8)
        t = rows["time0"][:, 0]
        lo, hi = int(t.min()), int(t.max())
        st: Statistics = self._Writer__statistics  # type: ignore[attr-defined]
        st.message_start_time = lo if st.message_count == 0 else min(st.message_start_time, lo)
        st.message_end_time = max(st.message_end_time, hi)
        st.message_count += n * m
        for cid in layout.channel_ids:
            st.channel_message_counts[cid] += n
        # every message of the block, in order: where its record starts and ends in ``data``
        row0 = np.arange(n, dtype=np.int64)[:, None] * layout.row_bytes
        starts = (row0 + layout._starts).ravel()
        ends = (row0 + layout._ends).ravel()
        limit: int = self._Writer__chunk_size  # type: ignore[attr-defined]
        total, pos = n * m, 0
        while pos < total:
            cb = self._Writer__chunk_builder  # type: ignore[attr-defined]
            count0 = cb.count
            # add_message closes the chunk after the first message that takes it past the chunk size
            over = int(np.searchsorted(ends, limit - count0 + starts[pos], side="right"))
            last = min(over, total - 1)
            a, b = int(starts[pos]), int(ends[last])
            cb.record_writer.write(data[a:b].data)
            for i in range(pos, min(pos + m, last + 1)):  # channels in order of their first message
                sl = slice(i, last + 1, m)  # this channel's messages: every m-th, one per tick
                ofs = starts[sl]
                pairs = np.empty((len(ofs), 2), np.uint64)
                pairs[:, 0] = t[i // m : i // m + len(ofs)]
                pairs[:, 1] = ofs + (count0 - a)
                cid = layout.channel_ids[i % m]
                ix = cb.message_indices.get(cid)
                if not isinstance(ix, _BlockIndex):
                    old = ix.records if ix is not None else []
                    ix = cb.message_indices[cid] = _BlockIndex(cid)
                    if old:
                        ix.parts.append(np.array(old, np.uint64).reshape(-1, 2))
                ix.parts.append(pairs)
            seg = t[pos // m : last // m + 1]
            lo_c, hi_c = int(seg.min()), int(seg.max())
            cb.message_start_time = lo_c if cb.num_messages == 0 else min(cb.message_start_time, lo_c)
            cb.message_end_time = max(cb.message_end_time, hi_c)
            cb.num_messages += last + 1 - pos
            if over <= last:
                self._Writer__maybe_finalize_chunk()  # type: ignore[attr-defined]
            pos = last + 1
