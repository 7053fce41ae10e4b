"""The writer process: drains the shared-memory tick ring, packs whole MCAP records with numpy, writes MCAP.

Runs in its own interpreter (multiprocessing spawn/forkserver), so MCAP encoding and compression
never hold the loop's GIL. It ignores SIGINT, SIGTERM and SIGHUP (they belong to the loop
process, which then makes the rig safe and closes the log), runs at a lower priority (``nice``) so that waking it never preempts
the loop, and finishes the file -- summary, statistics, chunk and metadata indexes -- both
on an explicit ``close`` command and on pipe EOF, i.e. when the loop process exits or dies
without closing.

Shared with the loop process:

* ``ring``: ``ring_ticks`` rows, each ``<q`` tick time in ns followed by ``ncols`` ``<d``
  values; row ``k`` of the log lives in slot ``k % ring_ticks``;
* ``idx`` (int64): ``HEAD`` rows published by the loop, ``TAIL`` rows consumed here (the loop
  reuses a slot only below ``TAIL + ring_ticks``), plus counters.

Pipe (loop -> writer, ``Connection.send_bytes`` frames), control only: ``b"close"``,
``b"flush"``, ``b"meta" + json([name, {str: str}])``, ``b"att" + json([name, media type, text])`` and, in notify mode, ``b"h" + <q head``.
The writer polls ``HEAD`` every ``idle_s`` when idle, so publishing costs the loop one store
and no system call. A block of rows becomes MCAP records in a few numpy operations and reaches the
file's chunk in one write (`bench.daq.mcap_block`), where mcap's per-message ``add_message`` cost
~4 µs per message (docs/results/bench-core.md has the writer's CPU per row, before and after). The writer
samples its own CPU, run-queue wait and time in file writes into ``idx`` (`bench.daq.diagnose`), so
that a full ring can be explained; while more than an eighth of the ring waits, it drops its extra
niceness where the OS allows. That relies on the CPU making the loop's row stores visible before its
``HEAD`` store (x86-64: yes, TSO). Elsewhere the loop runs in *notify* mode and sends the new
head through the pipe, whose write/read pair orders memory.

Runs that take requests (bench.operate.operator) have two more pipes. Loop -> writer, reports: ``json(report)`` of each
parameter change or operator action the loop applied or refused, counted in ``REPORTED``; a thread of this
process takes them in at once (the live server answers its clients even while the main thread catches up on
rows) and the main thread logs them on /params or /events once the rows up to their tick are written (the file
stays in log-time order). (``b"ev" + json(report)`` on the control pipe does the same.) Writer -> loop:
checked requests (``bench.operate.requests.Request.encode``), ``POSTED`` counts them; e-stop and stop bypass the pipe:
``ESTOP`` and ``STOP`` hold the sequence number of the latest one.

Writer -> loop (second pipe, pickled dicts): ``{"event": "ready"}`` once the header,
metadata, schemas and channels are written, then a final ``{"event": "done", ...}`` with
statistics, or ``{"event": "error", "error": traceback}``.
"""

from __future__ import annotations

import heapq
import itertools
import json
import math
import os
import select
import sys
import threading
import time
import traceback
from typing import Any, Sequence

import numpy as np
from mcap.writer import CompressionType

from .diagnose import SLOTS_END, SelfSampler
from .mcap_block import BlockWriter, RowLayout
from .schema import CDR_HEADER, HEADER_FIELD, Topic
from bench.core.shutdown import child_ignores_signals
from .live import PANEL_FIELDS, LoopStats, switch_codes, LiveStream
from .events import encode, EVENTS, PARAMS, schema_text
from bench.operate.requests import ParamSpace
from .live_control import LiveControl

COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}

# slots of the shared int64 index array
HEAD, TAIL, PIECES, FLUSHES = 0, 1, 2, 3
POSTED = 4  # operator requests sent to the loop (bench.operate.operator): the loop drains its pipe when this moves
ESTOP, STOP = 5, 6  # the latest e-stop / stop request's sequence number (0: none); the loop reads them every tick
REPORTED = 7  # reports the loop has sent on its report pipe (a refusal by the live server first takes them in)
PANEL = 8  # slots PANEL.. hold bench.daq.live.PANEL_FIELDS as float64 (the terminal panel), when asked
# slots 21..29: the writer's own accounting, for the loop's diagnosis of a full ring (bench.daq.diagnose)
IDX_SLOTS = SLOTS_END
LIVE_STOP_S = 2.0  # [s] the live server gets to close its connections after the log is finished
MAX_PIECE = 1024  # rows packed at once
COALESCE_ROWS = 192  # the writer drains once this many rows wait (at most 1/8 of the ring), or ...
PANEL_PERIOD_S = 0.1  # [s of loop time] the terminal panel's values are refreshed this often (drawn at 5 Hz)
BACKLOG_RAISE = 8  # the writer drops its extra niceness while more than 1/8 of the ring waits (and may) ...
BACKLOG_CALM = 64  # ... and takes it again below 1/64


class Packer:
    """Vectorised CDR packing of ``(n, ncols)`` float64 rows into one message per topic per row, field by
    field: the reference for `bench.daq.mcap_block.RowLayout`, which packs whole MCAP records."""

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


def row_dtype(ncols: int) -> np.dtype:
    """One ring slot: the loop packs it with ``struct.Struct(f"<q{ncols}d")``."""
    return np.dtype([("t", "<i8"), ("v", "<f8", (ncols,))])


def _post(req_conn: Any, idx: Any, frame: bytes) -> bool:
    """A checked request to the loop: the frame first, then the count the loop watches. The pipe is
    non-blocking and a frame is at most PIPE_BUF bytes (bench.daq.live_control.MAX_FRAME), so it is
    written whole or not at all: a loop that no longer drains it (the run is ending) never blocks the
    server's thread, and never finds half a frame."""
    try:
        req_conn.send_bytes(frame)
    except (OSError, ValueError):  # full (the loop stopped taking requests) or gone
        return False
    idx[POSTED] += 1
    return True


def _flag(idx: Any, kind: str, seq: int) -> None:
    """An e-stop or stop for the loop: one store into shared memory, read at the loop's next tick."""
    idx[ESTOP if kind == "estop" else STOP] = seq


class _TimedFile:
    """The log file, with the time spent in its writes and flushes counted (a slow disk shows there)."""

    def __init__(self, f: Any, sampler: SelfSampler) -> None:
        self.f, self.sampler = f, sampler
        self.tell = f.tell

    def write(self, data: Any) -> int:
        s = self.sampler
        s.writing(True)
        t0 = time.perf_counter_ns()
        try:
            return self.f.write(data)
        finally:
            s.io_ns += time.perf_counter_ns() - t0
            s.writing(False)

    def flush(self) -> None:
        s = self.sampler
        s.writing(True)
        t0 = time.perf_counter_ns()
        try:
            self.f.flush()
        finally:
            s.io_ns += time.perf_counter_ns() - t0
            s.writing(False)

    def close(self) -> None:
        self.f.close()


def _send(conn: Any, msg: dict) -> None:
    try:
        conn.send(msg)
    except (OSError, ValueError):  # parent gone: nobody to tell
        pass


class _Run:
    """One writer process's run: the MCAP file opened with its schemas and channels, the ring, the live view and
    the loop's reports; `serve` drains the ring until the loop closes the log (or dies), `finish` ends the file
    and `done` is the statistics the loop gets."""

    def __init__(self, conn: Any, spec: dict, ring: Any, idx: Any, nice: int) -> None:
        """Open the file and write its header, metadata, attachments, schemas and channels (raises on failure)."""
        self.conn, self.spec, self.idx, self.nice = conn, spec, idx, nice
        self.sampler = SelfSampler(idx)
        self.topics = topics = [Topic(*t) for t in spec["topics"]]
        ncols = sum(len(tp.fields) for tp in topics)
        self.cap = cap = int(spec["ring_ticks"])
        self.slots = np.frombuffer(ring, row_dtype(ncols), count=cap)
        # default buffering: a finished chunk (~100 kB compressed) goes to the OS at once, so a killed
        # writer leaves every complete chunk readable (a 1 MiB buffer held the first seconds back)
        self.f = _TimedFile(open(spec["path"], "wb"), self.sampler)
        self.w = w = BlockWriter(self.f, chunk_size=spec["chunk_size"], compression=COMPRESSION[spec["compression"]])
        w.start(profile="ros2", library=spec["library"])  # ros2msg schemas, CDR messages: the ROS 2 profile
        for name, data in spec["metadata"].items():
            w.add_metadata(name, data)
        for name, media_type, data in spec.get("attachments", ()):
            now = time.time_ns()
            w.add_attachment(create_time=now, log_time=now, name=name, media_type=media_type, data=data)
        channel_ids = []
        for tp in topics:
            sid = w.register_schema(tp.type, "ros2msg", tp.schema_text().encode())
            channel_ids.append(w.register_channel(tp.name, "cdr", sid))
        self.layout = RowLayout(topics, channel_ids)
        w.blocks = w.blocks and bool(spec.get("blocks", True))
        self.event_ids: dict[str, int] = {}
        if spec.get("operator"):  # /params and /events (bench.daq.events)
            for name, ty, fields in (PARAMS, EVENTS):
                sid = w.register_schema(ty, "ros2msg", schema_text(fields).encode())
                self.event_ids[name] = w.register_channel(name, "cdr", sid)
        w.flush()  # header and metadata are on disk before the first tick (schemas, channels: first chunk)
        self.notify = bool(spec["notify"])
        self.notified = 0  # last head received in notify mode
        cols0 = [n for n, _ in topics[0].fields]
        self.tick_col, self.t_col = (cols0.index(n) if n in cols0 else None for n in ("tick", "t"))
        self.live = self.stats = self.panel = self.control = None
        self.reports: threading.Thread | None = None
        self.tail = 0
        self.busy = self.pack_s = 0.0
        self.cpu = {"pack": 0, "mcap": 0, "live": 0}  # [ns] main-thread CPU per stage
        self.pieces = 0
        self.renices = 0  # times the writer dropped its niceness to catch up
        self.raised = False
        self.backlog_hw = 0
        self.panel_due, self.panel_tripped = -math.inf, False  # the next panel refresh [s of loop time]; its state
        self.ended_by = "eof"
        self.last = {"ts": 0, "tick": -1, "t": math.nan}  # the newest row written
        self.event_seq = {name: 0 for name in self.event_ids}
        self.due: list[tuple[int, int, dict]] = []  # events to log once their tick is written: (log time, order, ev)
        self.due_lock = threading.Lock()
        self.order = itertools.count()

    def newest(self) -> tuple[int, float, int]:
        """(tick, t, log time) of the newest row the loop has published: where the live server logs a refusal."""
        head = self.current_head()
        if head <= 0 or self.tick_col is None or self.t_col is None:
            return -1, math.nan, 0
        row = self.slots[(head - 1) % self.cap]
        return int(row["v"][self.tick_col]), float(row["v"][self.t_col]), int(row["t"])

    def current_head(self) -> int:
        return self.notified if self.notify else int(self.idx[HEAD])

    def start_live(self, req_conn: Any) -> None:
        """/status and the terminal panel, derived from the rows; the live view (bench.daq.live), with the
        operator's parameters and services where the run takes requests (raises on failure: a start-up failure)."""
        spec, idx = self.spec, self.idx
        if spec.get("live") or spec.get("panel"):
            self.stats = LoopStats(self.topics, switch_codes(spec.get("operator")))
            if spec.get("panel"):
                self.panel = np.frombuffer(idx, np.float64)[PANEL : PANEL + len(PANEL_FIELDS)]
                self.panel[:] = np.nan  # "no rows yet"
        if not spec.get("live"):
            return
        lv = spec["live"]
        control = None
        if spec.get("operator") and req_conn is not None:  # parameters and services
            os.set_blocking(req_conn.fileno(), False)
            control = LiveControl(ParamSpace.from_description(spec["operator"]),
                                  lambda frame: _post(req_conn, idx, frame),
                                  lambda kind, seq: _flag(idx, kind, seq), self.newest,
                                  lambda: int(idx[REPORTED]))  # fmt: skip
        self.live = LiveStream(self.topics, lv["host"], int(lv["port"]), int(lv["every"]), control)
        self.control = self.live.control

    def start_reports(self, rep_conn: Any) -> None:
        """A thread that takes in the loop's reports as they come (the live server answers at once)."""
        if rep_conn is None:
            return

        def read_reports() -> None:
            while True:
                try:
                    data = rep_conn.recv_bytes()
                except (EOFError, OSError):  # the loop closed its end (or died): every report is in
                    return
                try:
                    self.take_report(json.loads(data))
                except Exception:  # noqa: BLE001 - a report that cannot be read is lost, not the log
                    pass

        self.reports = threading.Thread(target=read_reports, name="reports", daemon=True)
        self.reports.start()

    def take_report(self, ev: dict) -> None:
        """A report of the loop: answered at once (the live server), logged in its place (`log_due`)."""
        if self.control is not None:  # first: it names the client of a flagged e-stop or stop
            self.control.reported(ev)
        with self.due_lock:
            heapq.heappush(self.due, (int(ev.pop("log_time")), next(self.order), ev))

    def log_event(self, ev: dict, log_time: int) -> None:
        topic, data = encode(ev)
        cid = self.event_ids.get(topic)
        if cid is None:
            return
        self.w.add_message(cid, log_time, data, log_time, self.event_seq[topic] & 0xFFFFFFFF)
        self.event_seq[topic] += 1
        if self.live is not None:
            self.live.event(topic, data, log_time)

    def log_due(self, final: bool = False) -> None:
        """Log the reports and refusals whose tick is written (``final``: all that are left)."""
        control, due = self.control, self.due
        with self.due_lock:
            while control is not None and control.refusals:  # decided at a tick the loop had published
                ev = control.refusals.popleft()
                heapq.heappush(due, (int(ev.pop("log_time")), next(self.order), ev))
            out = []
            while due and (final or due[0][0] <= self.last["ts"]):
                out.append(heapq.heappop(due))
        for log_time, _, ev in out:
            if self.stats is not None:  # a part switch, for the terminal panel
                self.stats.event(ev)
            self.log_event(ev, log_time)

    def write_rows(self, block: np.ndarray, first: int) -> None:
        """One MCAP message per topic per row, tick-major so the file is in log-time order;
        sequence = row index (uint32, wraps) so gaps show per channel."""
        live, stats, panel, last = self.live, self.stats, self.panel, self.last
        c0 = time.thread_time_ns()
        t0 = time.perf_counter()
        t = block["t"]
        vals = block["v"]
        rows = self.layout.pack_ring(block, first)  # copies out of the ring
        self.pack_s += time.perf_counter() - t0
        c1 = time.thread_time_ns()
        self.w.add_rows(self.layout, rows)
        c2 = time.thread_time_ns()
        last["ts"] = int(t[-1])
        if self.tick_col is not None and self.t_col is not None:
            last["tick"], last["t"] = int(vals[-1, self.tick_col]), float(vals[-1, self.t_col])
        if live is not None:  # cut at the /status instants: 10 Hz of loop time whatever the block size
            ts = t.tolist()
            for a, b in live.segments(ts):
                stats.update(vals[a:b])
                live.publish(ts, a, b, self.layout, rows, stats, first)
        elif stats is not None:
            stats.update(vals)
        if panel is not None and (stats.t >= self.panel_due or stats.tripped != self.panel_tripped):
            panel[:] = stats.panel()  # its latency p99 sorts a second of rows: at 10 Hz, not per block
            self.panel_due, self.panel_tripped = stats.t + PANEL_PERIOD_S, stats.tripped
        cpu = self.cpu
        cpu["pack"] += c1 - c0
        cpu["mcap"] += c2 - c1
        cpu["live"] += time.thread_time_ns() - c2

    def pace(self, head: int) -> None:
        """Drop the extra niceness while the backlog is large (where allowed), take it again once caught up."""
        backlog = head - self.tail
        self.backlog_hw = max(self.backlog_hw, backlog)
        if self.nice <= 0:
            return
        if not self.raised and backlog * BACKLOG_RAISE > self.cap:
            try:
                os.setpriority(os.PRIO_PROCESS, 0, 0)  # this thread (Linux): the one that drains
                self.raised, self.renices = True, self.renices + 1
            except OSError:  # not permitted (no CAP_SYS_NICE): stays nice
                pass
        elif self.raised and backlog * BACKLOG_CALM < self.cap:
            try:
                os.setpriority(os.PRIO_PROCESS, 0, self.nice)
            except OSError:
                pass
            self.raised = False

    def drain(self, head: int) -> None:
        """Write the rows up to ``head``, in pieces of at most `MAX_PIECE`, freeing their slots as it goes."""
        self.pace(head)
        cap, idx = self.cap, self.idx
        while self.tail < head:
            t0 = time.perf_counter()
            tail = self.tail
            s = tail % cap
            n = min(head - tail, cap - s, MAX_PIECE)
            self.write_rows(self.slots[s : s + n], tail)
            if tail == 0:  # close the first chunk at once: schemas and channels reach the disk with it
                self.w.flush()
            self.tail = tail + n
            idx[TAIL] = self.tail  # slots below tail + cap are free again
            self.pieces += 1
            idx[PIECES] = self.pieces
            self.busy += time.perf_counter() - t0
            self.log_due()  # the requests of these ticks, in their place, also while the writer catches up
            self.sampler.sample()

    def serve(self) -> str | None:
        """Drain the ring and obey the control pipe until ``close`` or EOF; then everything the loop published
        and every report. Returns the traceback of a failure (None: none)."""
        spec, idx, conn, w, live = self.spec, self.idx, self.conn, self.w, self.live
        notify = self.notify
        poller = select.poll()  # one poll object: multiprocessing's Connection.poll builds a selector per call
        poller.register(conn.fileno(), select.POLLIN)
        idle_s = float(spec["idle_s"])
        idle_ms = None if notify and self.control is None and self.reports is None else max(1, round(idle_s * 1e3))
        # ... once the first of them has waited coalesce_s: every drain starts with cold caches (after 21 ms
        # asleep, packing a 64-row block cost 3x what it costs back to back), so fewer, larger drains
        coalesce_rows = max(1, min(COALESCE_ROWS, self.cap // 8))
        coalesce_ns = int(float(spec.get("coalesce_s", 0.0)) * 1e9)
        pending_since = 0  # monotonic ns when the writer first saw rows it has not drained (0: none)
        try:
            while True:
                wait_ms = idle_ms
                if not notify:
                    head = int(idx[HEAD])
                    if head > self.tail:
                        now = time.monotonic_ns()
                        pending_since = pending_since or now
                        if head - self.tail >= coalesce_rows or now - pending_since >= coalesce_ns:
                            self.drain(head)
                            pending_since = 0
                            continue
                        wait_ms = max(1, min(idle_ms, -(-(pending_since + coalesce_ns - now) // 1_000_000)))
                self.log_due()
                self.sampler.sample()
                if not poller.poll(wait_ms):
                    continue
                try:
                    cmd = conn.recv_bytes()
                except (EOFError, OSError):  # loop closed the pipe or died (maybe mid-frame)
                    break
                if cmd[:1] == b"h":
                    self.notified = int.from_bytes(cmd[1:9], "little", signed=True)
                    self.drain(self.notified)
                elif cmd == b"close":
                    self.ended_by = "close"
                    break
                elif cmd == b"flush":
                    self.drain(self.current_head())
                    w.flush()
                    idx[FLUSHES] += 1
                elif cmd.startswith(b"meta"):
                    name, data = json.loads(cmd[4:])
                    w.add_metadata(name, data)
                    if live is not None and name == "shutdown":  # how the run ended: the last /status
                        self.drain(self.current_head())
                        live.ended(self.stats, data)
                elif cmd.startswith(b"ev"):
                    self.take_report(json.loads(cmd[2:]))
                elif cmd.startswith(b"att"):
                    name, media_type, text = json.loads(cmd[3:])
                    now = time.time_ns()
                    w.add_attachment(create_time=now, log_time=now, name=name, media_type=media_type,
                                     data=text.encode())  # fmt: skip
                else:
                    raise ValueError(f"unknown control frame {cmd[:16]!r}")
            self.drain(self.current_head())  # everything the loop published before it closed or died
            if self.reports is not None:  # the loop closes its report pipe before it closes the log (or died)
                self.reports.join(LIVE_STOP_S)
            self.log_due(final=True)
            if self.panel is not None:
                self.panel[:] = self.stats.panel()
        except BaseException:
            return traceback.format_exc()
        return None

    def finish(self) -> str | None:
        """Finish the file (summary, indexes), then stop the live server; the traceback of a failure, or None."""
        error = None
        try:
            self.w.finish()
            self.f.close()
        except BaseException:
            error = traceback.format_exc()
        if self.live is not None:  # after the log is complete: foxglove's stop() waits for a client that never reads
            stopper = threading.Thread(target=self.live.stop, daemon=True)
            stopper.start()
            stopper.join(LIVE_STOP_S)  # then the process exit ends the server
        return error

    def done(self, cpu0: float, wall0: float) -> dict:
        """The run's statistics for the loop (the ``done`` event)."""
        tail = self.tail
        return {
            "event": "done",
            "ended_by": self.ended_by,
            "rows": tail,
            "messages": tail * len(self.topics),
            "pieces": self.pieces,
            "busy_s": self.busy,
            "pack_s": self.pack_s,
            "cpu_s": time.process_time() - cpu0,  # all threads, the live server's included
            "wall_s": time.perf_counter() - wall0,
            "cpu_us_per_row": {k: v / 1e3 / max(tail, 1) for k, v in self.cpu.items()},  # main thread, per stage
            "backlog_hw_rows": self.backlog_hw,
            "renices": self.renices,
            "io_s": self.sampler.io_ns / 1e9,
            "file_bytes": os.path.getsize(self.spec["path"]),
            "requests": dict(self.control.counts) if self.control is not None else None,
        }


def main(conn: Any, result_conn: Any, spec: dict, ring: Any, idx: Any, req_conn: Any = None,
         rep_conn: Any = None) -> None:  # fmt: skip
    """Process entry point. ``spec``: path, topics, metadata, chunk_size, compression, library,
    ring_ticks, notify, idle_s, nice, live, panel, operator."""
    # Ctrl-C, Ctrl-Z, Ctrl-\, a closed terminal (SIGHUP) or a SIGTERM to the process group are the
    # loop process's to handle: it makes the rig safe and then closes the log. The writer finishes the
    # file on the close frame or on pipe EOF (the loop process exited or died), never half-way.
    child_ignores_signals()
    nice = int(spec.get("nice", 0))
    try:
        os.nice(nice)
    except OSError:
        pass
    try:  # a failure to open the log or to serve the live view is a start-up failure
        run = _Run(conn, spec, ring, idx, nice)
        run.start_live(req_conn)
    except BaseException:
        _send(result_conn, {"event": "error", "error": traceback.format_exc()})
        sys.exit(1)
    _send(result_conn, {"event": "ready", "pid": os.getpid(), "live_port": run.live.port if run.live else None})
    cpu0, wall0 = time.process_time(), time.perf_counter()
    run.start_reports(rep_conn)
    error = run.serve()
    finish_error = run.finish()
    if error or finish_error:
        _send(result_conn, {"event": "error", "error": error or finish_error, "rows": run.tail})
        sys.exit(1)
    _send(result_conn, run.done(cpu0, wall0))
