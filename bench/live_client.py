"""`bench set`, `bench stop`, `bench estop`, `bench mark`: a command-line client of a live session.

Speaks the Foxglove WebSocket protocol (the `websockets` package; the same protocol as Foxglove's
Parameters panel and service calls) to the server of ``bench run --live`` (bench.daq.live) and
waits until the loop has applied or refused the request: a parameter change shows up on /params,
an action comes back as the service's response.
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import time
from typing import Any

from bench.errors import BadInput

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
WAIT = 3.0  # [s] for the loop's answer


class _Session:
    """The connection, with a closed one reported as the end of the run (ConnectionError)."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws

    def __enter__(self) -> Any:
        return self.ws.__enter__()  # entered as websockets wants (a connection used bare warns)

    def __exit__(self, et: Any, exc: Any, tb: Any) -> None:
        from websockets.exceptions import ConnectionClosed

        self.ws.close()
        if isinstance(exc, ConnectionClosed):
            raise ConnectionError("the live session closed the connection (the run has ended)") from None


def _connect(host: str, port: int) -> Any:
    from websockets.sync.client import connect

    try:
        return _Session(connect(f"ws://{host}:{port}", subprotocols=SUBPROTOCOLS, max_size=None, open_timeout=3))  # type: ignore[arg-type]
    except (OSError, TimeoutError) as exc:
        raise BadInput("--port", f"no live session at {host}:{port} ({exc}); start one with `bench run --live`") from None
    except Exception as exc:  # noqa: BLE001 - a server that does not speak the protocol
        raise BadInput("--port", f"{host}:{port} is not a live imbench session: {exc}") from None


def _advertised(ws: Any, want: str, key: str) -> dict[str, dict]:
    """Read messages until the server has advertised ``want`` (a topic or a service name)."""
    seen: dict[str, dict] = {}
    end = time.monotonic() + WAIT
    while want not in seen:
        m = ws.recv(timeout=max(0.01, end - time.monotonic()))
        if isinstance(m, str):
            msg = json.loads(m)
            if msg.get("op") == ("advertise" if key == "topic" else "advertiseServices"):
                seen.update({c[key]: c for c in msg["channels" if key == "topic" else "services"]})
    return seen


def set_params(assignments: dict[str, Any], host: str = "127.0.0.1", port: int = 8765) -> list[dict]:
    """Set parameters of a live run; returns the loop's reports (/params), one per assignment."""
    for name, v in assignments.items():  # the protocol carries no nan/inf/bigint: the server would drop it
        if isinstance(v, float) and not math.isfinite(v) or isinstance(v, int) and not -(2**63) <= v < 2**63:
            shown = f"an integer of {len(str(abs(v)))} digits" if isinstance(v, int) else repr(v)
            raise BadInput(name, f"must be a finite number (within +-9.2e18), got {shown}")
    req_id = f"bench set {socket.gethostname()}:{os.getpid()}:{time.time_ns()}"
    with _connect(host, port) as ws:
        chans = _advertised(ws, "/params", "topic")
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": chans["/params"]["id"]}]}))
        params = [{"name": k, "value": v, **({"type": "float64"} if isinstance(v, float) else {})}
                  for k, v in assignments.items()]  # fmt: skip
        ws.send(json.dumps({"op": "setParameters", "parameters": params, "id": req_id}, allow_nan=False))
        from bench.daq.events import decode

        reports: dict[str, dict] = {}
        end = time.monotonic() + WAIT
        while len(reports) < len(assignments) and time.monotonic() < end:
            try:
                m = ws.recv(timeout=max(0.01, end - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(m, bytes) and m[0] == 1:  # message data: opcode, subscription, log time, payload
                ev = decode("/params", m[13:])
                if req_id in ev["who"] and ev["name"] in assignments:
                    reports[ev["name"]] = ev
    missing = [k for k in assignments if k not in reports]
    if missing:
        raise TimeoutError(f"no answer for {', '.join(missing)} within {WAIT:g} s (has the run ended?)")
    return [reports[k] for k in assignments]


def call(action: str, note: str = "", host: str = "127.0.0.1", port: int = 8765, body: dict | None = None) -> dict:
    """Call an operator service (stop, estop, mark, switch with ``body`` {"part", "to"}) of a live run; returns its
    JSON response, plus ``sent_ns`` (wall clock when the call left, for the latency to the tick it was applied at)."""
    from bench.operator import MAX_NOTE

    if len(note) > MAX_NOTE:  # the server refuses it too; here it is bad input before anything is sent
        raise BadInput("note", f"at most {MAX_NOTE} characters, got {len(note)}")
    with _connect(host, port) as ws:
        services = _advertised(ws, f"/{action}", "name")
        sid = services[f"/{action}"]["id"]
        who = f"bench {action} {socket.gethostname()}:{os.getpid()}"
        payload = json.dumps({"note": note, "who": who} if action == "mark" else {**(body or {}), "who": who}).encode()
        enc = b"json"
        sent_ns = time.time_ns()
        ws.send(struct.pack("<BIII", 2, sid, 1, len(enc)) + enc + payload)  # callService, call id 1
        end = time.monotonic() + WAIT + 1.0
        while time.monotonic() < end:
            m = ws.recv(timeout=max(0.01, end - time.monotonic()))
            if isinstance(m, bytes) and m[0] == 3:  # serviceCallResponse
                _, _, n = struct.unpack_from("<III", m, 1)
                return {**json.loads(m[13 + n :]), "sent_ns": sent_ns}
            if isinstance(m, str) and json.loads(m).get("op") == "serviceCallFailure":
                return {"ok": False, "status": json.loads(m).get("message", "service call failed"), "sent_ns": sent_ns}
    raise TimeoutError(f"no answer from /{action} within {WAIT + 1:g} s")


__all__ = ["call", "set_params"]
