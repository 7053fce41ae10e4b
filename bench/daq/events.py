"""The event topics of a run log: /params (parameter changes) and /events (operator actions).

One message per change (a request of several changes: one each, with the request's ``seq``) or action, applied or
refused, at the log time of the tick it was decided at: applied or refused by the loop, or refused by the live
server before it reached the loop (then the newest tick the loop had published, with the value in force then).
Written by the log writer process (bench.daq.writer_process) from the loop's reports (bench.operate.operator), served
live on the same topics, and read back by `LogReader.events` (e.g. for ``--replay-params``, which applies the
changes of one request together again).
"""

from __future__ import annotations

import math
from typing import Any

from .schema import decode_cdr, encode_cdr

PARAMS = ("/params", "imbench_msgs/msg/ParamChange", (
    ("tick", "int64"), ("t", "float64"), ("name", "string"), ("old_value", "float64"), ("new_value", "float64"),
    ("old_text", "string"), ("new_text", "string"), ("who", "string"), ("status", "string"), ("seq", "int64")))
EVENTS = ("/events", "imbench_msgs/msg/OperatorEvent", (
    ("tick", "int64"), ("t", "float64"), ("kind", "string"), ("note", "string"), ("who", "string"),
    ("status", "string"), ("seq", "int64")))  # fmt: skip
COMMENTS = {"t": "  # [s] loop time of the tick it was decided at (applied or refused)",
            "seq": "  # the request's number: one for all the changes of a request",
            "old_value": "  # as a number (nan: 'off' or not a number; old_text/new_text are exact)",
            "status": "  # applied, or refused: why",
            "kind": "  # stop, estop or mark"}  # fmt: skip


def schema_text(fields: tuple[tuple[str, str], ...]) -> str:
    return "".join(f"{t} {n}{COMMENTS.get(n, '')}\n" for n, t in fields)


def _number(v: Any) -> float:
    if isinstance(v, bool):
        return float(v)
    return float(v) if isinstance(v, (int, float)) else math.nan


def _text(v: Any) -> str:
    return "" if v is None else repr(v) if isinstance(v, float) else str(v)


def encode(ev: dict[str, Any]) -> tuple[str, bytes]:
    """(topic, CDR message) of one report of bench.operate.operator.Operator (or a writer-side refusal)."""
    if ev["kind"] == "set":
        vals = (ev["tick"], ev["t"], ev["name"], _number(ev["old"]), _number(ev["new"]), _text(ev["old"]),
                _text(ev["new"]), ev["who"], ev["status"], ev["seq"])  # fmt: skip
        return PARAMS[0], encode_cdr(PARAMS[2], vals)
    vals = (ev["tick"], ev["t"], ev["kind"], ev.get("note", ""), ev["who"], ev["status"], ev["seq"])
    return EVENTS[0], encode_cdr(EVENTS[2], vals)


def decode(topic: str, data: bytes) -> dict[str, Any]:
    fields = PARAMS[2] if topic == PARAMS[0] else EVENTS[2]
    ev = dict(zip((n for n, _ in fields), decode_cdr(fields, data)))
    if topic == PARAMS[0]:
        ev["kind"] = "set"
    return ev


__all__ = ["EVENTS", "PARAMS", "decode", "encode", "schema_text"]
