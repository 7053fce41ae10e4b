"""Read imbench MCAP logs into numpy arrays, self-described by the ros2msg schemas in the file.

The dtype of each topic is rebuilt from the Schema record stored in the file (flat
primitive ros2msg subset, see :func:`bench.daq.schema.parse_ros2msg`) -- no out-of-band
knowledge. Payloads of one chunk are concatenated and decoded with a single
``np.frombuffer`` (per-message only if sizes differ).

Files that were never finished (writer killed, power loss) have no summary: the reader then
scans from the start and keeps every complete chunk, stopping quietly at the torn tail
(``summary()["truncated"]`` tells).
"""

from __future__ import annotations

import json
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Chunk, ChunkIndex, Footer, Message, Metadata, Schema, Statistics
from mcap.stream_reader import StreamReader, breakup_chunk

from bench.errors import BadInput

from .schema import CDR_LE_HEADER, FIELD_TYPES, HEADER_FIELD, VAR_TYPES, cdr_dtype, decode_cdr, parse_ros2msg
from .events import EVENTS, PARAMS

LEGACY_METADATA_PREFIX = "imbench."  # logs before Nov 2026 named their metadata records "imbench.run", ...

__all__ = ["INTERNALS_TOPICS", "LogReader", "internals_topic", "is_finished"]

INTERNALS_TOPICS = ("/ctrl", "/ident")  # a controller's `topic`: /ident for bench identify's test plugin


def internals_topic(topics: list[str]) -> str | None:
    """The topic of a log (its ``topics()``) that holds the controller's internals, if any."""
    return next((tp for tp in INTERNALS_TOPICS if tp in topics), None)


def _decode_json(value: str) -> Any:
    try:
        return json.loads(value)
    except ValueError:
        return value


MCAP_MAGIC = b"\x89MCAP0\r\n"


def is_finished(path: str | os.PathLike[str]) -> bool:
    """True once the writer has finished the file (it ends with the MCAP magic)."""
    try:
        with open(path, "rb") as f:
            f.seek(-len(MCAP_MAGIC), os.SEEK_END)
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


class LogReader:
    """``LogReader(path)``: topics, fields, typed columns, metadata and a summary of one log."""

    def __init__(self, path: str | os.PathLike[str]):
        self.path = Path(path)
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._metadata: list[Metadata] = []
        self._stats: Statistics | None = None
        self._chunks = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._finalised = False
        self._truncated = False
        self._stop_reason = ""
        self._data: dict[int, tuple[np.ndarray, np.ndarray]] | None = None
        self._layouts: dict[int, tuple[list[tuple[str, str]], np.dtype]] = {}
        self.torn_rows = 0  # rows `read_ticks` left out after the last complete tick

        try:
            f = open(self.path, "rb")
        except OSError as e:
            raise BadInput(str(self.path), f"cannot read the log: {e.strerror or e}") from None
        with f:
            try:
                reader = SeekingReader(f)
                self._header = reader.get_header()
            except Exception as e:  # noqa: BLE001 - mcap raises several types for "not MCAP"
                why = "empty file" if os.path.getsize(self.path) == 0 else f"{type(e).__name__}"
                raise BadInput(str(self.path), f"not an MCAP log ({why})") from None
            try:
                summary = reader.get_summary()
            except Exception:  # torn tail: no footer where it should be
                summary = None
            if summary is not None:
                self._finalised = True
                self._schemas = dict(summary.schemas)
                self._channels = dict(summary.channels)
                self._stats = summary.statistics
                self._chunks = len(summary.chunk_indexes)
                self._chunk_indexes = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
                self._metadata = list(reader.iter_metadata())
        if not self._finalised:
            self._scan()

    # ------------------------------------------------------------------ structure
    def _topic_channels(self, topic: str) -> list[int]:
        ids = [cid for cid, ch in self._channels.items() if ch.topic == topic]
        if not ids:
            raise KeyError(f"no topic {topic!r} in {self.path}; topics: {self.topics()}")
        return ids

    def _layout(self, cid: int) -> tuple[list[tuple[str, str]], np.dtype]:
        if cid not in self._layouts:
            ch = self._channels[cid]
            schema = self._schemas.get(ch.schema_id)
            if schema is None or schema.encoding != "ros2msg" or ch.message_encoding != "cdr":
                raise ValueError(f"topic {ch.topic!r} is not ros2msg/cdr; the imbench reader cannot decode it")
            fields = parse_ros2msg(schema.data.decode())
            fixed = all(t in FIELD_TYPES for _, t in fields)  # else an event topic: decoded one by one
            self._layouts[cid] = (fields, cdr_dtype(fields) if fixed else np.dtype(object))
        return self._layouts[cid]

    def topics(self) -> list[str]:
        """Topic names in channel order."""
        seen: dict[str, None] = {}
        for ch in self._channels.values():
            seen.setdefault(ch.topic, None)
        return list(seen)

    def schema(self, topic: str) -> list[tuple[str, str]]:
        """(field, ros2msg type) pairs of ``topic``, parsed from the schema in the file."""
        return list(self._layout(self._topic_channels(topic)[0])[0])

    def fields(self, topic: str) -> list[str]:
        """Field names of ``topic`` in schema order."""
        return [n for n, _ in self.schema(topic)]

    def metadata(self) -> dict[str, dict]:
        """Metadata records, JSON values decoded: ``{"run": {...}, "rig": {...}, "daq": {...}}``.

        Logs written before Nov 2026 named them ``imbench.<name>``: they appear as ``<name>`` too.
        Values are plain strings or JSON (decoded where they parse as JSON).
        """
        out: dict[str, dict] = {}
        for rec in self._metadata:
            pre = LEGACY_METADATA_PREFIX
            name = rec.name[len(pre) :] if rec.name.startswith(pre) else rec.name
            out.setdefault(name, {}).update({k: _decode_json(v) for k, v in rec.metadata.items()})
        return out

    def attachments(self) -> dict[str, bytes]:
        """Attachments by name (the rig file, the summary, ...); a torn file keeps those before the tear."""
        out: dict[str, bytes] = {}
        with open(self.path, "rb") as f:
            for rec in self._intact_records(f, emit_chunks=True):
                if isinstance(rec, Attachment):
                    out[rec.name] = bytes(rec.data)
                elif isinstance(rec, Footer):
                    break
        return out

    def _intact_records(self, f: Any, emit_chunks: bool) -> Any:
        """Records front to back, stopping quietly at a torn tail (``summary()["truncated"]`` tells)."""
        records = StreamReader(f, emit_chunks=emit_chunks).records
        while True:
            try:
                yield next(records)
            except StopIteration:
                return
            except Exception as e:  # torn record at the end of an unfinished file
                self._truncated = True
                self._stop_reason = f"{type(e).__name__}: {e}"
                return

    # ------------------------------------------------------------------ data
    def _scan(self) -> None:
        """One pass over the whole file: structure (if unfinalised) and every topic's data."""
        acc: dict[int, tuple[list[int], list[bytes]]] = defaultdict(lambda: ([], []))
        parts: dict[int, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
        structure = not self._finalised

        def take(rec: Any) -> None:
            if isinstance(rec, Message):
                times, datas = acc[rec.channel_id]
                times.append(rec.log_time)
                datas.append(rec.data)
            elif isinstance(rec, Schema):
                self._schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel):
                self._channels.setdefault(rec.id, rec)

        def settle() -> None:
            for cid, (times, datas) in acc.items():
                if times:
                    parts[cid].append((np.array(times, np.int64), self._decode(cid, datas)))
            acc.clear()

        with open(self.path, "rb") as f:
            if self._chunk_indexes:
                # finished file: jump from chunk to chunk by the index (skips message indexes)
                for ci in self._chunk_indexes:
                    f.seek(ci.chunk_start_offset + 1 + 8)  # opcode + record length
                    for r in breakup_chunk(Chunk.read(ReadDataStream(f))):
                        take(r)
                    settle()
                chunks = len(self._chunk_indexes)
            else:
                chunks = self._scan_stream(f, take, settle)
        if structure:
            self._chunks = chunks
        self._data = {}
        for cid in self._channels:
            if cid in parts:
                ts = np.concatenate([p[0] for p in parts[cid]])
                rows = np.concatenate([p[1] for p in parts[cid]])
            else:
                ts, rows = np.empty(0, np.int64), np.empty(0, self._layout(cid)[1])
            self._data[cid] = (ts, rows)

    def _scan_stream(self, f: Any, take: Any, settle: Any) -> int:
        """Read records front to back, tolerating a torn tail; return the number of chunks read."""
        chunks = 0
        for rec in self._intact_records(f, emit_chunks=True):
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec)
                except Exception as e:  # chunk cut short by a crash
                    self._truncated = True
                    self._stop_reason = f"{type(e).__name__}: {e}"
                    break
                chunks += 1
                for r in inner:
                    take(r)
                settle()
            elif isinstance(rec, Metadata):
                if not self._finalised:
                    self._metadata.append(rec)
            elif isinstance(rec, Footer):
                break
            else:
                take(rec)
        settle()
        return chunks

    def _decode(self, cid: int, datas: list[bytes]) -> np.ndarray:
        fields, dt = self._layout(cid)
        if dt == np.dtype(object):  # variable-size messages (strings): kept as bytes, decoded by `read`
            rows = np.empty(len(datas), object)
            rows[:] = [bytes(d) for d in datas]
            return rows
        size = dt.itemsize
        if all(len(d) == size for d in datas):
            rows = np.frombuffer(b"".join(datas), dt)
        else:  # sizes differ (foreign writer padding): decode message by message
            rows = np.empty(len(datas), dt)
            for i, d in enumerate(datas):
                if len(d) < size:
                    raise ValueError(f"message {i} on {self._channels[cid].topic!r}: {len(d)} bytes < {size}")
                rows[i] = np.frombuffer(d, dt, count=1)[0]
        hdr = rows[HEADER_FIELD]
        if hdr.size and not (hdr[:, :2] == np.frombuffer(CDR_LE_HEADER[:2], np.uint8)).all():
            if (hdr[:, :2] == 0).all():  # CDR_BE: same layout, other byte order
                return rows.view(cdr_dtype(fields, ">"))
            raise ValueError(f"topic {self._channels[cid].topic!r}: unsupported CDR encapsulation")
        return rows

    def read(self, topic: str, ns: bool = False) -> dict[str, np.ndarray]:
        """Columns of ``topic``: ``log_time`` [s, float64] (int64 ns if ``ns``) plus every field.

        Arrays are contiguous, in file (= put) order, typed as the schema says (bool, int32, ...).
        """
        if self._data is None:
            self._scan()
        assert self._data is not None
        cids = self._topic_channels(topic)
        fields, _ = self._layout(cids[0])
        ts = np.concatenate([self._data[c][0] for c in cids])
        rows = np.concatenate([self._data[c][1] for c in cids])
        if len(cids) > 1:
            order = np.argsort(ts, kind="stable")
            ts, rows = ts[order], rows[order]
        out: dict[str, np.ndarray] = {"log_time": ts.copy() if ns else ts / 1e9}
        if rows.dtype == np.dtype(object):  # an event topic: one message at a time
            vals = [decode_cdr(fields, d) for d in rows]
            for j, (name, ftype) in enumerate(fields):
                col = [v[j] for v in vals]
                out[name] = np.array(col, object if ftype in VAR_TYPES else FIELD_TYPES[ftype])
            return out
        for name, _ in fields:
            col = rows[name]
            out[name] = np.ascontiguousarray(col.astype(col.dtype.newbyteorder("=")))
        return out

    def events(self) -> list[dict[str, Any]]:
        """The run's parameter changes (/params, kind "set") and operator actions (/events), applied or
        refused, in the order applied (tick, then request number)."""
        out = []
        for topic in (PARAMS[0], EVENTS[0]):
            if topic not in self.topics():
                continue
            cols = self.read(topic)
            names = [n for n in cols if n != "log_time"]
            for i in range(len(cols["log_time"])):
                ev = {n: cols[n][i].item() if hasattr(cols[n][i], "item") else cols[n][i] for n in names}
                ev["kind"] = ev.get("kind", "set")
                out.append(ev)
        return sorted(out, key=lambda e: (e["tick"], e["seq"]))

    def read_ticks(self, *topics: str) -> list[dict[str, np.ndarray]]:
        """Several per-tick topics of an imbench run log, cut to the ticks all of them have.

        A log whose writer died can end half-way through a tick (``/rig`` one message longer than
        ``/ctrl``); the rows after the last complete tick are left out (``torn_rows`` counts them).
        A file without the first topic is not an imbench run log: `BadInput`.
        """
        missing = [tp for tp in topics if tp not in self.topics()]
        if missing:
            raise BadInput(str(self.path), f"not an imbench run log: no topic {missing[0]} (topics: {self.topics()})")
        try:
            cols = [self.read(tp) for tp in topics]
        except ValueError as e:
            raise BadInput(str(self.path), f"cannot decode the log: {e}") from None
        n = min(len(c["log_time"]) for c in cols)
        self.torn_rows = sum(len(c["log_time"]) - n for c in cols)
        return [c if len(c["log_time"]) == n else {k: v[:n] for k, v in c.items()} for c in cols]

    def summary(self) -> dict[str, Any]:
        """Message counts per topic, start/end time, chunk count, and whether the file was finished."""
        if self._stats is not None:
            counts_by_id = dict(self._stats.channel_message_counts)
            start, end = self._stats.message_start_time, self._stats.message_end_time
        else:
            if self._data is None:
                self._scan()
            assert self._data is not None
            counts_by_id = {cid: len(ts) for cid, (ts, _) in self._data.items()}
            all_ts = [ts for ts, _ in self._data.values() if len(ts)]
            start = int(min(t.min() for t in all_ts)) if all_ts else 0
            end = int(max(t.max() for t in all_ts)) if all_ts else 0
        topics: dict[str, dict[str, Any]] = {}
        for cid, ch in self._channels.items():
            schema = self._schemas.get(ch.schema_id)
            entry = topics.setdefault(ch.topic, {"type": schema.name if schema else "", "messages": 0})
            entry["messages"] += int(counts_by_id.get(cid, 0))
        total = sum(t["messages"] for t in topics.values())
        return {
            "path": str(self.path),
            "finalised": self._finalised,
            "truncated": self._truncated,
            "stop_reason": self._stop_reason,
            "library": self._header.library,
            "topics": topics,
            "message_count": total,
            "start_ns": int(start),
            "end_ns": int(end),
            "start_time": start / 1e9,
            "end_time": end / 1e9,
            "duration_s": (end - start) / 1e9,
            "chunks": self._chunks,
        }
