"""Parameters and operator services on the live server (Foxglove WebSocket protocol, foxglove-sdk).

Lives in the log writer process next to bench.daq.live. Every parameter change and note from a
client is checked here first, against the session's parameter space (bench.operator.ParamSpace), its
size and a rate limit; only checked requests reach the loop, through a pipe it looks at between ticks.
A refusal goes back to the clients as a status message (and into the log on /params or /events); the
run never sees it. A request is encoded and measured before anything is written: a frame is at most
`MAX_FRAME` bytes, so the non-blocking pipe takes it whole or not at all, and one oversized request
can never leave half a frame that blocks every later one.

E-stop and stop never take that path: no rate limit, no checks that could refuse them, no pipe. Each
is one store into shared memory (the request's sequence number) that the loop reads every tick, so
it acts at the loop's next tick whatever other clients send (bench.daq.writer.RequestInbox).

foxglove-sdk calls the listener and the service handlers from its own threads; the MCAP log is the
writer's main thread's, so refusals are queued for it (`drain_refusals`) and reports from the loop
arrive there too (`reported`).
"""

from __future__ import annotations

import itertools
import json
import select
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from bench.errors import BadInput
from bench.operator import ACTIONS, MAX_NOTE, OFF, ParamSpace, Request

RATE = 50.0  # [requests/s] sustained, per server (all clients together)
BURST = 50  # requests accepted at once before the rate applies
SERVICE_WAIT = 1.0  # [s] a service call waits this long for the loop to apply it
SETTLE_S = 0.5  # [s] at most, at the end, for answered service calls to get their answers out
MAX_TEXT = 100  # characters of a client's parameter name or value kept in a refusal
MAX_FRAME = select.PIPE_BUF - 4  # [bytes] of an encoded request: with the pipe's 4-byte header, one atomic write
FLAGGED = ("estop", "stop")  # the actions that bypass the checks, the rate limit and the pipe
MAX_BODY = 16384  # [bytes] of a service call's body that is parsed at all (a note is at most MAX_NOTE characters)

_REQ_SCHEMA = {"stop": {"type": "object", "properties": {}}, "estop": {"type": "object", "properties": {}},
               "mark": {"type": "object", "properties": {"note": {"type": "string", "maxLength": MAX_NOTE}}},
               # a part switched while running, e.g. {"part": "speed_controller", "to": "lpv"} (bench switch)
               "switch": {"type": "object", "required": ["part", "to"],
                          "properties": {"part": {"type": "string"}, "to": {"type": "string"}}}}  # fmt: skip
_RESP_SCHEMA = {"type": "object", "properties": {"ok": {"type": "boolean"}, "status": {"type": "string"},
                                                 "tick": {"type": "integer"}, "t": {"type": "number"}}}  # fmt: skip


class TokenBucket:
    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, burst
        self.tokens, self.t = float(burst), time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        if self.tokens >= 1:
            self.tokens -= 1
            return True
        return False


class LiveControl:
    """The server listener (parameters) and the services (stop, estop, mark).

    ``post(frame)`` sends an encoded request down the pipe to the loop (False: not taken);
    ``flag(kind, seq)`` raises an e-stop or stop for the loop."""

    def __init__(self, space: ParamSpace, post: Callable[[bytes], bool], flag: Callable[[str, int], None]) -> None:
        self.space, self._post, self._flag = space, post, flag
        self.server: Any = None  # set once the server runs (bench.daq.live.LiveStream)
        self._lock = threading.Lock()
        self._bucket = TokenBucket(RATE, BURST)
        self._seqs = itertools.count(1)  # next() is atomic: a flagged action takes no lock before its flag
        self._waiters: dict[int, tuple[threading.Event, dict]] = {}
        self._flagged_calls: dict[int, tuple[str, str]] = {}  # unanswered e-stop/stop calls: kind, who
        self.refusals: deque[dict] = deque(maxlen=10_000)  # for the main thread to log
        self.counts = {"requests": 0, "refused": 0, "rate_limited": 0, "applied": 0}

    # ------------------------------------------------------------------ foxglove-sdk hooks
    def capabilities(self) -> list[Any]:
        from foxglove.websocket import Capability

        return [Capability.Parameters, Capability.Services]

    def services(self) -> list[Any]:
        import foxglove
        from foxglove.websocket import Service, ServiceSchema

        def schema(name: str, body: dict) -> Any:
            return foxglove.websocket.MessageSchema(encoding="json", schema=foxglove.Schema(
                name=name, encoding="jsonschema", data=json.dumps(body).encode()))  # fmt: skip

        return [Service(f"/{a}", schema=ServiceSchema(f"imbench/{a}", request=schema(f"imbench/{a}Request",
                                                                                      _REQ_SCHEMA[a]),
                                                      response=schema("imbench/ServiceResponse", _RESP_SCHEMA)),
                        handler=self._handler(a)) for a in (*ACTIONS, "switch")]  # fmt: skip

    def on_get_parameters(self, client: Any, param_names: list[str], request_id: str | None = None) -> list[Any]:
        names = param_names or list(self.space.params)
        return [self._param(n) for n in names if n in self.space.params]

    def on_set_parameters(self, client: Any, parameters: list[Any], request_id: str | None = None) -> list[Any]:
        who = _who(client, request_id)
        for p in parameters:
            try:
                value = p.get_value()
            except Exception:  # noqa: BLE001 - a value the SDK cannot turn into Python
                value = None
            name, problem = str(p.name), None
            if len(name) > MAX_TEXT or (isinstance(value, (str, bytes, list, dict)) and len(value) > MAX_TEXT):
                # no parameter has such a name or value: refused unread (a repr of megabytes would hold the GIL)
                size = max(len(name), len(value) if isinstance(value, (str, bytes, list, dict)) else 0)
                problem, value = f"a name or value of {size} characters or items: too large", f"<{size}>"
            self._request("set", name[:MAX_TEXT], value, who, problem=problem)
        return [self._param(p.name) for p in parameters if p.name in self.space.params]

    def on_subscribe(self, client: Any, channel: Any) -> None:  # the rest of the listener protocol: no-ops
        pass

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        pass

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        pass

    # ------------------------------------------------------------------ requests
    def _handler(self, action: str) -> Callable[[Any], bytes]:
        def handle(req: Any) -> bytes:
            if action in FLAGGED:  # first thing, whatever the payload: an e-stop is never refused
                return json.dumps(self._flagged(action, req)).encode()
            body = _body(req)
            problem = None if isinstance(body, dict) else \
                f"the request must be a JSON object of at most {MAX_BODY} bytes, got {len(req.payload)} bytes"
            if action == "switch":  # a parameter set of a switchable part, answered when the loop applied it
                part, to = (body.get("part"), body.get("to")) if problem is None else ("", None)
                if problem is None and part not in self.space.switchable:
                    problem = f"part must be one of {', '.join(self.space.switchable) or '(none)'}, got {str(part)[:MAX_TEXT]!r}"
                name = str(part)[:MAX_TEXT] if problem is None else "switch"
                return json.dumps(self._request("set", name, to, _who_id(req.client_id) + _named(body), wait=True,
                                                problem=problem)[1]).encode()  # fmt: skip
            note = body.get("note", "") if isinstance(body, dict) else None
            return json.dumps(self._request(action, "", note, _who_id(req.client_id) + _named(body), wait=True,
                                            problem=problem)[1]).encode()  # fmt: skip

        return handle

    def _flagged(self, kind: str, req: Any) -> dict:
        """An e-stop or stop: the flag before anything else, then who sent it (for the log). An answer
        from the loop covers every earlier call of the same kind (the flag holds only the latest), so
        no call waits on one that was superseded."""
        seq = next(self._seqs)
        waiter = self._waiters[seq] = (threading.Event(), {})
        self._flagged_calls[seq] = (kind, _who_id(req.client_id))
        self._flag(kind, seq)
        named = _named(_body(req))
        with self._lock:
            self.counts["requests"] += 1
            if named and seq in self._flagged_calls:  # not answered yet: add the name the client gave
                self._flagged_calls[seq] = (kind, self._flagged_calls[seq][1] + named)
        return self._wait(seq, waiter)

    def _request(self, kind: str, name: str, value: Any, who: str, wait: bool = False,
                 problem: str | None = None) -> tuple[int, dict]:  # fmt: skip
        """Check (``problem``: already known to be refused), rate-limit, measure and post one request."""
        with self._lock:
            seq = next(self._seqs)
            self.counts["requests"] += 1
            if not self._bucket.take():
                self.counts["rate_limited"] += 1
                return seq, {"ok": False, "status": f"refused: rate limit ({RATE:g} requests/s)"}
            try:
                if problem is not None:
                    raise BadInput(name or kind, problem)
                if kind == "set":
                    value = self.space.check(name, value)
                elif kind == "mark" and not (isinstance(value, str) and len(value) <= MAX_NOTE):
                    got = f"{len(value)} characters" if isinstance(value, str) else type(value).__name__
                    raise BadInput("note", f"must be a string of at most {MAX_NOTE} characters, got {got}")
                frame = Request(seq, kind, name, value, who).encode()
                if len(frame) > MAX_FRAME:  # measured before anything is written (see MAX_FRAME)
                    raise BadInput(name or kind, f"at most {MAX_FRAME} bytes as encoded, got {len(frame)} (shorten it)")
            except BadInput as exc:
                self.counts["refused"] += 1
                # a client's text is cut before it reaches the log (a 1 MB name at the rate limit would grow it fast)
                ev = {"seq": seq, "kind": kind, "name": name[:MAX_TEXT], "who": who,
                      "old": self.space.values.get(name), "new": _short(value), "note": "",
                      "status": f"refused: {str(exc)[:MAX_TEXT * 4]}"}  # fmt: skip
                self.refusals.append(ev)
                self._status(f"{name or kind}: {ev['status']}", error=True)
                return seq, {"ok": False, "status": ev["status"]}
            if not self._post(frame):
                self.counts["refused"] += 1
                return seq, {"ok": False, "status": "refused: the loop is not taking requests (the run is ending)"}
            waiter = (threading.Event(), {}) if wait else None
            if waiter is not None:
                self._waiters[seq] = waiter
        if waiter is None:
            return seq, {"ok": True, "status": "sent"}
        return seq, self._wait(seq, waiter)

    def _wait(self, seq: int, waiter: tuple[threading.Event, dict]) -> dict:
        """The loop's answer to a service call, or after SERVICE_WAIT that it has not come."""
        done = waiter[0].wait(SERVICE_WAIT)
        with self._lock:
            self._waiters.pop(seq, None)
            self._flagged_calls.pop(seq, None)
        if not done:
            return {"ok": True, "status": f"sent; not applied within {SERVICE_WAIT:g} s (the run may have ended)"}
        ev = waiter[1]
        return {"ok": ev["status"] == "applied", "status": ev["status"], "tick": ev["tick"], "t": ev["t"]}

    def settle(self, timeout: float = SETTLE_S) -> None:
        """Before the server stops (the run has ended): the calls the loop answered get their answers
        out, e.g. an e-stop's that ended the run (bounded; an unanswered call gets none anyway)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and any(done.is_set() for done, _ in list(self._waiters.values())):
            time.sleep(0.002)
        time.sleep(min(0.05, max(0.0, end - time.monotonic())))  # the SDK's thread writes the answer out

    def reported(self, ev: dict) -> None:
        """The loop applied (or refused) a request: tell the clients (writer's main thread)."""
        with self._lock:
            answered = [ev["seq"]]
            if ev["kind"] in FLAGGED:  # the log names its client; earlier calls of the kind get this answer too
                call = self._flagged_calls.pop(ev["seq"], None)
                if call is not None:
                    ev["who"] = call[1]
                # a snapshot: a handler thread may add a call meanwhile (without the lock, before its flag)
                answered += [q for q, (kind, _) in list(self._flagged_calls.items())
                             if kind == ev["kind"] and q < ev["seq"]]  # fmt: skip
                for q in answered[1:]:
                    self._flagged_calls.pop(q, None)
            if ev["status"] == "applied":
                self.counts["applied"] += 1
                if ev["kind"] == "set":
                    self.space.values[ev["name"]] = ev["new"]
            else:
                self.counts["refused"] += 1
            for q in answered:
                waiter = self._waiters.get(q)
                if waiter is not None:
                    waiter[1].update(ev)
                    waiter[0].set()
        if ev["kind"] == "set" and self.server is not None:
            try:
                self.server.publish_parameter_values([self._param(ev["name"])])
            except Exception:  # noqa: BLE001 - the server is going away
                pass
        if ev["status"] != "applied":
            self._status(f"{ev['name'] or ev['kind']}: {ev['status']}", error=True)

    def _param(self, name: str) -> Any:
        from foxglove import Parameter
        from foxglove.websocket import ParameterType

        v = self.space.values.get(name)
        if isinstance(v, float):
            return Parameter(name, value=v, type=ParameterType.Float64)
        return Parameter(name, value=v if v != OFF else OFF)

    def _status(self, message: str, error: bool) -> None:
        if self.server is None:
            return
        from foxglove.websocket import StatusLevel

        try:
            self.server.publish_status(message[:500], StatusLevel.Error if error else StatusLevel.Info)
        except Exception:  # noqa: BLE001
            pass


def _body(req: Any) -> Any:
    """A service call's JSON body, or None (not JSON, or larger than MAX_BODY: not even parsed)."""
    payload = bytes(req.payload)
    if req.encoding != "json" or len(payload) > MAX_BODY:
        return None
    try:
        return json.loads(payload or b"{}")
    except ValueError:
        return None


def _named(body: Any) -> str:
    """The name a client gave itself in a service call's body (``who``), cut short, for the log."""
    who = body.get("who") if isinstance(body, dict) else None
    return f" ({who[:80]})" if isinstance(who, str) and who else ""


def _short(value: Any) -> Any:
    return value if isinstance(value, (bool, int, float)) or value is None else repr(value)[:MAX_TEXT]


def _who_id(client_id: Any) -> str:
    return f"foxglove client {client_id}"


def _who(client: Any, request_id: str | None) -> str:
    base = _who_id(getattr(client, "id", "?"))
    return f"{base} ({str(request_id)[:80]})" if request_id else base


__all__ = ["BURST", "FLAGGED", "LiveControl", "MAX_FRAME", "RATE", "TokenBucket"]
