"""The writer process: receives tick batches over a pipe, packs CDR with numpy, writes MCAP.

Runs in its own interpreter (multiprocessing spawn/forkserver), so MCAP encoding and zstd
never hold the loop's GIL. It ignores SIGINT (Ctrl-C belongs to the loop process, which
then closes the log) and finishes the file -- summary, statistics, chunk and metadata
indexes -- both on an explicit ``close`` command and on pipe EOF, i.e. when the loop
process exits or dies without closing.

Pipe protocol (parent -> writer, one direction, ``Connection.send_bytes`` frames):

* data: one frame of n rows, each ``<q`` tick time in ns followed by ``ncols`` ``<d`` values;
* control: an empty frame, then ``b"close"``, ``b"flush"`` or ``b"meta" + json([name, {str: str}])``.

Writer -> parent (second pipe, pickled dicts): ``{"event": "ready"}`` once the header,
metadata, schemas and channels are written, then a final ``{"event": "done", ...}`` with
statistics, or ``{"event": "error", "error": traceback}``.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
import traceback
from typing import Any, Sequence

import numpy as np
from mcap.writer import CompressionType, Writer

from .schema import CDR_HEADER, HEADER_FIELD, Topic

COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}

# counters shared with the parent (multiprocessing RawArray('q'))
C_BATCHES, C_ROWS, C_BYTES, C_FLUSHES = 0, 1, 2, 3


class Packer:
    """Vectorised CDR packing of ``(n, ncols)`` float64 rows into one message per topic per row."""

    def __init__(self, topics: Sequence[Topic]):
        self.plans: list[tuple[np.dtype, list[tuple[str, int]]]] = []
        col = 0
        for tp in topics:
            cols = []
            for fname, _ in tp.fields:
                cols.append((fname, col))
                col += 1
            self.plans.append((tp.dtype(), cols))
        self.ncols = col

    def pack(self, vals: np.ndarray) -> list[tuple[bytes, int]]:
        """``vals`` is (n, ncols) float64 -> per topic (n concatenated CDR messages, message size).

        Integer and bool columns are cast from float64 (C semantics: truncation, nonzero is
        True); values beyond 2**53 lose precision on the way through float64.
        """
        n = vals.shape[0]
        out = []
        for dt, cols in self.plans:
            rows = np.zeros(n, dt)  # zeros: CDR padding bytes are deterministic
            rows[HEADER_FIELD] = CDR_HEADER
            for fname, c in cols:
                rows[fname] = vals[:, c]
            out.append((rows.tobytes(), dt.itemsize))
        return out


def _send(conn: Any, msg: dict) -> None:
    try:
        conn.send(msg)
    except (OSError, ValueError):  # parent gone: nobody to tell
        pass


def main(data_conn: Any, result_conn: Any, spec: dict, counters: Any) -> None:
    """Process entry point. ``spec``: path, topics, metadata, chunk_size, compression, library."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        topics = [Topic(*t) for t in spec["topics"]]
        packer = Packer(topics)
        f = open(spec["path"], "wb", buffering=1 << 20)
        w = Writer(f, chunk_size=spec["chunk_size"], compression=COMPRESSION[spec["compression"]])
        w.start(profile="", library=spec["library"])
        for name, data in spec["metadata"].items():
            w.add_metadata(name, data)
        channel_ids = []
        for tp in topics:
            sid = w.register_schema(tp.type, "ros2msg", tp.schema_text().encode())
            channel_ids.append(w.register_channel(tp.name, "cdr", sid))
        w.flush()  # header, metadata, schemas, channels are on disk before the first tick
    except BaseException:
        _send(result_conn, {"event": "error", "error": traceback.format_exc()})
        sys.exit(1)
    _send(result_conn, {"event": "ready", "pid": os.getpid()})

    ncols = packer.ncols
    row = np.dtype([("t", "<i8"), ("v", "<f8", (ncols,))])
    recv = data_conn.recv_bytes
    add = w.add_message
    rows_done = batches = 0
    busy = pack_s = 0.0
    ended_by = "eof"
    error = None
    try:
        while True:
            try:
                frame = recv()
            except (EOFError, OSError):  # loop closed the pipe or died (maybe mid-frame): finish
                break
            t0 = time.perf_counter()
            if not frame:  # control
                try:
                    cmd = recv()
                except (EOFError, OSError):
                    break
                if cmd == b"close":
                    ended_by = "close"
                    break
                if cmd == b"flush":
                    w.flush()
                    counters[C_FLUSHES] += 1
                elif cmd.startswith(b"meta"):
                    name, data = json.loads(cmd[4:])
                    w.add_metadata(name, data)
                busy += time.perf_counter() - t0
                continue
            if len(frame) % row.itemsize:
                raise ValueError(f"batch frame of {len(frame)} bytes is not a whole number of {row.itemsize}-byte rows")
            batch = np.frombuffer(frame, row)
            n = batch.shape[0]
            ts = batch["t"].tolist()
            packed = packer.pack(batch["v"])
            t1 = time.perf_counter()
            # one message per topic per tick, tick-major so the file is in log-time order;
            # sequence = tick index (uint32, wraps) so gaps are visible per channel
            per_topic = [
                (cid, [buf[o : o + size] for o in range(0, n * size, size)])
                for cid, (buf, size) in zip(channel_ids, packed)
            ]
            for k in range(n):
                t = ts[k]
                seq = (rows_done + k) & 0xFFFFFFFF
                for cid, msgs in per_topic:
                    add(cid, t, msgs[k], t, seq)
            rows_done += n
            batches += 1
            counters[C_ROWS] = rows_done
            counters[C_BYTES] += len(frame)
            counters[C_BATCHES] = batches
            t2 = time.perf_counter()
            pack_s += t1 - t0
            busy += t2 - t0
    except BaseException:
        error = traceback.format_exc()
    finish_error = None
    try:
        w.finish()
        f.close()
    except BaseException:
        finish_error = traceback.format_exc()
    if error or finish_error:
        _send(result_conn, {"event": "error", "error": error or finish_error, "rows": rows_done})
        sys.exit(1)
    _send(
        result_conn,
        {
            "event": "done",
            "ended_by": ended_by,
            "rows": rows_done,
            "messages": rows_done * len(topics),
            "batches": batches,
            "busy_s": busy,
            "pack_s": pack_s,
            "file_bytes": os.path.getsize(spec["path"]),
        },
    )
