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

import bisect
import json
import math
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from .schema import Topic
from .events import EVENTS, PARAMS, schema_text

STATUS_PERIOD_NS = 100_000_000  # /status every 0.1 s of loop time
STATUS_TYPE = "imbench_msgs/msg/Status"  # /status's schema name: the same in every run (a layout may refer to it)
STATUS_SCHEMA = {
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "loop time [s]"},
        "tick": {"type": "integer"},
        "deadline_misses": {"type": "integer", "description": "overruns + skipped ticks so far"},
        "latency_p99_us": {"type": "number", "description": "wake-up latency p99 over the last second [us]"},
        "tripped": {"type": "boolean"},
        "state": {"type": "string", "description": "supervisor: running, tripped; at the end: ended or tripped"},
        "trip_cause": {"type": "string", "description": "why the run tripped (known when it ends), else empty"},
        "rows_written": {"type": "integer", "description": "ticks written to the MCAP log"},
        "requests_requests": {"type": "integer", "description": "parameter sets and service calls received"},
        "requests_applied": {"type": "integer", "description": "... applied by the loop"},
        "requests_refused": {"type": "integer", "description": "... refused (checks, or by the loop)"},
        "requests_rate_limited": {"type": "integer", "description": "... refused by the rate limit (per client)"},
    },
}
# what the terminal panel shows (bench.runtime.session._draw_progress), in the writer's shared index array
PANEL_FIELDS = ("t", "omega_r", "omega_r_ref", "i_s", "i_mr", "deadline_misses", "latency_p99_us", "tripped",
                "rr_hat", "rr_gate", "switches", "last_switch", "last_switch_t")  # fmt: skip


def switch_codes(operator: dict | None) -> list[tuple[str, str]]:
    """(part, choice) of every switch a run can make, in a fixed order, from its parameter description
    (`bench.operate.requests.ParamSpace.describe`): the panel carries the last switch as an index into this list (the
    panel is a row of floats in shared memory), and the writer and the drawing process make the same list."""
    if not operator:
        return []
    choices = {d["name"]: d["choices"] or () for d in operator["params"]}
    return [(part, str(c)) for part in operator.get("switchable", ()) for c in choices.get(part, ())]


class LoopStats:
    """How the loop is doing, derived from the logged rows alone (the loop sends nothing extra).

    Deadline misses = rows flagged ``overrun`` + ticks missing between rows (skipped), as in
    bench.runtime.loop; wake-up latency p99 over the last second of loop time; the latest values of the
    panel's signals: omega_r is the controller's estimate (/ctrl.omega_hat) or the mock plant's
    truth, |i_s| the amplitude-invariant space-vector length sqrt(2/3 (i_a^2 + i_b^2 + i_c^2))
    (thesis 2.1, i_a + i_b + i_c = 0), i_mR the controller's estimate or else its reference; the on-line R_r
    estimate and its gate where the controller logs them (/ctrl.rr_hat, rr_gate; else nan).
    """

    def __init__(self, topics: Sequence[Topic], switches: Sequence[tuple[str, str]] = ()) -> None:
        self.codes = list(switches)  # `switch_codes` of the run
        col, off = {}, 0
        for tp in topics:
            col.update({f"{tp.name}.{f}": off + j for j, f in enumerate(tp.field_names)})
            off += len(tp.field_names)

        def first(*names: str) -> int | None:
            return next((col[n] for n in names if n in col), None)

        self.ok = all(f"/rig.{n}" in col for n in ("t", "tick", "latency_us", "overrun", "tripped"))
        self._c = {n: col.get(f"/rig.{n}") for n in ("t", "tick", "latency_us", "overrun", "tripped", "omega_r_ref")}
        self._i = [col.get(f"/rig.{n}") for n in ("i_a", "i_b", "i_c")]
        self._w = first("/ctrl.omega_hat", "/truth.omega_r")
        self._imr = first("/ctrl.i_mr_hat", "/rig.i_mr_ref")
        self._rr = (first("/ctrl.rr_hat"), first("/ctrl.rr_gate"))
        self._lat: deque[tuple[np.ndarray, np.ndarray]] = deque()  # (t, latency) per block, of the last second
        self.misses = 0
        self.tick: int | None = None
        self.t = 0.0
        self.tripped = False
        self.last: np.ndarray | None = None
        self.switches, self.last_switch, self.last_switch_t = 0, math.nan, math.nan

    def event(self, ev: dict) -> None:
        """An applied part switch (a /params event of a switchable part) for the panel."""
        if ev.get("kind") != "set" or ev.get("status") != "applied":
            return
        codes = self.codes
        key = (str(ev.get("name")), str(ev.get("new")))
        if key in codes:
            self.switches += 1
            self.last_switch, self.last_switch_t = float(codes.index(key)), float(ev.get("t", math.nan))

    def update(self, vals: np.ndarray) -> None:
        """Fold in a block of rows ``(n, ncols)``."""
        if not self.ok or len(vals) == 0:
            return
        c = self._c
        first, last = int(vals[0, c["tick"]]), int(vals[-1, c["tick"]])
        prev = first - 1 if self.tick is None else self.tick
        # skipped ticks: the gaps between successive ticks, sum(diff(ticks) - 1), which telescopes
        self.misses += int(np.count_nonzero(vals[:, c["overrun"]])) + (last - prev - len(vals))
        self.tick = last
        self.t = float(vals[-1, c["t"]])
        self.tripped = bool(vals[-1, c["tripped"]])
        self.last = vals[-1]
        self._lat.append((vals[:, c["t"]].copy(), vals[:, c["latency_us"]].copy()))
        while self._lat and self._lat[0][0][-1] < self.t - 1.0:  # blocks wholly older than a second
            self._lat.popleft()

    def latency_p99_us(self) -> float:
        """p99 of the wake-up latency over the rows of the last second of loop time (t >= t_now - 1 s)."""
        if not self._lat:
            return 0.0
        t = np.concatenate([a for a, _ in self._lat])
        lat = np.concatenate([b for _, b in self._lat])[t >= self.t - 1.0]
        return float(np.percentile(lat, 99)) if lat.size else 0.0

    def panel(self) -> tuple[float, ...]:
        """The values of PANEL_FIELDS (nan where the rows do not have them)."""
        v = self.last
        if v is None:
            return (math.nan,) * len(PANEL_FIELDS)

        def at(j: int | None) -> float:
            return float(v[j]) if j is not None else math.nan

        i_s = math.sqrt(2 / 3 * sum(at(j) ** 2 for j in self._i)) if None not in self._i else math.nan
        return (self.t, at(self._w), at(self._c["omega_r_ref"]), i_s, at(self._imr), float(self.misses),
                self.latency_p99_us(), float(self.tripped), at(self._rr[0]), at(self._rr[1]), float(self.switches),
                self.last_switch, self.last_switch_t)  # fmt: skip


def panel_text(v: Sequence[float], switches: Sequence[tuple[str, str]] = ()) -> str:
    """One line of the terminal panel from the values of PANEL_FIELDS (``switches``: the run's `switch_codes`)."""
    t, w, w_ref, i_s, i_mr, misses, p99, tripped, rr, gate, n_sw, last, t_sw = (float(x) for x in v)
    if math.isnan(t):
        return "waiting for the first rows ..."
    rr_text = "" if math.isnan(rr) else f"  R_r {rr:5.2f} \u03a9 {'adapting' if gate == 0 else 'frozen'}"
    if n_sw > 0 and not math.isnan(last) and int(last) < len(switches):  # the last switch, when, how many so far
        part, choice = switches[int(last)]
        rr_text += f"  {part} \u2192 {choice} at {t_sw:.2f} s ({int(n_sw)} switch{'es' if n_sw > 1 else ''})"
    return (f"t {t:6.2f} s  \u03c9_r {w:6.1f} (ref {w_ref:6.1f}) rad/s  |i_s| {i_s:4.2f} A  i_mR {i_mr:4.2f} A  "
            f"misses {int(misses)}  lat p99 {p99:.1f} \u00b5s  {'TRIPPED' if tripped else 'running'}{rr_text}")


class LiveStream:
    """Foxglove server + one channel per log topic (decimated) + /status."""

    def __init__(self, topics: Sequence[Topic], host: str, port: int, every: int, control: Any = None) -> None:
        import foxglove


        extra = {}
        if control is not None:  # parameters and services (bench.daq.live_control)
            extra = {"capabilities": control.capabilities(), "server_listener": control,
                     "services": control.services(), "supported_encodings": ["json"]}  # fmt: skip
        self.server = foxglove.start_server(host=host, port=port, name="imbench", **extra)
        if control is not None:
            control.server = self.server
        self.control = control
        self.port = int(self.server.port)
        # /params and /events: the same messages as in the log, when the run takes requests
        self.event_channels = {name: foxglove.Channel(name, schema=foxglove.Schema(
            name=ty, encoding="ros2msg", data=schema_text(fields).encode()), message_encoding="cdr")
            for name, ty, fields in (PARAMS, EVENTS)} if control is not None else {}  # fmt: skip
        self.every = max(1, int(every))
        self.channels = [foxglove.Channel(tp.name, schema=foxglove.Schema(name=tp.type, encoding="ros2msg",
                                                                          data=tp.schema_text().encode()),
                                          message_encoding="cdr") for tp in topics]  # fmt: skip
        self.status = foxglove.Channel("/status", schema=foxglove.Schema(
            name=STATUS_TYPE, encoding="jsonschema", data=json.dumps(STATUS_SCHEMA).encode()), message_encoding="json")
        self._next_status: int | None = None  # log time of the next /status
        self._rows = 0
        self._last_ts = 0

    def publish(self, ts: list[int], a: int, b: int, layout: Any, rows: Any, stats: LoopStats, first: int) -> None:
        """Every ``every``-th row of rows ``a:b`` of a written block (log times ``ts``, records ``rows`` of
        `bench.daq.mcap_block.RowLayout` ``layout``; row ``k`` is the log's row ``first + k``), and the status
        when due (``stats`` holds the rows up to ``b``)."""
        start = a + (-(first + a)) % self.every
        for k in range(start, b, self.every):
            for j, ch in enumerate(self.channels):
                ch.log(layout.message(rows, k, j), log_time=ts[k])
        self._rows, self._last_ts = first + b, ts[b - 1]
        if stats.ok and ts[b - 1] >= self._due(ts[a]):
            self._next_status = self._after(self._next_status, ts[b - 1])
            self._status(stats, "tripped" if stats.tripped else "running", "")

    def _due(self, t0: int) -> int:
        if self._next_status is None:
            self._next_status = t0
        return self._next_status

    @staticmethod
    def _after(due: int, t: int) -> int:
        """The next /status instant: one period on (10 Hz of loop time), never in the past."""
        return max(due + STATUS_PERIOD_NS, t + 1)

    def segments(self, ts: list[int]) -> list[tuple[int, int]]:
        """A block's rows cut at the /status instants, so that a large block (the writer fell behind)
        still gives one /status per 0.1 s of loop time, each from the rows up to its instant."""
        out, a, due = [], 0, self._due(ts[0])
        while a < len(ts):
            i = bisect.bisect_left(ts, due, a)
            if i >= len(ts):
                out.append((a, len(ts)))
                break
            out.append((a, i + 1))
            a, due = i + 1, self._after(due, ts[i])
        return out

    def event(self, topic: str, data: bytes, log_time: int) -> None:
        """A /params or /events message (the log's bytes)."""
        ch = self.event_channels.get(topic)
        if ch is not None:
            ch.log(data, log_time=log_time)

    def _status(self, stats: LoopStats, state: str, cause: str) -> None:
        msg = {"t": stats.t, "tick": stats.tick if stats.tick is not None else -1, "deadline_misses": stats.misses,
               "latency_p99_us": stats.latency_p99_us(), "tripped": stats.tripped or state == "tripped",
               "state": state, "trip_cause": cause, "rows_written": self._rows}  # fmt: skip
        if self.control is not None:
            msg.update({f"requests_{k}": v for k, v in self.control.counts.items()})
        self.status.log(json.dumps(msg).encode(), log_time=self._last_ts or None)

    def ended(self, stats: LoopStats, shutdown: dict) -> None:
        """The last /status, from the log's ``shutdown`` record (bench.runtime.run_summary.close_log): the cause."""
        cause = str(shutdown.get("cause") or "")
        self._status(stats, "tripped" if cause else "ended", cause)

    def stop(self) -> None:
        if self.control is not None:  # answers the loop gave (an e-stop's) go out before the connections close
            self.control.settle()
        self.server.stop()


def stream_every(loop_rate_hz: float, live_rate_hz: float) -> int:
    """Decimation of the live stream: every N-th tick."""
    return max(1, int(round(loop_rate_hz / live_rate_hz)))


__all__ = ["LiveStream", "LoopStats", "PANEL_FIELDS", "panel_text", "STATUS_SCHEMA", "STATUS_TYPE", "stream_every"]
