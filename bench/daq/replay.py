"""A recorded session's operator requests and loop stalls, read back from its log for `--replay-params`
(`bench.operate.requests.ReplaySource`; the stalls for the loop's ``inject_stalls``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from bench.daq.reader import LogReader
from bench.errors import BadInput
from bench.operate.requests import ReplaySource, Request


def read_requests(path: str, rate_hz: float) -> ReplaySource:
    """The applied events of a log's /params and /events (refused ones were never applied)."""
    try:
        log = LogReader(path)
        meta = log.metadata().get("run", {})
        events = log.events()
    except BadInput:
        raise
    except Exception as exc:  # noqa: BLE001 - a file that is not a readable imbench log
        raise BadInput("--replay-params", f"cannot read {path}: {type(exc).__name__}: {exc}") from None
    rec_rate = float(meta.get("rate_hz", rate_hz))
    if abs(rec_rate - rate_hz) > 1e-9 * rate_hz:
        raise BadInput("--replay-params", f"{path} ran at {rec_rate:g} Hz, this rig at {rate_hz:g} Hz: the "
                       "ticks would not match")  # fmt: skip
    groups: list[list[dict]] = []  # the changes of one request (one tick, one sequence number) together
    for e in events:
        if e["status"] != "applied":
            continue
        same = groups and e["kind"] == "set" == groups[-1][0]["kind"] and \
            (e["tick"], e["seq"]) == (groups[-1][0]["tick"], groups[-1][0]["seq"])  # fmt: skip
        if same:
            groups[-1].append(e)
        else:
            groups.append([e])
    reqs = []
    for i, g in enumerate(groups):
        e = g[0]
        items = tuple((x["name"], _decode_value(x)) for x in g) if len(g) > 1 else ()
        reqs.append(Request(i, e["kind"], e.get("name", "") if not items else "", None if items else _decode_value(e),
                            f"replay of {e['who']}", int(e["tick"]), items))  # fmt: skip
    return ReplaySource(reqs)


def read_stalls(path: str) -> dict[int, int]:
    """The loop stalls of a recorded run, {first tick skipped: ticks skipped}: the gaps in /rig's tick column and
    before its first row (a real-time loop that wakes a period or more late skips the ticks it missed,
    `bench.runtime.loop.TimedLoop.run`). A
    replay injects them at the same ticks, so the controller and the drive ride through the same gaps as in the
    recording."""
    try:
        ticks = LogReader(path).read("/rig")["tick"]
    except Exception as exc:  # noqa: BLE001 - a file that is not a readable imbench log
        raise BadInput("--replay-params", f"cannot read the /rig ticks of {path}: {type(exc).__name__}: {exc}") from None
    # a loop that wakes late for its very first tick starts the log past tick 0: that is a stall too
    first = {0: int(ticks[0])} if len(ticks) and ticks[0] > 0 else {}
    return first | {int(a) + 1: int(b - a) - 1 for a, b in zip(ticks[:-1], ticks[1:]) if b - a > 1}


def _decode_value(e: Mapping[str, Any]) -> Any:
    """A logged request's value, exactly: from its text (repr of a float, True, 'off', ...)."""
    if e["kind"] == "mark":
        return e["note"]
    text = str(e.get("new_text", ""))
    if text in ("True", "False"):
        return text == "True"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text
