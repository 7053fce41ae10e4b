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

    `pack_ring` turns a block of ring rows (``int64`` t_ns, then ``ncols`` float64: `ring_dtype`) into
    the records in two structured assignments: every field of every message takes its ring column,
    cast to the field's type as numpy casts (integers truncate, nonzero is True), log and publish time
    take t_ns; the sequence numbers (row index, uint32, wraps) are the other. Opcode, record length,
    channel id, CDR header and padding come from a template.
    """

    def __init__(self, topics: Sequence[Topic], channel_ids: Sequence[int]) -> None:
        if len(topics) != len(channel_ids):
            raise ValueError("one channel id per topic")
        self.channel_ids = [int(c) for c in channel_ids]
        m = len(self.channel_ids)
        template = bytearray()
        src: list[tuple[str, int]] = []  # (type, offset in the ring row) of each assigned field, in order
        dst: list[tuple[Any, int]] = []  # (type, offset in the record row)
        self.msg_slices: list[tuple[int, int]] = []  # per topic: its CDR message's bytes within a row
        self.rec_offsets: list[int] = []
        self.rec_sizes: list[int] = []
        base = col = 0
        for tp, cid in zip(topics, self.channel_ids):
            cdr = tp.dtype()
            size = cdr.itemsize
            data0 = base + _MSG_HEAD
            template += struct.pack("<BQH", Opcode.MESSAGE, _MSG_HEAD - 9 + size, cid) + bytes(20)
            template += bytes(size)  # the CDR message: zero padding between its fields
            template[data0 : data0 + 4] = b"\x00\x01\x00\x00"  # CDR_LE encapsulation header
            src += [("<i8", 0), ("<i8", 0)]  # log time and publish time: the row's t_ns
            dst += [("<u8", base + 15), ("<u8", base + 23)]
            for fname, _ in tp.fields:
                ftype, off = cdr.fields[fname][:2]
                src.append(("<f8", 8 + 8 * col))
                dst.append((ftype, data0 + off))
                col += 1
            self.msg_slices.append((data0, data0 + size))
            self.rec_offsets.append(base)
            self.rec_sizes.append(_MSG_HEAD + size)
            base += _MSG_HEAD + size
        self.ncols = col
        self.row_bytes = base
        self.ring_dtype = np.dtype([("t", "<i8"), ("v", "<f8", (col,))])

        def fields(spec: list[tuple[Any, int]], itemsize: int) -> np.dtype:
            return np.dtype({"names": [f"f{i}" for i in range(len(spec))], "formats": [f for f, _ in spec],
                             "offsets": [o for _, o in spec], "itemsize": itemsize})  # fmt: skip

        self._src = fields(src, self.ring_dtype.itemsize)  # overlapping fields: t_ns read twice per topic
        self._dst = fields(dst, base)
        self._seq_src = fields([("<u4", 0)] * m, 4)
        self._seq_dst = fields([("<u4", o + 11) for o in self.rec_offsets], base)
        self.dtype = np.dtype({"names": ["time0"], "formats": [("<u8", (2,))], "offsets": [15], "itemsize": base})
        self.template = np.frombuffer(bytes(template), np.uint8)
        # per message of a row: where its record starts and ends within the row
        self._starts = np.asarray(self.rec_offsets, np.int64)
        self._ends = self._starts + np.asarray(self.rec_sizes, np.int64)

    def pack_ring(self, block: np.ndarray, first_seq: int) -> np.ndarray:
        """``(n,)`` records (dtype ``self.dtype``: field ``time0`` is [log time, publish time]) of the ring rows
        ``block``; ``.view(np.uint8)`` is the bytes of their messages, tick-major."""
        n = len(block)
        buf = np.tile(self.template, n)
        rows = buf.view(self._dst)
        rows[...] = block.view(self._src)
        seq = np.arange(first_seq, first_seq + n, dtype=np.int64).astype(np.uint32)  # wraps at 2**32
        buf.view(self._seq_dst)[...] = seq.view(self._seq_src)
        return buf.view(self.dtype)

    def pack(self, t_ns: np.ndarray, vals: np.ndarray, first_seq: int) -> np.ndarray:
        """`pack_ring` of ``t_ns`` and ``vals`` (``(n, ncols)`` float64) as ring rows."""
        block = np.empty(len(t_ns), self.ring_dtype)
        block["t"] = t_ns
        block["v"] = vals
        return self.pack_ring(block, first_seq)

    def message(self, rows: np.ndarray, k: int, j: int) -> bytes:
        """The CDR message of topic ``j`` in tick ``k`` of ``rows`` (from `pack`)."""
        a, b = self.msg_slices[j]
        return rows[k : k + 1].view(np.uint8)[a:b].tobytes()


class _BlockIndex(MessageIndex):
    """A chunk's message index of one channel, kept as runs and written out when the chunk closes: a block's
    run is (log times, first offset, stride) -- one message per tick, a record row apart; entries that
    ``add_message`` appended (``records``) become a run of (log times, offsets, 0)."""

    def __init__(self, channel_id: int, records: list[tuple[int, int]]) -> None:
        super().__init__(channel_id=channel_id, records=list(records))
        self.runs: list[tuple[np.ndarray, Any, int]] = []

    def take_records(self) -> None:
        if self.records:
            pairs = np.array(self.records, np.uint64).reshape(-1, 2)
            self.runs.append((pairs[:, 0], pairs[:, 1], 0))
            self.records.clear()

    def write(self, stream: Any) -> None:
        self.take_records()
        n = sum(len(t) for t, _, _ in self.runs)
        body = np.empty((n, 2), "<u8")
        k = 0
        for t, first, stride in self.runs:
            body[k : k + len(t), 0] = t
            body[k : k + len(t), 1] = first + stride * np.arange(len(t), dtype=np.uint64) if stride else first
            k += len(t)
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
        t = rows["time0"][:, 0]
        if not self.blocks:
            ts = t.tolist()
            seq = rows.view(layout._seq_dst)["f0"].tolist()
            for k in range(n):
                for j, cid in enumerate(layout.channel_ids):
                    self.add_message(cid, ts[k], layout.message(rows, k, j), ts[k], seq[k])
            return
        data = rows.view(np.uint8)
        lo, hi = int(t.min()), int(t.max())
        st: Statistics = self._Writer__statistics  # type: ignore[attr-defined]
        st.message_start_time = lo if st.message_count == 0 else min(st.message_start_time, lo)
        st.message_end_time = max(st.message_end_time, hi)
        st.message_count += n * m
        for cid in layout.channel_ids:
            st.channel_message_counts[cid] += n
        R, off, end = layout.row_bytes, layout.rec_offsets, layout._ends
        limit: int = self._Writer__chunk_size  # type: ignore[attr-defined]
        total, pos = n * m, 0  # messages, flat: message i is topic i % m of tick i // m
        while pos < total:
            cb = self._Writer__chunk_builder  # type: ignore[attr-defined]
            count0 = cb.count
            a = pos // m * R + off[pos % m]  # where message pos starts in ``data``
            # add_message closes the chunk after the first message that takes it past the chunk size:
            # the first message ending beyond ``budget`` in ``data``
            budget = limit - count0 + a
            r = max(budget // R, pos // m)
            over = total if r >= n else r * m + int(np.searchsorted(end, budget - r * R, side="right"))
            last = min(max(over, pos), total - 1)  # (over >= pos: message pos starts within the budget)
            b = last // m * R + int(end[last % m])
            cb.record_writer.write(data[a:b].data)
            for i in range(pos, min(pos + m, last + 1)):  # channels in order of their first message
                j, r0, r1 = i % m, i // m, (last - i % m) // m  # this channel's messages: ticks r0..r1
                cid = layout.channel_ids[j]
                ix = cb.message_indices.get(cid)
                if not isinstance(ix, _BlockIndex):
                    ix = cb.message_indices[cid] = _BlockIndex(cid, ix.records if ix is not None else [])
                ix.take_records()  # add_message's entries on this channel before this block
                ix.runs.append((t[r0 : r1 + 1], count0 + r0 * R + off[j] - a, R))
            lo_c, hi_c = (lo, hi) if pos == 0 and last == total - 1 else (
                int(t[pos // m : last // m + 1].min()), int(t[pos // m : last // m + 1].max()))  # fmt: skip
            cb.message_start_time = lo_c if cb.num_messages == 0 else min(cb.message_start_time, lo_c)
            cb.message_end_time = max(cb.message_end_time, hi_c)
            cb.num_messages += last + 1 - pos
            if over <= last:
                self._Writer__maybe_finalize_chunk()  # type: ignore[attr-defined]
            pos = last + 1
