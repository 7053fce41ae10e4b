"""Loop-side MCAP logger: ``put()`` appends one tick to a local buffer, a writer process does the rest.

``put(t_ns, values)`` costs about 1 µs for 53 values: one precompiled ``struct.pack_into``
of the row (``int64`` time + ``float64`` values) into a preallocated batch buffer -- about
twice as fast as ``array('d').extend``, which converts element by element. Every
``batch_ticks`` rows the buffer goes as one frame down a one-way pipe (enlarged to 1 MiB
where the kernel allows) to a separate writer process (:mod:`bench.daq.writer_process`),
which packs CDR with numpy and writes the MCAP file. The loop never encodes, compresses or
touches the disk.

What can be lost
----------------
* Loop process crashes or is killed (even SIGKILL): the writer sees EOF, writes everything it
  was sent and finishes the file (summary + indexes). Lost: the rows still in the loop's
  partial batch, at most ``batch_ticks - 1`` ticks. :meth:`LogWriter.flush` hands the
  partial batch over early.
* Writer process killed (SIGKILL/SIGTERM) or the machine dies: the file is left without a
  summary; :class:`~bench.daq.reader.LogReader` still reads every complete chunk (~1 MiB).
  Lost: the open chunk, whatever sat in the pipe, and later puts (counted as ``dropped``).
* The pipe never drops: if the writer falls behind by more than the pipe holds, ``put()``
  blocks in the batch send until there is room (``send_us_max`` in :meth:`LogWriter.stats`).
* Ctrl-C (KeyboardInterrupt) in the middle of a batch send leaves a torn frame in the pipe;
  nothing more is sent after it, close() just closes the pipe and the writer finishes the
  file from the complete batches. Lost: that batch and later puts (``lost_interrupted``).

The writer process is started with ``spawn`` (or ``forkserver``), so the usual
multiprocessing rule holds: a main *script* that creates a LogWriter must be import-safe
(``if __name__ == "__main__":``). If the loop process later ``os.fork()``s, the children
inherit the pipe and the writer sees EOF only once they exit too.
"""

from __future__ import annotations

import atexit
import fcntl
import json
import multiprocessing as mp
import os
import struct
import time
from array import array
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER

from . import writer_process
from .schema import Topic
from .version import code_version

__all__ = ["LogWriter", "LogWriterError", "METADATA_PREFIX"]

METADATA_PREFIX = "imbench."  # metadata {"run": {...}} -> MCAP metadata record "imbench.run"
_DAQ_RECORD = "daq"  # written by LogWriter itself
_TIMING_RING = 1 << 16  # put() durations kept for percentiles (~22 s at 3 kHz)
_now = time.perf_counter_ns


class LogWriterError(RuntimeError):
    """The writer process failed to start, failed while writing, or did not finish."""


def encode_metadata(metadata: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, str]]:
    """``{"run": {"seed": 3}}`` -> ``{"imbench.run": {"seed": "3"}}`` (values JSON-encoded)."""
    out: dict[str, dict[str, str]] = {}
    for name, entries in (metadata or {}).items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"metadata name {name!r} must be a non-empty string")
        if not isinstance(entries, Mapping):
            raise TypeError(f"metadata {name!r} must be a dict of JSON-able values, got {type(entries).__name__}")
        rec = {}
        for key, value in entries.items():
            try:
                rec[str(key)] = json.dumps(value)
            except (TypeError, ValueError) as e:
                raise TypeError(f"metadata {name!r}[{key!r}] is not JSON-able: {e}") from None
        out[METADATA_PREFIX + name] = rec
    return out


def _enlarge_pipe(fd: int, size: int) -> int:
    """Try F_SETPIPE_SZ; return the pipe capacity actually in force."""
    setsz = getattr(fcntl, "F_SETPIPE_SZ", None)
    getsz = getattr(fcntl, "F_GETPIPE_SZ", None)
    if setsz is not None:
        try:
            fcntl.fcntl(fd, setsz, size)
        except OSError:  # above /proc/sys/fs/pipe-max-size without CAP_SYS_RESOURCE
            pass
    if getsz is not None:
        try:
            return int(fcntl.fcntl(fd, getsz))
        except OSError:
            pass
    return 0


class LogWriter:
    """Log one record per tick to an MCAP file, one message per topic per tick.

    Parameters
    ----------
    path : file to create (parent directories are made).
    topics : the topics; ``put`` takes the concatenation of their fields in this order.
    metadata : ``{name: {key: JSON-able}}`` -> MCAP metadata records ``imbench.<name>``.
        ``"daq"`` is reserved (code version, creation time, layout; written automatically).
    batch_ticks : rows per hand-over to the writer process (64 = 21 ms at 3 kHz).
    chunk_size : MCAP chunk size in bytes (uncompressed). compression: "zstd", "lz4", "none".
    start_method : "spawn" or "forkserver" (never "fork": the writer must not inherit
        the pipe's write end, or it would never see EOF).
    timing : record each ``put()`` duration for :meth:`stats` (costs ~0.15 µs per put).
    pipe_bytes : requested pipe capacity (F_SETPIPE_SZ).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        topics: Sequence[Topic],
        metadata: Mapping[str, Mapping[str, Any]] | None = None,
        batch_ticks: int = 64,
        *,
        chunk_size: int = 1 << 20,
        compression: str = "zstd",
        start_method: str = "spawn",
        timing: bool = True,
        pipe_bytes: int = 1 << 20,
        start_timeout: float = 60.0,
        close_timeout: float = 120.0,
    ):
        topics = list(topics)
        if not topics:
            raise ValueError("LogWriter needs at least one topic")
        for tp in topics:
            if not isinstance(tp, Topic):
                raise TypeError(f"topics must be Topic instances, got {type(tp).__name__}")
        names = [tp.name for tp in topics]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate topic names in {names}")
        if int(batch_ticks) < 1:
            raise ValueError("batch_ticks must be >= 1")
        if compression not in writer_process.COMPRESSION:
            raise ValueError(f"compression must be one of {list(writer_process.COMPRESSION)}")
        if start_method not in ("spawn", "forkserver"):
            raise ValueError("start_method must be 'spawn' or 'forkserver'")
        if metadata and _DAQ_RECORD in metadata:
            raise ValueError(f"metadata name {_DAQ_RECORD!r} is reserved")
        self.path = Path(path)
        self.topics = topics
        self.batch_ticks = int(batch_ticks)
        self.ncols = sum(len(tp.fields) for tp in topics)
        self._close_timeout = close_timeout

        meta = encode_metadata(metadata)
        meta[METADATA_PREFIX + _DAQ_RECORD] = encode_metadata(
            {
                _DAQ_RECORD: {
                    "code_version": code_version(),
                    "created_utc": datetime.now(timezone.utc).isoformat(),
                    "batch_ticks": self.batch_ticks,
                    "topics": names,
                    "writer": "bench.daq.LogWriter",
                }
            }
        )[METADATA_PREFIX + _DAQ_RECORD]
        spec = {
            "path": str(self.path),
            "topics": [(tp.name, tp.type, tp.fields) for tp in topics],
            "metadata": meta,
            "chunk_size": int(chunk_size),
            "compression": compression,
            "library": f"imbench-daq/{code_version()}; {LIBRARY_IDENTIFIER}",
        }
        self.path.parent.mkdir(parents=True, exist_ok=True)

        ctx = mp.get_context(start_method)
        data_r, data_w = ctx.Pipe(duplex=False)
        res_r, res_w = ctx.Pipe(duplex=False)
        self.pipe_bytes = _enlarge_pipe(data_w.fileno(), pipe_bytes)
        self._counters = ctx.RawArray("q", 4)
        self._proc = ctx.Process(
            target=writer_process.main,
            args=(data_r, res_w, spec, self._counters),
            name=f"imbench-daq-writer[{self.path.name}]",
            daemon=False,  # a daemon would be terminated at exit before finishing the file
        )
        self._proc.start()
        data_r.close()  # only the writer keeps the read end ...
        res_w.close()  # ... and the result write end, so EOF works both ways
        self._conn = data_w
        self._res = res_r
        self._result: dict | None = None
        self._closed = False
        self._failed = False

        # one row on the pipe: int64 t_ns + float64 per value, little-endian, no padding
        self._row = struct.Struct(f"<q{self.ncols}d")
        self._rowsize = self._row.size
        self._bufsize = self._rowsize * self.batch_ticks
        self._buf = bytearray(self._bufsize)
        self._pack = self._row.pack_into
        self._off = 0
        self._torn = False
        self._lost = 0
        self._rows_sent = 0
        self._batches = 0
        self._queue_hw = 0
        self._dropped = 0
        self._send_max_ns = 0
        self._send_ns = 0
        self._timing = timing
        self._dur = array("q", [0]) * _TIMING_RING
        self._mask = _TIMING_RING - 1
        self._nput = 0
        self._dmax = 0
        # put is re-bound per instance (timed / dropping / closed), so the plain path has no
        # branches for those cases
        if timing:
            self.put = self._put_timed  # type: ignore[method-assign]

        ready = self._wait_result(start_timeout)
        if ready is None or ready.get("event") != "ready":
            self._closed = True
            self.put = self._put_closed  # type: ignore[method-assign]
            self._conn.close()
            self._proc.join(5)
            detail = (ready or {}).get("error") or (
                f"writer process exited (code {self._proc.exitcode}) before it was ready. If the main "
                "script creates a LogWriter at import time, guard it with `if __name__ == '__main__':` "
                "(spawn re-imports the main module in the writer process)."
            )
            raise LogWriterError(f"writer process for {self.path} failed to start:\n{detail}")
        self.writer_pid: int = ready["pid"]
        atexit.register(self._close_at_exit)

    # ------------------------------------------------------------------ loop side
    def put(self, t_ns: int, values: Sequence[float]) -> None:
        """Log one tick: ``values`` is the concatenation of all topics' fields, in topic order.

        ``t_ns`` (int) becomes log_time = publish_time of every topic's message. Ints and bools
        may be given as Python ints, bools or floats; they travel as float64 (exact to 2**53).
        (With ``timing=True`` the instance's ``put`` is the timed twin of this method.)
        """
        try:
            self._pack(self._buf, self._off, t_ns, *values)
        except struct.error as e:
            raise self._bad_row(t_ns, values, e) from None
        self._off += self._rowsize
        if self._off >= self._bufsize:
            self._send()

    def _put_timed(self, t_ns: int, values: Sequence[float]) -> None:
        t0 = _now()
        try:
            self._pack(self._buf, self._off, t_ns, *values)
        except struct.error as e:
            raise self._bad_row(t_ns, values, e) from None
        self._off += self._rowsize
        if self._off >= self._bufsize:
            self._send()
        d = _now() - t0
        i = self._nput
        self._dur[i & self._mask] = d
        self._nput = i + 1
        if d > self._dmax:
            self._dmax = d

    def _bad_row(self, t_ns: Any, values: Sequence[Any], err: Exception) -> Exception:
        try:
            n = len(values)
        except TypeError:
            return TypeError(f"put(): values must be a sequence of {self.ncols} numbers")
        if n != self.ncols:
            return ValueError(f"put() got {n} values, the topics have {self.ncols} fields")
        if not isinstance(t_ns, int):
            return TypeError(f"put(): t_ns must be an int (nanoseconds), got {type(t_ns).__name__}")
        return TypeError(f"put(): {err} (t_ns: int64 ns, then {self.ncols} numbers or bools)")

    def _put_dropping(self, t_ns: int, values: Sequence[float]) -> None:
        self._dropped += 1

    def _put_closed(self, t_ns: int, values: Sequence[float]) -> None:
        raise ValueError(f"put() on a closed LogWriter ({self.path})")

    def _send(self) -> None:
        n_bytes = self._off
        if n_bytes == 0:
            return
        n = n_bytes // self._rowsize
        if self._torn:  # an earlier frame was cut short: nothing more may follow it
            self._off = 0
            self._lost += n
            return
        t0 = _now()
        try:
            self._off = 0
            self._conn.send_bytes(self._buf, 0, n_bytes)  # synchronous: buffer reusable after
        except OSError:  # writer died: never stall or crash the loop; close() reports it
            self._failed = True
            self._dropped += n
            self.put = self._put_dropping  # type: ignore[method-assign]
        except BaseException:  # Ctrl-C mid-frame: the pipe may hold half a frame
            self._torn = True
            self._lost += n
            raise
        else:
            self._rows_sent += n
            self._batches += 1
            depth = self._batches - self._counters[writer_process.C_BATCHES]
            if depth > self._queue_hw:
                self._queue_hw = depth
        dt = _now() - t0
        self._send_ns += dt
        if dt > self._send_max_ns:
            self._send_max_ns = dt

    def flush(self, chunk: bool = False) -> None:
        """Hand the partial batch to the writer now (bounds loss on a loop crash to later puts).

        ``chunk=True`` also makes the writer close its current MCAP chunk and flush the file to
        the OS, which bounds loss if the *writer* is killed, at some cost in compression.
        """
        if self._closed or self._failed:
            return
        self._send()
        if chunk and not self._failed:
            self._control(b"flush")

    def add_metadata(self, name: str, entries: Mapping[str, Any]) -> None:
        """Write another metadata record mid-run or at the end (e.g. results, trip reasons)."""
        if self._closed or self._failed:
            raise LogWriterError("add_metadata() on a closed or failed LogWriter")
        if name == _DAQ_RECORD:
            raise ValueError(f"metadata name {_DAQ_RECORD!r} is reserved")
        ((rec_name, rec),) = encode_metadata({name: entries}).items()
        self._control(b"meta" + json.dumps([rec_name, rec]).encode())

    def _control(self, cmd: bytes) -> None:
        if self._torn:
            return
        try:
            self._conn.send_bytes(b"")
            self._conn.send_bytes(cmd)
        except OSError:
            self._failed = True
            self.put = self._put_dropping  # type: ignore[method-assign]
        except BaseException:
            self._torn = True
            raise

    # ------------------------------------------------------------------ lifecycle
    def _wait_result(self, timeout: float) -> dict | None:
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            try:
                if self._res.poll(min(remaining, 0.5)):
                    return self._res.recv()
            except (EOFError, OSError):
                return None
            if not self._proc.is_alive() and not self._res.poll(0):
                return None

    def close(self) -> dict:
        """Send the partial batch, let the writer finish the file, wait for it. Idempotent.

        Returns the writer's final report; raises :class:`LogWriterError` if the writer
        failed, died, dropped rows, or did not finish within ``close_timeout`` (it is then
        left running to finish on its own, and a later ``close()`` waits again).
        """
        if not self._closed:
            self._closed = True
            atexit.unregister(self._close_at_exit)
            if not self._failed:
                self._send()
                self._control(b"close")
            self.put = self._put_closed  # type: ignore[method-assign]
            self._conn.close()  # EOF finishes the writer even if the close frame was lost
        if self._result is None:
            res = self._wait_result(self._close_timeout)
            if res is None and self._proc.is_alive():
                raise LogWriterError(f"writer for {self.path} did not finish within {self._close_timeout} s")
            self._result = res if res is not None else {"event": "lost"}
            self._proc.join(self._close_timeout)
        res = self._result
        if res.get("event") != "done":
            detail = res.get("error") or f"exit code {self._proc.exitcode}"
            raise LogWriterError(f"writer process for {self.path} failed:\n{detail}")
        if self._dropped:
            raise LogWriterError(f"{self._dropped} rows were dropped for {self.path}")
        return res

    def _close_at_exit(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        # an exception from the loop wins; the file still gets every row put before it
        if exc_type is None:
            self.close()
        else:
            try:
                self.close()
            except LogWriterError:
                pass

    @property
    def healthy(self) -> bool:
        """False once the writer process is gone before close (cheap enough for a slow loop)."""
        return not self._failed and (self._closed or self._proc.is_alive())

    def stats(self) -> dict:
        """Loop-side and writer-side counters; put() percentiles over the last 65 536 puts."""
        pending = self._off // self._rowsize
        rows_put = self._rows_sent + pending + self._dropped + self._lost
        out: dict[str, Any] = {
            "rows_put": rows_put,
            "rows_sent": self._rows_sent,
            "rows_pending": pending,
            "rows_written": int(self._counters[writer_process.C_ROWS]),
            "batches_sent": self._batches,
            "batches_written": int(self._counters[writer_process.C_BATCHES]),
            "chunk_flushes": int(self._counters[writer_process.C_FLUSHES]),
            "queue_hw_batches": self._queue_hw,
            "queue_hw_bytes_est": self._queue_hw * self._bufsize,
            "pipe_bytes": self.pipe_bytes,
            "dropped": self._dropped,
            "lost_interrupted": self._lost,
            "send_us_max": self._send_max_ns / 1e3,
            "send_us_mean": self._send_ns / 1e3 / max(self._batches, 1),
            "writer_failed": self._failed,
        }
        if self._timing and self._nput:
            n = min(self._nput, _TIMING_RING)
            d = np.frombuffer(self._dur, np.int64)[:n] / 1e3
            out["put_us"] = {
                "n": self._nput,
                "mean": float(d.mean()),
                "p50": float(np.percentile(d, 50)),
                "p99": float(np.percentile(d, 99)),
                "p99.9": float(np.percentile(d, 99.9)),
                "max": self._dmax / 1e3,
            }
        if self._result is not None:
            out["writer"] = dict(self._result)
            if "rows" in self._result:
                out["rows_written"] = self._result["rows"]
        return out
