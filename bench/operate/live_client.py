"""`bench set`, `bench switch`, `bench stop`, `bench estop`, `bench mark`: a command-line client of a live session.

Speaks the Foxglove WebSocket protocol (the `websockets` package) to the server of ``bench run --live``
(bench.daq.live_control): one service call per command (/set, /switch, /stop, /estop, /mark), all its changes
in one request that the loop applies whole or refuses whole, with an id of its own. The server answers with the
loop's report (applied at tick k, or refused and why) as soon as it comes, or "pending" when the timeout is near
(or after a second, when many calls wait already); a pending request is asked after by its id (/request) until
the timeout, and once more then. Every command ends in one of three answers:

* **applied** (exit 0): the loop applied it, at the tick printed (also when the answer came late);
* **refused** (exit 2): by the server's checks, the client's rate limit or the loop, with the reason;
* **unknown** (exit 4, `EXIT_NO_ANSWER`): no answer within the timeout (a loop that stalls, a run that ends, a
  server that does not answer): it may or may not have been applied; /params, /events and the log tell.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import socket
import struct
import time
from typing import Any

from bench.errors import BadInput

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
WAIT = 5.0  # [s] for the loop's answer (`bench set --timeout`)
CONNECT_WAIT = 3.0  # [s] for the connection and the server's list of services
POLL = 0.25  # [s] between questions about a pending request
LAST_ASK = 2.0  # [s] for the server's answer to the last question, at the timeout
APPLIED, REFUSED, UNKNOWN = "applied", "refused", "unknown"
EXIT_CODES = {APPLIED: 0, REFUSED: 2, UNKNOWN: 4}  # bench.core.shutdown.EXIT_OK, EXIT_BAD_INPUT, EXIT_NO_ANSWER


def _connect(host: str, port: int) -> Any:
    from websockets.sync.client import connect

    try:
        return connect(f"ws://{host}:{port}", subprotocols=SUBPROTOCOLS, max_size=None,  # type: ignore[arg-type]
                       open_timeout=CONNECT_WAIT)  # fmt: skip
    except (OSError, TimeoutError) as exc:
        raise BadInput("--port", f"no live session at {host}:{port} ({exc}); start one with `bench run --live`") from None
    except Exception as exc:  # noqa: BLE001 - a server that does not speak the protocol
        raise BadInput("--port", f"{host}:{port} is not a live imbench session: {exc}") from None


def _services(ws: Any, want: str, host: str, port: int) -> dict[str, int]:
    """The server's services by name, once it has advertised ``want`` (`BadInput`: not a live imbench session;
    nothing has been sent)."""
    seen: dict[str, int] = {}
    end = time.monotonic() + CONNECT_WAIT
    try:
        while want not in seen:
            m = ws.recv(timeout=max(0.01, end - time.monotonic()))
            if isinstance(m, str):
                msg = json.loads(m)
                if msg.get("op") == "advertiseServices":
                    seen.update({s["name"]: s["id"] for s in msg["services"]})
    except TimeoutError:
        raise BadInput("--port", f"{host}:{port} offers no {want} within {CONNECT_WAIT:g} s: not a live imbench "
                       "session (nothing was sent)") from None  # fmt: skip
    return seen


def _call(ws: Any, sid: int, body: dict, call_id: int, until: float) -> dict | None:
    """One service call; its JSON answer, or None if none came by ``until`` (monotonic)."""
    enc = b"json"
    ws.send(struct.pack("<BIII", 2, sid, call_id, len(enc)) + enc + json.dumps(body, allow_nan=False).encode())
    while True:
        try:
            m = ws.recv(timeout=max(0.01, until - time.monotonic()))
        except TimeoutError:
            return None
        if isinstance(m, bytes) and m[:1] == b"\x03":  # serviceCallResponse: service, call, encoding, payload
            _, cid, n = struct.unpack_from("<III", m, 1)
            if cid == call_id:
                return json.loads(m[13 + n :])
        elif isinstance(m, str):
            msg = json.loads(m)
            if msg.get("op") == "serviceCallFailure" and msg.get("callId") == call_id:
                return {"state": REFUSED, "status": f"refused: {msg.get('message', 'service call failed')}"}
        if time.monotonic() >= until:
            return None


def request(action: str, body: dict | None = None, host: str = "127.0.0.1", port: int = 8765,
            wait: float = WAIT) -> dict:  # fmt: skip
    """Send one request (``action``: set, switch, stop, estop, mark) and wait up to ``wait`` seconds for the loop's
    answer. Returns it: ``state`` applied, refused or unknown, ``status`` (the reason of a refusal, or why it is
    unknown), ``tick``, ``t``, ``seq``, ``id``, ``items`` (a set's or switch's changes: name, old, new), ``late``
    (the answer came after the server had said "pending"), ``sent_ns`` (wall clock when it was sent).
    `BadInput`: no live session there (nothing was sent)."""
    from websockets.exceptions import ConnectionClosed

    host_pid = f"{socket.gethostname()}:{os.getpid()}"
    rid = f"{host_pid}:{time.time_ns()}"
    out: dict[str, Any] = {"state": UNKNOWN, "id": rid, "late": False, "sent_ns": None}
    ws = _connect(host, port)
    try:
        with ws:
            services = _services(ws, f"/{action}", host, port)
            calls = itertools.count(1)
            out["sent_ns"] = time.time_ns()
            end = time.monotonic() + wait
            # the server holds the call until the loop answers, a little less long than this client waits
            ans = _call(ws, services[f"/{action}"], {**(body or {}), "id": rid, "who": f"bench {action} {host_pid}",
                                                     "wait": max(0.0, wait - POLL)}, next(calls), end)  # fmt: skip
            why = "the live server did not answer"
            while ans is None or ans.get("state") not in (APPLIED, REFUSED):
                if ans is not None:  # pending (or a question the server could not answer yet)
                    out["seq"] = ans.get("seq", out.get("seq"))
                    why = f"request {ans.get('seq', '?')} is pending in the loop: it may still be applied"
                    out["late"] = True
                left = end - time.monotonic()
                if left <= 0 or "/request" not in services:
                    break
                time.sleep(min(POLL, left))
                ans = _call(ws, services["/request"], {"id": rid}, next(calls), end)
            else:
                out.update(ans)
                out["id"] = rid
                return out
            if "/request" in services:  # the timeout: one last question (it may have come in meanwhile)
                ans = _call(ws, services["/request"], {"id": rid}, next(calls), time.monotonic() + LAST_ASK)
                if ans is not None and ans.get("state") in (APPLIED, REFUSED):
                    out.update(ans, id=rid, late=True)
                    return out
    except ConnectionClosed:
        why = "the live session closed the connection (the run has ended)"
    out["status"] = f"no answer from the loop within {wait:g} s ({why}); not known whether it was applied: " \
                    "see /params, /events or the log"  # fmt: skip
    return out


def set_params(assignments: dict[str, Any], host: str = "127.0.0.1", port: int = 8765,
               wait: float = WAIT) -> list[dict]:  # fmt: skip
    """Set parameters of a live run, all in one request (applied whole or refused whole); returns one report per
    assignment (name, old_text, new_text, tick, t, status). TimeoutError: no answer (not known whether applied)."""
    for name, v in assignments.items():  # the protocol carries no nan/inf/bigint: the server would drop it
        if isinstance(v, float) and not math.isfinite(v) or isinstance(v, int) and not -(2**63) <= v < 2**63:
            shown = f"an integer of {len(str(abs(v)))} digits" if isinstance(v, int) else repr(v)
            raise BadInput(name, f"must be a finite number (within +-9.2e18), got {shown}")
    ans = request("set", {"parameters": assignments}, host, port, wait)
    if ans["state"] == UNKNOWN:
        raise TimeoutError(ans["status"])
    items = {i["name"]: i for i in ans.get("items") or ()}
    return [{"name": k, "old_text": items.get(k, {}).get("old", ""), "new_text": items.get(k, {}).get("new", ""),
             "tick": ans.get("tick"), "t": ans.get("t"), "status": ans["status"]} for k in assignments]  # fmt: skip


def call(action: str, note: str = "", host: str = "127.0.0.1", port: int = 8765, body: dict | None = None,
         wait: float = WAIT) -> dict:  # fmt: skip
    """Call an operator service (stop, estop, mark; switch with ``body`` {"part", "to"} or {"parts": {...}}) of a live
    run; returns `request`'s answer plus ``ok`` (applied)."""
    from bench.operate.requests import MAX_NOTE

    if len(note) > MAX_NOTE:  # the server refuses it too; here it is bad input before anything is sent
        raise BadInput("note", f"at most {MAX_NOTE} characters, got {len(note)}")
    ans = request(action, {"note": note} if action == "mark" else body, host, port, wait)
    return {**ans, "ok": ans["state"] == APPLIED}


__all__ = ["APPLIED", "EXIT_CODES", "REFUSED", "UNKNOWN", "WAIT", "call", "request", "set_params"]
