"""The live view of a running session: a Foxglove WebSocket server fed by the log writer process.

Runs inside the writer process (bench.daq.writer_process), which already receives every tick and
packs its CDR messages: the server sends every N-th of those same messages (`rate_hz`), so /rig,
/ctrl and /truth have the MCAP log's schemas and field names and one Foxglove layout serves a live
run and a recorded one. /status (JSON, about 10 Hz of loop time) says how the loop is doing. The
loop process never waits for any of it: foxglove-sdk serves clients from its own threads with
bounded per-client queues (a client that does not read loses messages, it does not stall anyone),
and if the writer itself fell behind, the loop's ring would tell (bench.daq.writer).

The protocol has no authentication: the server binds 127.0.0.1 unless asked otherwise.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from .schema import Topic

STATUS_PERIOD_NS = 100_000_000  # /status every 0.1 s of loop time
STATUS_SCHEMA = {
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "loop time [s]"},
        "tick": {"type": "integer"},
        "deadline_misses": {"type": "integer", "description": "overruns + skipped ticks so far"},
        "latency_p99_us": {"type": "number", "description": "wake-up latency p99 over the last second [us]"},
        "tripped": {"type": "boolean"},
        "rows_written": {"type": "integer", "description": "ticks written to the MCAP log"},
    },
}


class LiveStream:
    """Foxglove server + one channel per log topic (decimated) + /status."""

    def __init__(self, topics: Sequence[Topic], host: str, port: int, every: int) -> None:
        import foxglove

        self.server = foxglove.start_server(host=host, port=port, name="imbench")
        self.port = int(self.server.port)
        self.every = max(1, int(every))
        self.channels = [foxglove.Channel(tp.name, schema=foxglove.Schema(name=tp.type, encoding="ros2msg",
                                                                          data=tp.schema_text().encode()),
                                          message_encoding="cdr") for tp in topics]  # fmt: skip
        self.status = foxglove.Channel("/status", schema=STATUS_SCHEMA)
        rig = topics[0].field_names  # /rig first (bench.loop.log_topics)
        self._col = {name: rig.index(name) for name in ("t", "tick", "latency_us", "overrun", "tripped")
                     if name in rig}  # fmt: skip
        self._lat: deque[tuple[float, float]] = deque()  # (t, latency) of the last second
        self._misses = 0
        self._last_tick: int | None = None
        self._next_status: int | None = None  # log time of the next /status

    def publish(self, ts: list[int], per_topic: Sequence[list[bytes]], vals: np.ndarray, first: int) -> None:
        """Every ``every``-th row of a written block, and the status when due."""
        start = (-first) % self.every
        for k in range(start, len(ts), self.every):
            for ch, msgs in zip(self.channels, per_topic):
                ch.log(msgs[k], log_time=ts[k])
        if len(self._col) == 5:
            self._status(ts, vals, first)

    def _status(self, ts: list[int], vals: np.ndarray, first: int) -> None:
        """One /status per 0.1 s of loop time, each computed from the rows up to its instant (a large
        block, written after the writer fell behind, still gives 10 Hz of loop time)."""
        start = 0
        if self._next_status is None:
            self._next_status = ts[0]
        while start < len(ts):
            if ts[-1] < self._next_status:
                self._account(vals[start:])
                return
            end = int(np.searchsorted(np.asarray(ts[start:]), self._next_status, side="left")) + start + 1
            self._account(vals[start:end])
            self._publish_status(ts[end - 1], vals[end - 1], first + end)
            self._next_status = max(self._next_status + STATUS_PERIOD_NS, ts[end - 1] + 1)
            start = end

    def _account(self, vals: np.ndarray) -> None:
        if not len(vals):
            return
        c = self._col
        ticks = vals[:, c["tick"]].astype(np.int64)
        prev = ticks[0] - 1 if self._last_tick is None else self._last_tick
        self._misses += int(np.sum(vals[:, c["overrun"]] != 0)) + int(np.sum(np.diff(ticks, prepend=prev) - 1))
        self._last_tick = int(ticks[-1])
        self._lat.extend(zip(vals[:, c["t"]].tolist(), vals[:, c["latency_us"]].tolist()))
        t_end = float(vals[-1, c["t"]])
        while self._lat and self._lat[0][0] < t_end - 1.0:
            self._lat.popleft()

    def _publish_status(self, log_time: int, row: np.ndarray, rows_written: int) -> None:
        c = self._col
        lat = np.fromiter((x for _, x in self._lat), float) if self._lat else np.zeros(1)
        self.status.log({"t": float(row[c["t"]]), "tick": self._last_tick, "deadline_misses": self._misses,
                         "latency_p99_us": float(np.percentile(lat, 99)), "tripped": bool(row[c["tripped"]]),
                         "rows_written": rows_written}, log_time=log_time)  # fmt: skip

    def stop(self) -> None:
        self.server.stop()


def stream_every(loop_rate_hz: float, live_rate_hz: float) -> int:
    """Decimation of the live stream: every N-th tick."""
    return max(1, int(round(loop_rate_hz / live_rate_hz)))


__all__ = ["LiveStream", "STATUS_SCHEMA", "stream_every"]
