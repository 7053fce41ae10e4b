"""Loop-side MCAP logger: ``put()`` packs one tick into shared memory, a writer process does the rest.

``put(t_ns, values)`` is one precompiled ``struct.pack_into`` of the row (``int64`` time +
``float64`` per value) straight into a shared-memory ring -- about 0.7 µs for 53 values with
hot caches, twice as fast as ``array('d').extend``. Every ``batch_ticks`` rows the loop
publishes the new head index with a single store; the writer process
(:mod:`bench.daq.writer_process`) polls it, packs CDR with numpy and writes the MCAP file.
The loop makes no system call while logging: measured on the 2-vCPU VM, sending a 27 kB batch
down a pipe cost the loop ~75 µs per batch (p50) and waking a blocked reader let it preempt
the loop for up to 2 ms. The writer also runs at ``nice`` +10 for the same reason.

What can be lost
----------------
* Loop process crashes or is killed (even SIGKILL): the writer sees EOF on the control pipe,
  writes every published row and finishes the file (summary + indexes). Lost: the rows of
  the unpublished partial batch, at most ``batch_ticks - 1`` ticks. :meth:`LogWriter.flush`
  publishes early.
* Writer process killed (SIGKILL/SIGTERM) or the machine dies: the file is left without a
  summary; :class:`~bench.daq.reader.LogReader` still reads every complete chunk (~1 MiB).
  Lost: the open chunk and everything not yet written (``dropped`` after close(): the rows put
  minus the rows the file holds, counted by reading it back).
* A slow or stalled writer: ``put()`` never blocks for long. At each batch boundary the loop
  checks that the writer process lives and that the ring has room for the next batch. With no
  room, ``put()`` waits at most ``max_wait`` seconds (0 in real time: a real-time loop must
  never wait on its log; lockstep runs wait, the writer sets their pace) and then declares a
  *fault*: ``fault`` holds the reason and ``on_fault(reason)`` is called (the session turns it
  into a supervisor trip at the next tick). The last ``reserve_ticks`` slots of the ring are kept
  for the rows after a fault, so the trip and the safe command still reach the file if the
  writer recovers. A dead writer is a fault at once. A stall shorter than the ring (default
  32768 rows, 10.9 s at 3 kHz) loses nothing and is only counted (``stalls``). The fault's reason
  is one line that says what the full ring held (loop time and rows) and why the writer fell
  behind (:mod:`bench.daq.diagnose`): CPU-starved (the CPU it got and the time it waited for
  one, the load average), the disk, a stopped process, or more to log than its CPU does.
  The writer drops its extra niceness while more than an eighth of the ring waits (where the OS
  allows: CAP_SYS_NICE), so that a busy machine's other programs do not starve it.

The writer process is started with ``spawn`` (`bench.core.shutdown.child_context`: the child does not
import the caller's main module, so a script needs no ``if __name__ == "__main__":`` guard), or
with ``forkserver`` (multiprocessing's own rules). If the loop process later ``os.fork()``s, the children
inherit the control pipe and the writer sees EOF only once they exit too.
"""

from __future__ import annotations

import atexit
import json
import multiprocessing as mp
import os
import platform
import struct
import time
from array import array
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER

from bench.core.shutdown import child_context, spawning

from . import diagnose, writer_process
from .writer_process import ESTOP, FLUSHES, HEAD, IDX_SLOTS, PIECES, POSTED, REPORTED, STOP, TAIL
from .reader import LogReader
from .schema import Topic
from .version import code_version
from bench.operate.requests import Request

__all__ = ["LogWriter", "LogWriterError"]

_RESERVED = ("daq", "units")  # records LogWriter writes itself
_TIMING_RING = 1 << 16  # put() durations kept for percentiles (~22 s at 3 kHz)
_now = time.perf_counter_ns
# CPUs whose memory model keeps store order (TSO): the ring needs no system call to publish
_TSO = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686", "x86")


class LogWriterError(RuntimeError):
    """The writer process failed to start, failed while writing, or did not finish."""


def _plain(value: Any) -> str:
    """A metadata value as MCAP stores it (str -> str): strings as they are, everything else as JSON."""
    return value if isinstance(value, str) else json.dumps(value)


def encode_metadata(metadata: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, str]]:
    """``{"run": {"seed": 3, "scenario": "demo"}}`` -> record ``run``: ``{"seed": "3", "scenario": "demo"}``.

    Strings stay plain (Foxglove shows them as they are); numbers, lists and dicts are JSON.
    """
    out: dict[str, dict[str, str]] = {}
    for name, entries in (metadata or {}).items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"metadata name {name!r} must be a non-empty string")
        if not isinstance(entries, Mapping):
            raise TypeError(f"metadata {name!r} must be a dict of JSON-able values, got {type(entries).__name__}")
        rec = {}
        for key, value in entries.items():
            try:
                rec[str(key)] = _plain(value)
            except (TypeError, ValueError) as e:
                raise TypeError(f"metadata {name!r}[{key!r}] is not JSON-able: {e}") from None
        out[name] = rec
    return out


class RequestInbox:
    """The loop's end of the requests from the live server (bench.daq.live_control). `pending` reads
    shared memory only, so a loop can ask every tick; `take` returns a flagged e-stop and stop first
    (they never wait in the pipe), then the frames the writer has counted as posted. The read end is
    non-blocking: a frame that is not whole, a bad frame or a closed pipe sets `broken` (the loop trips
    on it) instead of stalling the loop."""

    def __init__(self, idx: Any, conn: Any) -> None:
        self._idx, self._conn, self._seen = idx, conn, 0
        self._estop = self._stop = 0  # the flagged requests already taken
        self.broken: str | None = None
        os.set_blocking(conn.fileno(), False)

    def pending(self) -> bool:
        i = self._idx
        return i[POSTED] != self._seen or i[ESTOP] != self._estop or i[STOP] != self._stop

    def take(self, k: int) -> list:
        i, out = self._idx, []
        if i[ESTOP] != self._estop:
            self._estop = i[ESTOP]
            out.append(Request(self._estop, "estop", who="live client"))
        if i[STOP] != self._stop:
            self._stop = i[STOP]
            out.append(Request(self._stop, "stop", who="live client"))
        posted = i[POSTED]  # each counted frame is in the pipe whole; later ones stay pending
        try:
            while self.broken is None and self._seen < posted:
                out.append(Request.decode(self._conn.recv_bytes()))
                self._seen += 1
        except Exception as exc:  # noqa: BLE001 - torn or bad frame, writer gone: no request can be trusted
            self.broken = f"live request channel broken: {type(exc).__name__}: {exc}"[:300]
        self._seen = posted  # broken: only the flags are read from here on
        return out


def _check_options(topics: list, metadata: Mapping[str, Any] | None, batch_ticks: int, compression: str,
                   start_method: str) -> None:  # fmt: skip
    """`LogWriter`'s arguments that would make no log: one ValueError (TypeError) naming the one."""
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
    for reserved in _RESERVED:
        if metadata and reserved in metadata:
            raise ValueError(f"metadata name {reserved!r} is reserved")


class LogWriter:
    """Log one record per tick to an MCAP file, one message per topic per tick.

    Parameters
    ----------
    path : file to create (parent directories are made).
    topics : the topics; ``put`` takes the concatenation of their fields in this order.
    metadata : ``{name: {key: JSON-able}}`` -> MCAP metadata records ``imbench.<name>``.
        ``"daq"`` is reserved (code version, creation time, layout; written automatically).
    batch_ticks : rows per publication to the writer process (64 = 21 ms at 3 kHz).
    ring_ticks : shared ring capacity in rows (default 8192 = 2.7 s at 3 kHz, 3.5 MB for 53
        values); rounded up to a multiple of ``batch_ticks``.
    chunk_size : MCAP chunk size in bytes (uncompressed). compression: "lz4" (default: a third of the
        writer's CPU per row less than zstd, about 10 % larger files), "zstd", "none".
    start_method : "spawn" or "forkserver" (never "fork": the writer must not inherit
        the pipe's write end, or it would never see EOF).
    timing : record each ``put()`` duration for :meth:`stats` (costs ~0.15 µs per put).
    writer_nice : niceness added to the writer process, so it never preempts the loop.
    notify : publish through the pipe instead of by a store (default: only on CPUs
        without store ordering; see :mod:`bench.daq.writer_process`).
    writer_idle_s : how often an idle writer looks at the ring (each look costs it ~20-40 µs of CPU on
        a VM: at 2 ms, as much CPU as writing the rows at 3 kHz).
    writer_coalesce_s : the writer drains published rows once 192 of them (at most 1/8 of the ring) wait
        or the first has waited this long: larger, fewer drains (each starts with cold caches).
    max_wait : longest time a ``put()`` may wait for room in the ring before the writer is
        declared stalled (a fault); 0 = never wait (real time).
    on_fault : called once with the reason when the writer dies or stalls (see "What can be lost").
    reserve_ticks : ring slots kept for the rows after a fault (the trip and the coast-down).
    attachments : ``(name, media type, bytes)`` stored as MCAP attachments at the start (e.g. the
        rig file); `attach` adds more later (e.g. the summary).
    block_write : write a block of rows at once (`bench.daq.mcap_block`); False: message by message
        through mcap's ``add_message`` (the same file, ~4x the writer's CPU; for comparisons).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        topics: Sequence[Topic],
        metadata: Mapping[str, Mapping[str, Any]] | None = None,
        batch_ticks: int = 64,
        *,
        chunk_size: int = 1 << 20,
        compression: str = "lz4",
        start_method: str = "spawn",
        ring_ticks: int = 32768,
        timing: bool = True,
        writer_nice: int = 10,
        notify: bool | None = None,
        writer_idle_s: float = 0.01,
        writer_coalesce_s: float = 0.05,
        start_timeout: float = 60.0,
        close_timeout: float = 120.0,
        max_wait: float = 60.0,
        on_fault: Callable[[str], None] | None = None,
        reserve_ticks: int = 256,
        attachments: Sequence[tuple[str, str, bytes]] = (),
        live: Mapping[str, Any] | None = None,
        panel: bool = False,
        operator: Mapping[str, Any] | None = None,
        block_write: bool = True,
    ):
        topics = list(topics)
        _check_options(topics, metadata, batch_ticks, compression, start_method)
        self.path = Path(path)
        self.topics = topics
        self.batch_ticks = int(batch_ticks)
        self.ring_ticks = max(2, -(-int(ring_ticks) // self.batch_ticks)) * self.batch_ticks
        # rows kept free for after a fault, whole batches, and at least one batch of normal room
        self.reserve_ticks = min(-(-max(0, int(reserve_ticks)) // self.batch_ticks) * self.batch_ticks,
                                 self.ring_ticks - self.batch_ticks)  # fmt: skip
        self.max_wait = float(max_wait)
        self.on_fault = on_fault
        self.fault: str | None = None
        self.ncols = sum(len(tp.fields) for tp in topics)
        self.notify = (not _TSO) if notify is None else bool(notify)
        self._close_timeout = close_timeout
        # one ring slot: int64 t_ns + float64 per value, little-endian, no padding
        self._row = struct.Struct(f"<q{self.ncols}d")
        self._rowsize = self._row.size

        spec = self._spec(metadata, chunk_size, compression, attachments, live, panel, operator, writer_idle_s,
                          writer_coalesce_s, writer_nice, block_write)  # fmt: skip
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._result: dict | None = None
        self._closed = False
        self._failed = False
        self._torn = False
        self._proc = None
        self._conn = self._res = self._rep = None
        self.inbox: RequestInbox | None = None  # requests from live clients (bench.operate.operator), if taken
        self._start_process(spec, start_method, operator)

        self._pack = self._row.pack_into
        self._ring_bytes = self.ring_ticks * self._rowsize
        self._batch_bytes = self.batch_ticks * self._rowsize
        self._off = 0  # byte offset of the next row in the ring
        self._pub_off = 0  # byte offset of the first unpublished row
        self._batch_end = self._batch_bytes  # publish when _off reaches this
        self._head = 0  # rows published
        self._publishes = 0
        self._queue_hw = 0
        self._put_after_loss = 0  # puts while the writer was known to be gone
        self._unwritten = 0  # rows put before that which never reached the file
        self._in_file: int | None = None  # rows in the file, counted after a writer failure
        self._stalls = 0
        self._stall_ns_max = 0
        self._timing = timing
        self._dur = array("q", [0]) * _TIMING_RING
        self._mask = _TIMING_RING - 1
        self._nput = 0
        self._dmax = 0
        # put is re-bound per instance (timed / dropping / closed), so the plain path has no
        # branches for those cases
        if timing:
            self.put = self._put_timed  # type: ignore[method-assign]

        ready = self._await_ready(start_timeout, start_method)
        self.writer_pid: int = ready["pid"]
        self.live_port: int | None = ready.get("live_port")
        self._panel = bool(panel)
        atexit.register(self._close_at_exit)

    def _spec(self, metadata: Mapping[str, Mapping[str, Any]] | None, chunk_size: int, compression: str,
              attachments: Sequence[tuple[str, str, bytes]], live: Mapping[str, Any] | None, panel: bool,
              operator: Mapping[str, Any] | None, writer_idle_s: float, writer_coalesce_s: float, writer_nice: int,
              block_write: bool) -> dict:  # fmt: skip
        """What the writer process is started with (`bench.daq.writer_process.main`): the file, topics, metadata
        (the reserved ``daq`` and ``units`` records added), attachments and the writer's settings."""
        topics, names = self.topics, [tp.name for tp in self.topics]
        meta = encode_metadata(metadata)
        meta.update(encode_metadata({
            "daq": {"code_version": code_version(), "created_utc": datetime.now(timezone.utc).isoformat(),
                    "batch_ticks": self.batch_ticks, "topics": names, "writer": "bench.daq.LogWriter",
                    "log_time": "ns since the Unix epoch: the run's start epoch + the loop time t (field t)"},
            "units": {f"{tp.name}/{f}": u for tp in topics for (f, _), u in zip(tp.fields, tp.units) if u},
        }))  # fmt: skip
        return {
            "path": str(self.path),
            "topics": [(tp.name, tp.type, tp.fields, tp.units) for tp in topics],
            "attachments": [(n, mt, bytes(data)) for n, mt, data in attachments],
            "live": dict(live) if live else None,
            "panel": bool(panel),
            "operator": dict(operator) if operator is not None else None,
            "metadata": meta,
            "chunk_size": int(chunk_size),
            "compression": compression,
            "library": f"imbench-daq/{code_version()}; {LIBRARY_IDENTIFIER}",
            "ring_ticks": self.ring_ticks,
            "notify": self.notify,
            "idle_s": float(writer_idle_s),
            "coalesce_s": float(writer_coalesce_s),
            "nice": int(writer_nice),
            "blocks": bool(block_write),
        }

    def _start_process(self, spec: dict, start_method: str, operator: Mapping[str, Any] | None) -> None:
        """The pipes, the shared ring and index, and the writer process, started deaf to terminal keys."""
        ctx = child_context() if start_method == "spawn" else mp.get_context(start_method)
        req_w = rep_r = None
        try:
            ctl_r, ctl_w = ctx.Pipe(duplex=False)
            self._conn = ctl_w
            res_r, res_w = ctx.Pipe(duplex=False)
            self._res = res_r
            self._ring = ctx.RawArray("B", self.ring_ticks * self._rowsize)
            self._idx = ctx.RawArray("q", IDX_SLOTS)
            if operator is not None:
                req_r, req_w = ctx.Pipe(duplex=False)
                self.inbox = RequestInbox(self._idx, req_r)
                rep_r, self._rep = ctx.Pipe(duplex=False)  # the loop's reports (`event`), apart from the rows
            self._proc = ctx.Process(
                target=writer_process.main,
                args=(ctl_r, res_w, spec, self._ring, self._idx, req_w, rep_r),
                name=f"imbench-daq-writer[{self.path.name}]",
                daemon=False,  # a daemon would be terminated at exit before finishing the file
            )
            # the child starts deaf to terminal keys (Ctrl-Z would stop it, Ctrl-\ kill it), and a signal while
            # start() hands it its start-up data (which would leave it reading a half-written pipe, with a
            # multiprocessing traceback on stderr) is raised right after: bench.core.shutdown.spawning
            with spawning():
                self._proc.start()
            ctl_r.close()  # only the writer keeps the read end ...
            res_w.close()  # ... and the result write end, so EOF works both ways
            if req_w is not None:
                req_w.close()
                rep_r.close()
        except BaseException:  # e.g. Ctrl-C during start-up: leave no writer waiting on an open pipe
            self._abandon()
            raise

    def _await_ready(self, start_timeout: float, start_method: str) -> dict:
        """The writer's ``ready`` event; a start-up failure closes this writer and raises `LogWriterError`."""
        try:
            ready = self._wait_result(start_timeout)
        except BaseException:
            self._abandon()
            raise
        if ready is None or ready.get("event") != "ready":
            self._closed = True
            self.put = self._put_closed  # type: ignore[method-assign]
            self._conn.close()
            self._proc.join(5)
            detail = (ready or {}).get("error") or (
                f"writer process exited (code {self._proc.exitcode}) before it was ready"
                + (". With start_method='forkserver' a main script that creates a LogWriter at import time "
                   "needs `if __name__ == '__main__':`" if start_method == "forkserver" else "")
            )
            raise LogWriterError(f"writer process for {self.path} failed to start:\n{detail}")
        return ready

    def panel_source(self) -> Any:
        """The shared index array whose slots PANEL.. the writer fills with bench.daq.live.PANEL_FIELDS
        once per block (for a drawing process; the loop never touches them), or None if not asked."""
        return self._idx if self._panel else None

    # ------------------------------------------------------------------ loop side
    def put(self, t_ns: int, values: Sequence[float]) -> None:
        """Log one tick: ``values`` is the concatenation of all topics' fields, in topic order.

        ``t_ns`` (int) becomes log_time = publish_time of every topic's message. Ints and bools
        may be given as Python ints, bools or floats; they travel as float64 (exact to 2**53).
        (With ``timing=True`` the instance's ``put`` is the timed twin of this method.)
        """
        try:
            self._pack(self._ring, self._off, t_ns, *values)
        except struct.error as e:
            raise self._bad_row(t_ns, values, e) from None
        self._off += self._rowsize
        if self._off >= self._batch_end:
            self._publish()

    def _put_timed(self, t_ns: int, values: Sequence[float]) -> None:
        t0 = _now()
        try:
            self._pack(self._ring, self._off, t_ns, *values)
        except struct.error as e:
            raise self._bad_row(t_ns, values, e) from None
        self._off += self._rowsize
        if self._off >= self._batch_end:
            self._publish()
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
        self._put_after_loss += 1

    def _put_closed(self, t_ns: int, values: Sequence[float]) -> None:
        raise ValueError(f"put() on a closed LogWriter ({self.path})")

    def _publish(self) -> None:
        """Make the rows packed since the last publication visible to the writer, then make
        sure the ring has room up to the next batch boundary (waiting for the writer if not)."""
        off = self._off
        n = (off - self._pub_off) // self._rowsize
        if n == 0:
            return
        head = self._head + n
        if self.notify:
            self._control(b"h" + head.to_bytes(8, "little", signed=True))
        else:
            self._idx[HEAD] = head  # one aligned 8-byte store: atomic, ordered after the rows (TSO)
        self._head = head
        self._publishes += 1
        if off >= self._ring_bytes:
            off = 0
        self._off = self._pub_off = off
        self._batch_end = min(off + self._batch_bytes, self._ring_bytes)
        tail = self._idx[TAIL]
        if head - tail > self._queue_hw:
            self._queue_hw = head - tail
        if not self._proc.is_alive():  # one waitpid(WNOHANG) per batch: a dead writer is a fault at once
            self._writer_lost(self._death())
            return
        # the next rows go to slots head .. head + k - 1; the writer frees slots below tail + cap;
        # until a fault, the last reserve_ticks slots count as full
        cap = self.ring_ticks if self.fault else self.ring_ticks - self.reserve_ticks
        if head + (self._batch_end - off) // self._rowsize - cap > tail:
            self._wait_for_room(cap)

    def _wait_for_room(self, cap: int) -> None:
        need = self._head + (self._batch_end - self._off) // self._rowsize - cap
        t0 = _now()
        limit = t0 + int(self.max_wait * 1e9)
        self._stalls += 1
        while self._idx[TAIL] < need:
            if not self._proc.is_alive():  # never stall forever on a dead writer
                self._writer_lost(self._death())
                break
            if _now() >= limit:
                if self.fault is None:  # go on into the reserve; the session trips at the next tick
                    self._declare_fault(self._stall_reason())
                else:  # the reserve is full too: drop from here on, never block the loop
                    self._writer_lost(self.fault)
                break
            time.sleep(0.0002)
        dt = _now() - t0
        if dt > self._stall_ns_max:
            self._stall_ns_max = dt

    def _stall_reason(self) -> str:
        """One line: how much the full ring holds (loop time and rows), and why the writer fell behind
        (`bench.daq.diagnose.stall_cause`: CPU starvation, the disk, a stopped writer, ...)."""
        rows = self.ring_ticks - self.reserve_ticks
        size = f"{rows} rows"
        try:
            tail = int(self._idx[TAIL])
            if self._head > tail:  # the loop time the unwritten rows span
                first = struct.unpack_from("<q", self._ring, (tail % self.ring_ticks) * self._rowsize)[0]
                newest = struct.unpack_from("<q", self._ring, ((self._head - 1) % self.ring_ticks) * self._rowsize)[0]
                size = f"{(newest - first) / 1e9:.1f} s, {rows} rows"
            cause = diagnose.stall_cause(self._idx, self.writer_pid)
        except Exception as exc:  # noqa: BLE001 - the trip must happen whatever the diagnosis does
            cause = f"cause unknown ({type(exc).__name__}: {exc})"
        waited = f" and nothing was freed for {self.max_wait:g} s" if self.max_wait else ""
        return f"log writer stalled: its ring ({size}) is full{waited}: {cause}"

    def _death(self) -> str:
        """Why the writer process is gone: its own last word (e.g. a full disk), else its exit code."""
        why = f"exit code {self._proc.exitcode}"
        try:
            if self._res.poll(0):
                self._result = self._res.recv()
                lines = [ln for ln in str(self._result.get("error", "")).splitlines() if ln.strip()]
                why = lines[-1].strip() if lines else why
        except (EOFError, OSError):
            pass
        return f"log writer died ({why})"

    def _declare_fault(self, reason: str) -> None:
        if self.fault is None:
            self.fault = reason
            if self.on_fault is not None:
                self.on_fault(reason)

    def _writer_lost(self, reason: str = "log writer gone") -> None:
        self._failed = True
        self.put = self._put_dropping  # type: ignore[method-assign]
        self._declare_fault(reason)

    def _abandon(self) -> None:
        """Start-up failed or was interrupted: close our pipe ends and end the writer process."""
        self._closed = True
        self.put = self._put_closed  # type: ignore[method-assign]
        for c in (self._conn, self._res, self._rep):
            if c is not None:
                try:
                    c.close()
                except OSError:
                    pass
        if self._proc is not None and self._proc.pid is not None:
            self._proc.join(2.0)  # EOF finishes an already running writer
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(2.0)

    def abort(self) -> None:
        """Kill a writer that does not finish (stalled); the file keeps every complete chunk."""
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
            self._proc.join(5.0)

    def flush(self, chunk: bool = False) -> None:
        """Publish the partial batch now (bounds loss on a loop crash to later puts).

        ``chunk=True`` also makes the writer write everything published, close its current
        MCAP chunk and flush the file to the OS, which bounds loss if the *writer* is
        killed, at some cost in compression. Both cost the loop a little; neither waits.
        """
        if self._closed or self._failed:
            return
        self._publish()
        if chunk:
            self._control(b"flush")

    def add_metadata(self, name: str, entries: Mapping[str, Any]) -> None:
        """Write another metadata record mid-run or at the end (e.g. results, trip reasons)."""
        if self._closed or self._failed:
            raise LogWriterError("add_metadata() on a closed or failed LogWriter")
        if name in _RESERVED:
            raise ValueError(f"metadata name {name!r} is reserved")
        ((rec_name, rec),) = encode_metadata({name: entries}).items()
        self._control(b"meta" + json.dumps([rec_name, rec]).encode())

    def event(self, ev: Mapping[str, Any]) -> None:
        """A parameter change or operator action the loop applied or refused (bench.operate.operator), for
        /params or /events; ``ev["log_time"]`` [ns] places it. Never raises (the log's health is
        watched elsewhere). A run that takes requests sends it on its own pipe, which the writer reads at once
        (the live server answers the client even while the writer catches up on rows), and counts it in
        ``REPORTED``."""
        if not (self._closed or self._failed):
            try:
                data = json.dumps(ev, default=str).encode()
                if self._rep is None:
                    self._control(b"ev" + data)
                    return
                self._rep.send_bytes(data)
                self._idx[REPORTED] += 1
            except Exception:  # noqa: BLE001 - e.g. a value JSON cannot take, a writer gone: the report is lost, not the run
                pass

    def attach(self, name: str, media_type: str, text: str) -> None:
        """Store a text file (e.g. the run summary) as an MCAP attachment."""
        if self._closed or self._failed:
            raise LogWriterError("attach() on a closed or failed LogWriter")
        self._control(b"att" + json.dumps([name, media_type, text]).encode())

    def _control(self, cmd: bytes) -> None:
        if self._torn or self._failed:
            return
        try:
            self._conn.send_bytes(cmd)
        except OSError:  # writer gone
            self._writer_lost("log writer gone (control pipe closed)")
        except BaseException:  # Ctrl-C mid-frame: nothing more may follow on the pipe
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
            except (EOFError, OSError):  # the writer closed its end without a word: it died or is dying
                self._proc.join(min(5.0, max(remaining, 0.1)))  # reaped: the exit code tells how it ended
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
            if self._rep is not None:  # every report is out: the writer logs them before it finishes
                self._rep.close()
            if not self._failed:
                self._publish()
                self._control(b"close")
            self.put = self._put_closed  # type: ignore[method-assign]
            self._conn.close()  # EOF finishes the writer even if the close frame was lost
        if self._result is None:
            t0 = time.monotonic()
            res = self._wait_result(self._close_timeout)
            if res is None and self._proc.is_alive():
                waited = time.monotonic() - t0
                raise LogWriterError(f"writer for {self.path} did not finish within {waited:.0f} s"
                                     if waited >= self._close_timeout else
                                     f"writer for {self.path} ended without finishing the file")  # fmt: skip
            self._result = res if res is not None else {"event": "lost"}
            self._proc.join(self._close_timeout)
        if self._result.get("event") != "done" and self._in_file is None:  # what really reached the file
            self._in_file = self._rows_in_file()
            handed = self._head + (self._off - self._pub_off) // self._rowsize  # put before the writer was lost
            self._unwritten = max(0, handed - self._in_file)
        res = self._result
        if res.get("event") != "done":
            detail = res.get("error") or f"exit code {self._proc.exitcode}"
            raise LogWriterError(f"writer process for {self.path} failed:\n{detail}")
        if self._put_after_loss:
            raise LogWriterError(f"{self._put_after_loss} rows were dropped for {self.path}")
        return res

    def _rows_in_file(self) -> int:
        """Rows the file really holds (a failed writer's file keeps its complete chunks only): read back."""
        try:
            return len(LogReader(self.path).read(self.topics[0].name, ns=True)["log_time"])
        except Exception:  # noqa: BLE001 - not even a header (e.g. a full disk from the start)
            return 0

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
        pending = (self._off - self._pub_off) // self._rowsize
        written = int(self._idx[TAIL])
        out: dict[str, Any] = {
            "rows_put": self._head + pending + self._put_after_loss,
            "rows_published": self._head,
            "rows_pending": pending,
            "rows_written": written,
            "publishes": self._publishes,
            "writer_pieces": int(self._idx[PIECES]),
            "chunk_flushes": int(self._idx[FLUSHES]),
            "ring_ticks": self.ring_ticks,
            "queue_hw_rows": self._queue_hw,
            "stalls": self._stalls,
            "stall_us_max": self._stall_ns_max / 1e3,
            "dropped": self._put_after_loss + self._unwritten,
            "writer_failed": self._failed,
            "notify": self.notify,
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
            lines = [ln.strip() for ln in str(self._result.get("error") or "").splitlines() if ln.strip()]
            if lines:  # a traceback: its last line says what went wrong (the exception raised from close() has more)
                out["writer"]["error"] = lines[-1]
            if "rows" in self._result:
                out["rows_written"] = self._result["rows"]
        if self._in_file is not None:  # the writer failed: what the file holds, not what it was given
            out["rows_written"] = self._in_file
        return out
