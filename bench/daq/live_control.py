"""Parameters and operator services on the live server (Foxglove WebSocket protocol, foxglove-sdk).

Lives in the log writer process next to bench.daq.live. Every parameter change, switch and note from a
client is checked here first, against the session's parameter space (bench.operate.requests.ParamSpace), its
size and the client's rate limit; only checked requests reach the loop, through a pipe it looks at between
ticks. A refusal goes back to the client (the service's answer, a status message) and into the log on
/params or /events, at the tick the server decided it with the value in force then; the run never sees it.
A request is encoded and measured before anything is written: a frame is at most `MAX_FRAME` bytes, so the
non-blocking pipe takes it whole or not at all, and one oversized request can never leave half a frame that
blocks every later one.

**Fair to every client.** The rate limit is per client (per WebSocket connection): `RATE` requests/s, bursts
of `BURST`. A client that floods is refused beyond that ("rate limit: 50 requests/s per client", counted in
/status and the summary, told to it at most once a second); every other client keeps its own budget.

**One request, one answer.** Several changes in one request (`bench set a=1 b=2`, `bench switch observer=jl
current_controller=lpv`, one setParameters message) travel as one `bench.operate.requests.Request` that the loop
applies whole between two ticks or refuses whole. Each request gets a sequence number (``seq``, on /params
and /events) and may carry the client's id (``id``); the server remembers what became of the latest
`MAX_RECORDS` (``/request`` answers: applied, refused, pending), so a client whose answer came late can ask.

E-stop and stop never take the checked path: no rate limit, no checks that could refuse them, no pipe. Each
is one store into shared memory (the request's sequence number) that the loop reads every tick, so it acts at
the loop's next tick whatever other clients send (bench.daq.writer.RequestInbox).

foxglove-sdk calls the listener (setParameters: inline on its network threads, which must never wait) and the
service handlers (on a pool of blocking threads: they wait for the loop up to `SERVICE_WAIT`, or as long as the
client says, ``wait`` in the body, for at most `MAX_LONG` calls at once and `MAX_LONG_PER_CLIENT` of one client,
so that threads stay free for an e-stop) from its own
threads. The loop's reports arrive on a thread of the writer process (`reported`); the MCAP log is the
writer's main thread's, so refusals are queued for it (`refusals`).
"""

from __future__ import annotations

import itertools
import json
import math
import select
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from typing import Any

from bench.errors import BadInput, clip, clip_repr
from bench.operate.requests import ACTIONS, MAX_NOTE, OFF, ParamSpace, Request

RATE = 50.0  # [requests/s] sustained, per client (per WebSocket connection)
BURST = 50  # requests a client may send at once before its rate applies
SERVICE_WAIT = 1.0  # [s] a service call waits this long for the loop, then answers "pending" ...
MAX_SERVICE_WAIT = 120.0  # [s] ... or as long as its body's "wait" says, up to this,
MAX_LONG, MAX_LONG_PER_CLIENT = 64, 4  # ... for so many calls at once (all clients, one client)
SETTLE_S = 0.5  # [s] at most, at the end, for answered service calls to get their answers out
MAX_TEXT = 100  # characters of a client's parameter name or value read at all (longer: refused unread)
MAX_FRAME = select.PIPE_BUF - 4  # [bytes] of an encoded request: with the pipe's 4-byte header, one atomic write
FLAGGED = ("estop", "stop")  # the actions that bypass the checks, the rate limit and the pipe
MAX_BODY = 16384  # [bytes] of a service call's body that is parsed at all (a note is at most MAX_NOTE characters)
MAX_ITEMS = 16  # changes in one request
MAX_CLIENTS = 1024  # clients whose rate-limit budget is kept (the least recently seen is dropped)
MAX_RECORDS = 4096  # requests with an id whose outcome the server remembers (`/request`)
HISTORY = 64  # applied changes kept per parameter, to tell the value in force at a past tick
REPORT_SYNC_S = 0.05  # [s] at most, a refusal waits for the loop's reports already sent (the value in force)
TELL_EVERY = 1.0  # [s] a rate-limited client is told so at most this often

_WHO = {"id": {"type": "string", "description": "the client's id of the request (for /request)"},
        "who": {"type": "string", "description": "who asks, for the log"},
        "wait": {"type": "number", "description": "[s] how long the call may wait for the loop (default 1)"}}  # fmt: skip
_REQ_SCHEMA = {"stop": {"type": "object", "properties": _WHO}, "estop": {"type": "object", "properties": _WHO},
               "mark": {"type": "object", "properties": {"note": {"type": "string", "maxLength": MAX_NOTE}, **_WHO}},
               # parts switched while running, e.g. {"part": "speed_controller", "to": "lpv"} or, applied whole or
               # not at all, {"parts": {"observer": "jl", "current_controller": "lpv"}} (bench switch)
               "switch": {"type": "object", "properties": {"part": {"type": "string"}, "to": {"type": "string"},
                                                           "parts": {"type": "object"}, **_WHO}},
               # parameters, applied whole or not at all: {"parameters": {"speed_Kp": 0.8, "speed_Ti": 0.05}}
               "set": {"type": "object", "required": ["parameters"],
                       "properties": {"parameters": {"type": "object"}, **_WHO}},
               # what became of a request: {"id": "..."} (the same answer as the request's own, or "pending")
               "request": {"type": "object", "required": ["id"], "properties": {"id": {"type": "string"}}}}  # fmt: skip
_RESP_SCHEMA = {"type": "object", "properties": {
    "ok": {"type": "boolean", "description": "applied"},
    "state": {"type": "string", "description": "applied, refused, pending (sent to the loop, no answer yet), unknown"},
    "status": {"type": "string"}, "tick": {"type": "integer"}, "t": {"type": "number"}, "seq": {"type": "integer"},
    "id": {"type": "string"}, "items": {"type": "array"}}}  # fmt: skip


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
    """The server listener (parameters) and the services (set, switch, stop, estop, mark, request).

    ``post(frame)`` sends an encoded request down the pipe to the loop (False: not taken); ``flag(kind, seq)``
    raises an e-stop or stop for the loop; ``now()`` is (tick, t, log time) of the newest tick the loop has
    published, where a refusal here is logged; ``reports_sent()`` counts the reports the loop has sent (a
    refusal first takes those in, so that it logs the value in force)."""

    def __init__(self, space: ParamSpace, post: Callable[[bytes], bool], flag: Callable[[str, int], None],
                 now: Callable[[], tuple[int, float, int]] | None = None,
                 reports_sent: Callable[[], int] | None = None) -> None:  # fmt: skip
        self.space, self._post, self._flag = space, post, flag
        self._now = now or (lambda: (-1, math.nan, 0))
        self._reports_sent = reports_sent or (lambda: 0)
        self.server: Any = None  # set once the server runs (bench.daq.live.LiveStream)
        self._lock = threading.Lock()
        self._reports = threading.Condition(self._lock)  # notified per report taken in (`reported`)
        self._reports_seen = 0
        self._buckets: OrderedDict[Any, TokenBucket] = OrderedDict()  # per client, least recently seen first
        self._told: dict[Any, float] = {}  # when a rate-limited client was last told
        self._seqs = itertools.count(1)  # next() is atomic: a flagged action takes no lock before its flag
        self._waiters: dict[int, tuple[threading.Event, dict]] = {}
        self._flagged_calls: dict[int, tuple[str, str]] = {}  # unanswered e-stop/stop calls: kind, who
        self._ids: dict[int, str] = {}  # seq -> the client's id, of requests the loop has not answered yet
        self._records: OrderedDict[str, dict] = OrderedDict()  # by the client's id: what became of the request
        self._long: dict[Any, int] = {}  # service calls per client waiting longer than SERVICE_WAIT
        self._parts: dict[int, list[dict]] = {}  # reports of a request of several changes, until all are in
        self._history: dict[str, deque[tuple[int, Any, Any]]] = {}  # applied (tick, old, new) per parameter
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
                        handler=self._handler(a)) for a in (*ACTIONS, "switch", "set", "request")]  # fmt: skip

    def on_get_parameters(self, client: Any, param_names: list[str], request_id: str | None = None) -> list[Any]:
        names = param_names or list(self.space.params)
        return [self._param(n) for n in names if n in self.space.params]

    def on_set_parameters(self, client: Any, parameters: list[Any], request_id: str | None = None) -> list[Any]:
        """One request of all the parameters given. The reply (and the update to every client) carries only
        settled values: a refused change the value in force; a change sent to the loop comes as a parameter
        update with its new value once the loop applied it (or the old one, and an error status, if the loop
        refused it). Never waits: the SDK calls this on its network threads."""
        items, problem = [], None
        for p in parameters:
            try:
                value = p.get_value()
            except Exception:  # noqa: BLE001 - a value the SDK cannot turn into Python
                value = None
            name = str(p.name)
            if len(name) > MAX_TEXT or (isinstance(value, (str, bytes, list, dict)) and len(value) > MAX_TEXT):
                # no parameter has such a name or value: refused unread (a repr of megabytes would hold the GIL)
                size = max(len(name), len(value) if isinstance(value, (str, bytes, list, dict)) else 0)
                problem, value = f"a name or value of {size} characters or items: too large", f"<{size}>"
            items.append((name[:MAX_TEXT], value))
        resp = self._request("set", items, None, _who(client, request_id), getattr(client, "id", None),
                             request_id, problem=problem)  # fmt: skip
        if resp["state"] == "pending":
            return []
        return [self._param(n) for n, _ in items if n in self.space.params]

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
            if action == "request":
                return json.dumps(self.query(body.get("id") if isinstance(body, dict) else None)).encode()
            problem = None if isinstance(body, dict) else \
                f"the request must be a JSON object of at most {MAX_BODY} bytes, got {len(req.payload)} bytes"
            body = body if isinstance(body, dict) else {}
            rid = _rid(body.get("id"))
            who = _who_id(req.client_id) + _named(body) + (f" [id {rid}]" if rid else "")
            if action in ("set", "switch"):
                items, why = _items(action, body, self.space.switchable)
                return json.dumps(self._request("set", items, None, who, req.client_id, rid, _wait_of(body),
                                                problem=problem or why, label=action)).encode()  # fmt: skip
            return json.dumps(self._request(action, [], body.get("note", ""), who, req.client_id, rid,
                                            _wait_of(body), problem=problem)).encode()  # fmt: skip

        return handle

    def _flagged(self, kind: str, req: Any) -> dict:
        """An e-stop or stop: the flag before anything else, then who sent it (for the log). An answer
        from the loop covers every earlier call of the same kind (the flag holds only the latest), so
        no call waits on one that was superseded."""
        seq = next(self._seqs)
        waiter = self._waiters[seq] = (threading.Event(), {})
        self._flagged_calls[seq] = (kind, _who_id(req.client_id))
        self._flag(kind, seq)
        body = _body(req)
        rid = _rid(body.get("id") if isinstance(body, dict) else None)
        named = _named(body) + (f" [id {rid}]" if rid else "")
        with self._lock:
            self.counts["requests"] += 1
            if named and seq in self._flagged_calls:  # not answered yet: add the name the client gave
                self._flagged_calls[seq] = (kind, self._flagged_calls[seq][1] + named)
            if rid is not None:
                self._ids[seq] = rid
                self._record(rid, {"ok": False, "state": "pending", "status": "sent to the loop", "seq": seq})
        return self._wait(seq, waiter, rid, _wait_of(body), req.client_id)

    def _request(self, kind: str, items: list[tuple[str, Any]], note: Any, who: str, client: Any, rid: Any,
                 wait: float = 0.0, problem: str | None = None, label: str = "") -> dict:  # fmt: skip
        """Rate-limit, check (``problem``: already known to be refused), measure and post one request (a "set"
        of ``items``, or a mark's ``note``); the answer: refused at once, or pending (``wait`` > 0: the loop's
        answer, if it comes within that many seconds, see `_wait`)."""
        rid = _rid(rid)
        tell = None
        with self._lock:
            seq = next(self._seqs)
            self.counts["requests"] += 1
            if not self._bucket(client).take():  # not logged one by one (a flood would fill the log): counted
                self.counts["rate_limited"] += 1
                resp = {"ok": False, "state": "refused", "seq": seq,
                        "status": f"refused: rate limit: {RATE:g} requests/s per client"}  # fmt: skip
                last = self._told.get(client, -math.inf)
                if time.monotonic() - last >= TELL_EVERY:
                    self._told[client] = time.monotonic()
                    tell = f"{clip(who)}: {resp['status']}"
                waiter = None
            else:
                try:
                    frame = self._frame(seq, kind, items, note, who, problem, label)
                except BadInput as exc:
                    self.counts["refused"] += 1
                    resp = {"ok": False, "state": "refused", "seq": seq, "status": f"refused: {exc}"}
                    self._log_refusal(seq, kind, items or [(label or kind, None)], note, who, resp["status"])
                    tell = f"{clip(items[0][0]) if items else label or kind}: {resp['status']}"
                    waiter = None
                else:
                    if not self._post(frame):
                        self.counts["refused"] += 1
                        resp = {"ok": False, "state": "refused", "seq": seq,
                                "status": "refused: the loop is not taking requests (the run is ending)"}  # fmt: skip
                        waiter = None
                    else:
                        resp = {"ok": False, "state": "pending", "seq": seq, "status": "sent to the loop"}
                        waiter = (threading.Event(), {})
                        self._waiters[seq] = waiter
                        if rid is not None:
                            self._ids[seq] = rid
            if rid is not None:
                self._record(rid, resp)
        if tell is not None:
            self._status(tell, error=True)
        if waiter is None or wait <= 0:
            return _answer(resp, rid)
        return self._wait(seq, waiter, rid, wait, client)

    def _frame(self, seq: int, kind: str, items: list[tuple[str, Any]], note: Any, who: str, problem: str | None,
               label: str) -> bytes:  # fmt: skip
        """The request checked and encoded, or `BadInput` naming what is refused."""
        if problem is not None:  # (the problem names what it is about, cut short)
            raise BadInput(label or kind, problem)
        if kind == "set":
            if not items:
                raise BadInput(label or kind, "no parameters given")
            if len(items) > MAX_ITEMS:
                raise BadInput(label or kind, f"at most {MAX_ITEMS} changes in one request, got {len(items)}")
            names = [n for n, _ in items]
            twice = next((n for n in names if names.count(n) > 1), None)
            if twice is not None:
                raise BadInput(clip(twice), "given twice in one request")
            checked = tuple((n, self.space.check(n, v)) for n, v in items)
            req = Request(seq, "set", *checked[0], who) if len(checked) == 1 else Request(seq, "set", who=who,
                                                                                         items=checked)  # fmt: skip
        elif kind == "mark":
            if not (isinstance(note, str) and len(note) <= MAX_NOTE):
                got = f"{len(note)} characters" if isinstance(note, str) else type(note).__name__
                raise BadInput("note", f"must be a string of at most {MAX_NOTE} characters, got {got}")
            req = Request(seq, "mark", "", note, who)
        else:
            raise BadInput("request", f"unknown kind {clip_repr(kind)}")
        frame = req.encode()
        if len(frame) > MAX_FRAME:  # measured before anything is written (see MAX_FRAME)
            raise BadInput(label or kind, f"at most {MAX_FRAME} bytes as encoded, got {len(frame)} (shorten it)")
        return frame

    def _bucket(self, client: Any) -> TokenBucket:
        """The client's rate-limit budget (the caller holds the lock)."""
        b = self._buckets.get(client)
        if b is None:
            b = self._buckets[client] = TokenBucket(RATE, BURST)
            if len(self._buckets) > MAX_CLIENTS:
                gone, _ = self._buckets.popitem(last=False)
                self._told.pop(gone, None)
        else:
            self._buckets.move_to_end(client)
        return b

    def _log_refusal(self, seq: int, kind: str, items: list[tuple[str, Any]], note: Any, who: str,
                     status: str) -> None:  # fmt: skip
        """Queue a refusal for the log, at the newest tick the loop has published (when it was decided), with the
        value in force at that tick (the caller holds the lock). A client's text is cut before it reaches the
        log (a 1 MB name at the rate limit would grow it fast)."""
        tick, t, log_time = self._now()
        sent = self._reports_sent()  # the loop's reports up to that tick have been sent: take them in first
        self._reports.wait_for(lambda: self._reports_seen >= sent, timeout=REPORT_SYNC_S)
        base = {"seq": seq, "kind": kind, "who": who, "status": clip(status, 400), "tick": tick, "t": t,
                "log_time": log_time, "note": ""}  # fmt: skip
        if kind == "mark":
            self.refusals.append({**base, "name": "", "old": None, "new": None,
                                  "note": clip(note) if isinstance(note, str) else ""})  # fmt: skip
            return
        for name, value in items:
            self.refusals.append({**base, "kind": "set", "name": clip(name, MAX_TEXT),
                                  "old": self._value_at(name, tick), "new": _short(value)})  # fmt: skip

    def _value_at(self, name: str, tick: int) -> Any:
        """The value of ``name`` in force at ``tick``, from the loop's reports (the caller holds the lock)."""
        h = self._history.get(name)
        if not h:
            return self.space.values.get(name)
        for k, _, new in reversed(h):
            if k <= tick:
                return new
        return h[0][1]  # before the oldest change kept: its old value

    def _record(self, rid: str, resp: dict) -> None:
        """Remember what became of the client's request ``rid`` (the caller holds the lock)."""
        self._records[rid] = _answer(resp, rid)
        self._records.move_to_end(rid)
        while len(self._records) > MAX_RECORDS:
            self._records.popitem(last=False)

    def query(self, rid: Any) -> dict:
        """What became of the request with the client's id ``rid``: the answer it got or will get."""
        rid = _rid(rid)
        if rid is None:
            return {"ok": False, "state": "unknown", "status": "no request id given"}
        with self._lock:
            rec = self._records.get(rid)
        return dict(rec) if rec is not None else \
            {"ok": False, "state": "unknown", "status": f"no request {clip_repr(rid)} known to this server", "id": rid}

    def _wait(self, seq: int, waiter: tuple[threading.Event, dict], rid: str | None, wait: float,
              client: Any) -> dict:  # fmt: skip
        """The loop's answer to a service call, or after ``wait`` seconds that it is pending. Longer than
        SERVICE_WAIT only while few calls wait that long (MAX_LONG, MAX_LONG_PER_CLIENT): the SDK's pool of
        threads for service calls is bounded, and an e-stop needs one."""
        with self._lock:
            long = wait > SERVICE_WAIT and sum(self._long.values()) < MAX_LONG and \
                self._long.get(client, 0) < MAX_LONG_PER_CLIENT  # fmt: skip
            if long:
                self._long[client] = self._long.get(client, 0) + 1
            else:
                wait = min(wait, SERVICE_WAIT)
        try:
            done = waiter[0].wait(wait)
        finally:
            if long:
                with self._lock:
                    self._long[client] -= 1
                    if not self._long[client]:
                        del self._long[client]
        with self._lock:
            self._waiters.pop(seq, None)
            if not done:
                return _answer({"ok": False, "state": "pending", "seq": seq,
                                "status": f"sent to the loop as request {seq}; no answer within {wait:g} s "
                                          "(ask /request for it later)"}, rid)  # fmt: skip
            self._flagged_calls.pop(seq, None)
            if rid is not None:  # (an e-stop answered before its id was known)
                self._record(rid, waiter[1])
        return _answer(waiter[1], rid)

    def settle(self, timeout: float = SETTLE_S) -> None:
        """Before the server stops (the run has ended): the calls the loop answered get their answers
        out, e.g. an e-stop's that ended the run (bounded; an unanswered call gets none anyway)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and any(done.is_set() for done, _ in list(self._waiters.values())):
            time.sleep(0.002)
        time.sleep(min(0.05, max(0.0, end - time.monotonic())))  # the SDK's thread writes the answer out

    def reported(self, ev: dict) -> None:
        """The loop applied (or refused) a request, or one change of a request of several (``ev["n"]``): take it
        in and, once the request is whole, answer its clients (a thread of the writer process)."""
        with self._lock:
            self._reports_seen += 1
            self._reports.notify_all()
            seq = ev["seq"]
            if ev["kind"] == "set" and ev["status"] == "applied":
                self.space.values[ev["name"]] = ev["new"]
                h = self._history.setdefault(ev["name"], deque(maxlen=HISTORY))
                h.append((int(ev["tick"]), ev["old"], ev["new"]))
            parts = self._parts.setdefault(seq, [])
            parts.append(ev)
            whole = len(parts) >= int(ev.get("n", 1))
            if whole:
                del self._parts[seq]
                answered = [seq]
                if ev["kind"] in FLAGGED:  # the log names its client; earlier calls of the kind get this answer too
                    call = self._flagged_calls.pop(seq, None)
                    if call is not None:
                        ev["who"] = call[1]
                    # a snapshot: a handler thread may add a call meanwhile (without the lock, before its flag)
                    answered += [q for q, (kind, _) in list(self._flagged_calls.items())
                                 if kind == ev["kind"] and q < seq]  # fmt: skip
                    for q in answered[1:]:
                        self._flagged_calls.pop(q, None)
                applied = ev["status"] == "applied"
                self.counts["applied" if applied else "refused"] += 1
                resp = {"ok": applied, "state": "applied" if applied else "refused", "status": ev["status"],
                        "tick": ev["tick"], "t": ev["t"], "seq": seq}  # fmt: skip
                if ev["kind"] == "set":
                    resp["items"] = [{"name": e["name"], "old": _text(e["old"]), "new": _text(e["new"])} for e in parts]
                for q in answered:
                    rid = self._ids.pop(q, None)
                    if rid is not None:
                        self._record(rid, resp)
                    waiter = self._waiters.get(q)
                    if waiter is not None:
                        waiter[1].update(resp)
                        waiter[0].set()
        if ev["kind"] == "set" and whole and self.server is not None:  # applied: the new values; refused: the old
            try:
                self.server.publish_parameter_values([self._param(e["name"]) for e in parts
                                                      if e["name"] in self.space.params])  # fmt: skip
            except Exception:  # noqa: BLE001 - the server is going away
                pass
        if ev["status"] != "applied" and whole:
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
            self.server.publish_status(clip(message, 300), StatusLevel.Error if error else StatusLevel.Info)
        except Exception:  # noqa: BLE001
            pass


def _items(action: str, body: dict, switchable: list[str]) -> tuple[list[tuple[str, Any]], str | None]:
    """The changes a /set or /switch call asks for, or why it is refused (a switch names switchable parts)."""
    if action == "set":
        params = body.get("parameters")
        if not isinstance(params, dict):
            return [], "parameters must be a JSON object {name: value, ...}"
        items = [(str(k)[:MAX_TEXT], v) for k, v in params.items()]
    else:
        parts = body.get("parts")
        if parts is None and "part" in body:
            parts = {body.get("part"): body.get("to")}
        if not isinstance(parts, dict):
            return [], "give parts as {part: choice, ...}, or part and to"
        items = [(str(k)[:MAX_TEXT], v) for k, v in parts.items()]
        wrong = next((k for k, _ in items if k not in switchable), None)
        if wrong is not None:
            return items, f"part must be one of {', '.join(switchable) or '(none)'}, got {clip_repr(wrong)}"
    return items, None


def _wait_of(body: Any) -> float:
    """How long a service call may wait for the loop [s]: its body's ``wait`` (bounded), else SERVICE_WAIT."""
    w = body.get("wait") if isinstance(body, dict) else None
    if isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w):
        return min(max(float(w), 0.0), MAX_SERVICE_WAIT)
    return SERVICE_WAIT


def _answer(resp: dict, rid: str | None) -> dict:
    return {**resp, "id": rid} if rid is not None else dict(resp)


def _body(req: Any) -> Any:
    """A service call's JSON body, or None (not JSON, or larger than MAX_BODY: not even parsed)."""
    payload = bytes(req.payload)
    if req.encoding != "json" or len(payload) > MAX_BODY:
        return None
    try:
        return json.loads(payload or b"{}")
    except ValueError:
        return None


def _rid(rid: Any) -> str | None:
    """A client's request id as kept (cut short), or None."""
    return clip(rid) if isinstance(rid, str) and rid else None


def _named(body: Any) -> str:
    """The name a client gave itself in a service call's body (``who``), cut short, for the log."""
    who = body.get("who") if isinstance(body, dict) else None
    return f" ({clip(who)})" if isinstance(who, str) and who else ""


def _short(value: Any) -> Any:
    return value if isinstance(value, (bool, int, float)) or value is None else clip_repr(value, MAX_TEXT)


def _text(v: Any) -> str:
    """A reported value as text (as /params shows it)."""
    return "" if v is None else repr(v) if isinstance(v, float) else str(v)


def _who_id(client_id: Any) -> str:
    return f"foxglove client {client_id}"


def _who(client: Any, request_id: str | None) -> str:
    base = _who_id(getattr(client, "id", "?"))
    return f"{base} ({clip(str(request_id))})" if request_id else base


__all__ = ["BURST", "FLAGGED", "LiveControl", "MAX_FRAME", "RATE", "TokenBucket"]
