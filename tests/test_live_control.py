"""Live control fair to every operator, requests applied whole or not at all, echoes cut short, one answer per
request with an exit code that says applied (0), refused (2) or unknown (4), refusals logged at the tick they
were decided with the value in force then, a stable /status schema name.

The in-process tests drive `LiveControl` and `Operator` directly; the others run real processes: `bench run
--realtime --live` on the mock rig, `bench set|switch|mark|stop` as the operator would type them, a flooding
WebSocket client, and a server that never answers.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from bench.daq import LogReader

ROOT = Path(__file__).resolve().parents[1]
SUBPROTOCOLS = ["foxglove.sdk.v1"]
BIG = 100_000  # characters of an oversized argument
ECHO = 200  # characters at most of any reply, error line or log field that echoes one


def _space():  # the FOC's and the session's parameters on the mock rig
    from bench.core.config import load
    from bench.operate.requests import ParamSpace
    from bench.runtime.compose import build_rig, make_controller

    cfg = load("mock")
    return ParamSpace.of(make_controller(cfg, build_rig(cfg, 0), "foc", {}), cfg.limits, 10.0)


def _bench(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def _start(log: Path, *args: str) -> tuple[subprocess.Popen, str]:
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--duration", "120",
                          "--log", str(log), "--live", "--live-port", "0", *args], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    line = p.stderr.readline()
    assert line.startswith("bench: live: ws://127.0.0.1:"), line
    return p, line.split("ws://127.0.0.1:")[1].split()[0]


def _end(p: subprocess.Popen, port: str) -> tuple[str, str]:
    stop = _bench("stop", "--port", port)
    try:
        return p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
        assert stop.returncode in (0, 2, 4), stop.stderr  # the run may have ended on its own (a trip): not asserted


def _one_line(q: subprocess.CompletedProcess, code: int, most: int = 600) -> str:
    """The one line on stderr of a command that exited with ``code`` (at most ``most`` characters)."""
    assert q.returncode == code, (q.returncode, q.stdout[:300], q.stderr[:300])
    assert q.stderr.count("\n") == 1 and len(q.stderr) <= most, q.stderr[:300]
    return q.stderr


# ------------------------------------------------------------------------------------------------ in-process
def test_the_rate_limit_is_per_client_and_never_holds_back_an_estop():
    from bench.daq.live_control import RATE, LiveControl

    posted: list[bytes] = []
    flags: list[tuple[str, int]] = []
    lc = LiveControl(_space(), lambda frame: posted.append(frame) or True, lambda kind, seq: flags.append((kind, seq)))
    answers = [lc._request("set", [("flux_Km", 4.0 + i * 1e-3)], None, "flooder", 1, None) for i in range(500)]
    refused = [a for a in answers if a["state"] == "refused"]
    assert len(refused) >= 500 - 2 * RATE and all(a["status"] == f"refused: rate limit: {RATE:g} requests/s per client"
                                                  for a in refused)  # fmt: skip
    assert lc._request("set", [("speed_Kp", 0.8)], None, "bench set", 2, "id-2")["state"] == "pending"
    assert lc._request("mark", [], "during the flood", "bench mark", 3, None)["state"] == "pending"
    assert lc.query("id-2")["state"] == "pending"
    th = threading.Thread(target=lambda: lc._flagged("estop", SimpleNamespace(client_id=1, encoding="json",
                                                                              payload=b"{}")), daemon=True)  # fmt: skip
    th.start()  # the flooder's own e-stop: flagged at once (its answer waits for the loop, on its own thread)
    end = time.monotonic() + 10
    while not flags and time.monotonic() < end:
        time.sleep(0.001)
    assert [k for k, _ in flags] == ["estop"] and lc.counts["rate_limited"] == len(refused)


def test_a_refusal_is_logged_at_the_tick_decided_with_the_value_in_force_then():
    """The loop applied speed_Kp 0.6 -> 0.8 at tick 100 and 0.8 -> 0.9 at tick 300 (reported at once); the server
    refuses speed_Kp = 500 while the loop has published up to tick 150, and one report the loop has sent has not
    been taken in yet: the refusal waits for it, and logs tick 150 with 0.8, not the start value, not 0.9."""
    from bench.daq.live_control import LiveControl

    now = [(150, 0.05, 1_000_150)]
    sent = [2]
    lc = LiveControl(_space(), lambda frame: True, lambda kind, seq: None, lambda: now[0], lambda: sent[0])
    lc.reported({"seq": 1, "kind": "set", "name": "speed_Kp", "old": 0.6, "new": 0.8, "status": "applied",
                 "tick": 100, "t": 0.033, "who": "a"})  # fmt: skip
    late = threading.Timer(0.01, lc.reported, args=({"seq": 2, "kind": "set", "name": "speed_Kp", "old": 0.8,
                                                     "new": 0.9, "status": "applied", "tick": 300, "t": 0.1,
                                                     "who": "b"},))  # fmt: skip
    late.start()
    resp = lc._request("set", [("speed_Kp", 500.0)], None, "c", 7, None)
    late.join()
    assert resp["state"] == "refused" and "(0, 100]" in resp["status"]
    ev = lc.refusals[-1]
    assert (ev["tick"], ev["t"], ev["log_time"], ev["old"], ev["new"]) == (150, 0.05, 1_000_150, 0.8, 500.0), ev
    now[0] = (400, 0.13, 1_000_400)
    lc._request("set", [("speed_Kp", 600.0)], None, "c", 7, None)
    assert (lc.refusals[-1]["tick"], lc.refusals[-1]["old"]) == (400, 0.9)


def test_a_request_of_several_changes_is_answered_once_all_are_reported_and_set_parameters_replies_settled():
    from bench.daq.live_control import LiveControl

    lc = LiveControl(_space(), lambda frame: True, lambda kind, seq: None)
    out: dict = {}
    handler = lc._handler("switch")
    body = json.dumps({"parts": {"observer": "jl", "speed_source": "estimate"}, "id": "sw1"}).encode()
    th = threading.Thread(target=lambda: out.update(json.loads(handler(SimpleNamespace(
        client_id=5, encoding="json", payload=body)))), daemon=True)  # fmt: skip
    th.start()
    end = time.monotonic() + 10
    while lc.query("sw1")["state"] != "pending" and time.monotonic() < end:
        time.sleep(0.001)
    seq = lc.query("sw1")["seq"]
    for name, old, new in (("observer", "current_model", "jl"), ("speed_source", "encoder", "estimate")):
        assert not out  # not answered before the last change is reported
        lc.reported({"seq": seq, "kind": "set", "name": name, "old": old, "new": new, "status": "applied", "tick": 9,
                     "t": 0.003, "who": "x", "n": 2})  # fmt: skip
    th.join(10)
    assert out["state"] == "applied" and out["id"] == "sw1" and [i["name"] for i in out["items"]] == \
        ["observer", "speed_source"] and lc.query("sw1")["state"] == "applied"  # fmt: skip
    # setParameters: a change sent to the loop is not echoed with its old value; a refused one is, as in force
    client = SimpleNamespace(id=6)
    param = SimpleNamespace(name="speed_Kp", get_value=lambda: 0.8)
    assert lc.on_set_parameters(client, [param], "r1") == []
    bad = SimpleNamespace(name="speed_Kp", get_value=lambda: -1.0)
    (reply,) = lc.on_set_parameters(client, [bad], "r2")
    assert reply.name == "speed_Kp" and reply.get_value() == 0.6


def test_the_loop_applies_a_request_whole_or_not_at_all():
    """A FOC on the mock rig and the loop's operator: a multi-part switch with a part that cannot be had changes
    nothing; a valid one switches both between the same two ticks; a set whose second gain is refused leaves the
    first one as it was; a request mixing switches and gains is refused."""
    from bench.core.config import load
    from bench.operate.operator import Operator
    from bench.operate.requests import ParamSpace, ReplaySource, Request
    from bench.runtime.compose import build_rig, make_controller

    cfg = load("mock")
    ctrl = make_controller(cfg, build_rig(cfg, 0), "foc", {"speed_estimator": "rotor_equation",
                                                           "lpv_speed_artifact": "/nonexistent/speed"})  # fmt: skip
    ctrl.prepare_switching()
    space = ParamSpace.of(ctrl, cfg.limits, 10.0)
    reqs = [Request(1, "set", who="t", tick=1, items=(("speed_source", "estimate"), ("speed_controller", "lpv"))),
            Request(2, "set", who="t", tick=2, items=(("observer", "jl"), ("speed_source", "estimate"))),
            Request(3, "set", who="t", tick=3, items=(("speed_Kp", 0.9), ("current_wc", 500.0))),
            Request(4, "set", who="t", tick=4, items=(("current_controller", "lpv"),)),
            Request(5, "set", who="t", tick=5, items=(("sensorless_speed_Kp", 0.4), ("current_wc", 600.0))),
            Request(6, "set", who="t", tick=6, items=(("observer", "current_model"), ("speed_Kp", 0.7)))]
    events: list[dict] = []
    op = Operator(ctrl, space, ReplaySource(reqs), events.append, lambda why: None)
    for k in range(1, 7):
        op.service(k, k / 3000)
    by = {k: [e for e in events if e["tick"] == k] for k in range(1, 7)}
    assert [e["status"].startswith("refused") and "lpv cannot be had" in e["status"] for e in by[1]] == [True, True]
    assert [(e["name"], e["old"], e["new"], e["status"]) for e in by[2]] == \
        [("observer", "current_model", "jl", "applied"), ("speed_source", "encoder", "estimate", "applied")]  # fmt: skip
    assert all(e["status"] == "applied" for e in by[3]) and ctrl.p["current_wc"] == 500.0
    assert by[4][0]["status"] == "applied"
    assert all("not the PI" in e["status"] and "none applied" in e["status"] for e in by[5]), by[5]
    assert ctrl.p["sensorless_speed_Kp"] == 0.3 and ctrl.speed.K_p == 0.3  # the first change undone, exactly
    assert all("not both" in e["status"] for e in by[6]) and ctrl.p["observer"] == "jl"
    assert (ctrl.p["speed_source"], ctrl.p["speed_controller"], ctrl.p["current_controller"]) == \
        ("estimate", "pi", "lpv")  # fmt: skip


# ------------------------------------------------------------------------------------------------ real processes
def _flood(port: str, stop: threading.Event, out: dict) -> None:
    """One client: setParameters every millisecond (without waiting for anything), reading what it is told."""
    from websockets.sync.client import connect

    with connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        statuses: list[str] = out.setdefault("status", [])

        def read() -> None:
            try:
                while True:
                    m = ws.recv()
                    if isinstance(m, str) and json.loads(m).get("op") == "status":
                        statuses.append(json.loads(m)["message"])
            except Exception:  # noqa: BLE001 - closed
                pass

        threading.Thread(target=read, daemon=True).start()
        n, t0 = 0, time.monotonic()
        while not stop.is_set():
            ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "flux_Km", "value": 4.0 + (n % 100) * 1e-3,
                                                                       "type": "float64"}]}))  # fmt: skip
            n += 1
            time.sleep(max(0.0, t0 + n * 1e-3 - time.monotonic()))
        out["sent"] = n


def _watch(ws: object) -> tuple[dict, dict]:
    """A second client, as Foxglove's Parameters panel: subscribed to /params and to parameter updates."""
    chans: dict = {}
    while not {"/params", "/status"} <= set(chans):
        m = json.loads(ws.recv(timeout=30))  # type: ignore[attr-defined]
        if m.get("op") == "advertise":
            chans.update({c["topic"]: c for c in m["channels"]})
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [  # type: ignore[attr-defined]
        {"id": 1, "channelId": chans["/params"]["id"]}]}))  # fmt: skip
    ws.send(json.dumps({"op": "subscribeParameterUpdates",  # type: ignore[attr-defined]
                        "parameterNames": ["speed_Kp", "speed_Ti"]}))  # fmt: skip
    return chans, {"params": [], "values": [], "replies": {}}


def _read(ws: object, seen: dict, until: float) -> None:
    from bench.daq.events import decode

    while time.monotonic() < until:
        try:
            m = ws.recv(timeout=0.1)  # type: ignore[attr-defined]
        except TimeoutError:
            continue
        if isinstance(m, bytes) and m[0] == 1:
            seen["params"].append(decode("/params", m[13:]))
        elif isinstance(m, str) and json.loads(m).get("op") == "parameterValues":
            msg = json.loads(m)
            (seen["replies"].__setitem__(msg["id"], msg["parameters"]) if "id" in msg else
             seen["values"].extend(msg["parameters"]))  # fmt: skip


@pytest.mark.realtime
def test_a_flooding_client_does_not_starve_another_and_replies_carry_settled_values(tmp_path):
    from websockets.sync.client import connect

    log = tmp_path / "flood.mcap"
    p, port = _start(log, "--scenario", "fig5.7")
    stop, flood = threading.Event(), {}
    flooder = threading.Thread(target=_flood, args=(port, stop, flood), daemon=True)
    try:
        ws = connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, max_size=None).__enter__()
        chans, seen = _watch(ws)
        assert (chans["/status"]["schemaName"], chans["/status"]["encoding"]) == ("imbench_msgs/msg/Status", "json")
        flooder.start()
        time.sleep(1.0)  # the flood is on
        q = _bench("set", "speed_Kp=0.8", "--port", port)
        assert q.returncode == 0 and q.stdout.startswith("speed_Kp: 0.6 -> 0.8 at tick"), (q.stdout, q.stderr)
        m = _bench("mark", "during the flood", "--port", port)
        assert m.returncode == 0 and m.stdout.startswith("mark: applied at tick"), (m.stdout, m.stderr)
        # Foxglove's way: setParameters with an id; the reply holds only settled values
        ws.send(json.dumps({"op": "setParameters", "id": "ti", "parameters": [{"name": "speed_Ti", "value": 0.05,
                                                                                "type": "float64"}]}))  # fmt: skip
        ws.send(json.dumps({"op": "setParameters", "id": "kp", "parameters": [{"name": "speed_Kp", "value": 500.0,
                                                                                "type": "float64"}]}))  # fmt: skip
        end = time.monotonic() + 60
        while time.monotonic() < end and not ({"ti", "kp"} <= set(seen["replies"]) and any(
                v["name"] == "speed_Ti" for v in seen["values"])):  # fmt: skip
            _read(ws, seen, time.monotonic() + 0.5)
        stop.set()
        flooder.join(30)
        _read(ws, seen, time.monotonic() + 1.0)
        ws.close()
    finally:
        stop.set()
        out, err = _end(p, port)
    assert seen["replies"]["ti"] == [], seen["replies"]  # pending: not the old 0.04
    assert [v["value"] for v in seen["values"] if v["name"] == "speed_Ti"][-1] == 0.05  # once applied
    assert [v["value"] for v in seen["replies"]["kp"]] == [0.8]  # refused: the value in force
    kp = [e for e in seen["params"] if e["name"] == "speed_Kp" and e["status"] == "applied"]
    assert kp and kp[0]["new_text"] == "0.8" and "bench set" in kp[0]["who"]  # on /params, with its value
    assert any("rate limit: 50 requests/s per client" in s for s in flood["status"]), flood["status"][:3]
    assert flood["sent"] > 500
    summary = json.loads((tmp_path / "flood.summary.json").read_text())
    assert summary["operator"]["server"]["rate_limited"] > 0
    evs = LogReader(log).events()
    kp_log = [e for e in evs if e.get("name") == "speed_Kp"]
    assert [(e["new_text"], e["status"][:7]) for e in kp_log] == [("0.8", "applied"), ("500.0", "refused")]
    assert kp_log[1]["old_text"] == "0.8" and kp_log[0]["tick"] <= kp_log[1]["tick"] < evs[-1]["tick"]
    assert any(e["kind"] == "mark" and e["note"] == "during the flood" for e in evs)


@pytest.mark.realtime
def test_multi_switch_all_or_none_echoes_cut_short_and_exit_codes(tmp_path):
    log = tmp_path / "sw.mcap"
    p, port = _start(log, "--scenario", "load-step", "--scenario-arg", "speed=100", "--scenario-arg", "load=2",
                     "-p", "speed_estimator=rotor_equation", "-p", "lpv_speed_artifact=/nonexistent")  # fmt: skip
    try:
        # one valid part and one that cannot be had: nothing switched, one line, exit 2
        bad = _bench("switch", "speed_source=estimate", "speed_controller=lpv", "--port", port)
        assert "speed_controller" in _one_line(bad, 2) and "none applied" in bad.stderr
        # oversized arguments: refused, and no reply, error line or log entry echoes them whole (a 10 kB one is
        # read: the line may list what is allowed, and holds at most 80 characters of it)
        for args in (("switch", f"observer={'x' * BIG}"), ("switch", f"{'x' * BIG}=jl"), ("set", f"speed_Kp={'x' * BIG}"),
                     ("set", f"{'y' * BIG}=1"), ("mark", "z" * BIG)):  # fmt: skip
            _one_line(_bench(*args, "--port", port), 2, ECHO)
        for args in (("switch", f"observer={'x' * 10_000}"), ("switch", f"{'x' * 10_000}=jl"),
                     ("set", f"speed_Kp={'x' * 10_000}"), ("set", f"{'y' * 10_000}=1")):  # fmt: skip
            q = _bench(*args, "--port", port)
            assert q.returncode == 2 and q.stderr.count("\n") == 1, q.stderr[:300]
            assert "x" * 81 not in q.stderr and "y" * 81 not in q.stderr and len(q.stderr) < 500, q.stderr
        # refused: exit 2 with the reason, for set, switch and mark
        assert "speed_Kp" in _one_line(_bench("set", "speed_Kp=-1", "--port", port), 2)
        assert "observer" in _one_line(_bench("switch", "observer=nope", "--port", port), 2)
        assert "bytes as encoded" in _one_line(_bench("mark", "\U0001F600" * 1000, "--port", port), 2)
        # applied: exit 0, both parts at one tick
        ok = _bench("switch", "observer=jl", "speed_source=estimate", "--port", port)
        assert ok.returncode == 0, ok.stderr
        lines = ok.stdout.splitlines()
        assert [ln.split(" at tick")[0] for ln in lines] == ["observer -> jl", "speed_source -> estimate"]
        assert lines[0].split(" at tick")[1] == lines[1].split(" at tick")[1]
        assert _bench("mark", "switched", "--port", port).returncode == 0
        assert _bench("set", "sensorless_speed_Kp=0.35", "--port", port).returncode == 0
        # no answer: the loop process stopped (the writer process and its server go on): exit 4, one line each
        os.kill(p.pid, signal.SIGSTOP)
        try:
            for args in (("set", "speed_Kp=0.9"), ("switch", "observer=current_model"), ("mark", "stopped"), ("stop",)):
                err = _one_line(_bench(*args, "--timeout", "1.5", "--port", port), 4)
                assert "unknown" in err and "pending in the loop" in err, err
            late = subprocess.Popen([sys.executable, "-m", "bench", "set", "speed_Ti=0.05", "--timeout", "60",
                                     "--port", port], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True)  # fmt: skip
            time.sleep(2.0)  # the request waits in the loop's pipe (the server holds the call)
        finally:
            os.kill(p.pid, signal.SIGCONT)
        out, err = late.communicate(timeout=120)
        assert late.returncode == 0 and out.startswith("speed_Ti: 0.04 -> 0.05 at tick"), (out, err)  # once it ran
    finally:
        if p.poll() is None:
            os.kill(p.pid, signal.SIGCONT)
        out, err = _end(p, port)
    evs = LogReader(log).events()
    for e in evs:  # every text field of the log is cut short
        assert all(len(str(v)) <= 2 * ECHO + 1 and "x" * 101 not in str(v) and "y" * 101 not in str(v)
                   for v in e.values()), {k: str(v)[:100] for k, v in e.items()}  # fmt: skip
    first = [e for e in evs if e.get("name") in ("speed_source", "speed_controller")][:2]
    assert [e["status"][:7] for e in first] == ["refused", "refused"] and first[0]["seq"] == first[1]["seq"]
    switched = [e for e in evs if e["status"] == "applied" and e.get("name") in ("observer", "speed_source")][:2]
    assert [(e["name"], e["new_text"]) for e in switched] == [("observer", "jl"), ("speed_source", "estimate")]
    assert switched[0]["tick"] == switched[1]["tick"] and switched[0]["seq"] == switched[1]["seq"]


def test_an_answer_that_comes_after_pending_is_still_applied_exit_0():
    """A real server (in-process) whose loop answers only after the server has told `bench set` "pending": the
    client asks after its request by id and reports it applied, late (exit 0); one the loop never answers is
    unknown (exit 4)."""
    from bench.daq import Topic
    from bench.daq.live import LiveStream
    from bench.daq.live_control import LiveControl

    posted: list[bytes] = []
    lc = LiveControl(_space(), lambda frame: posted.append(frame) or True, lambda kind, seq: None)
    live = LiveStream([Topic("/rig", "imbench_msgs/msg/Dummy", [("t", "float64"), ("tick", "int64")])],
                      "127.0.0.1", 0, 1, lc)  # fmt: skip
    try:
        q = subprocess.Popen([sys.executable, "-m", "bench", "set", "speed_Kp=0.8", "--timeout", "3", "--port",
                              str(live.port)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
        lc_wait = time.monotonic() + 60
        while not (posted and not lc._waiters) and time.monotonic() < lc_wait:  # posted, and the call answered
            time.sleep(0.01)
        assert posted and not lc._waiters
        from bench.operate.requests import Request

        req = Request.decode(posted[0])
        lc.reported({"seq": req.seq, "kind": "set", "name": "speed_Kp", "old": 0.6, "new": 0.8, "status": "applied",
                     "tick": 42, "t": 0.014, "who": req.who})  # fmt: skip
        out, err = q.communicate(timeout=120)
        assert q.returncode == 0 and out == "speed_Kp: 0.6 -> 0.8 at tick 42 (t = 0.0140 s) (the answer came late)\n", \
            (out, err)  # fmt: skip
        never = _bench("mark", "x", "--timeout", "1", "--port", str(live.port))
        assert "pending in the loop" in _one_line(never, 4)
    finally:
        live.stop()


class _Mute:
    """A server that speaks enough of the protocol to be called and never answers a call."""

    def __enter__(self) -> str:
        from websockets.sync.server import serve

        def handler(ws: object) -> None:
            svc = [{"id": i, "name": f"/{n}", "type": n} for i, n in
                   enumerate(("set", "switch", "stop", "estop", "mark", "request"), 1)]  # fmt: skip
            ws.send(json.dumps({"op": "serverInfo", "name": "mute", "capabilities": ["services"]}))  # type: ignore[attr-defined]
            ws.send(json.dumps({"op": "advertiseServices", "services": svc}))  # type: ignore[attr-defined]
            for _ in ws:  # type: ignore[attr-defined]
                pass

        self.server = serve(handler, "127.0.0.1", 0, subprotocols=SUBPROTOCOLS)  # type: ignore[arg-type]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        return str(self.server.socket.getsockname()[1])

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()


def test_no_answer_from_a_server_that_never_answers_is_exit_4():
    with _Mute() as port:
        for args in (("set", "speed_Kp=0.8"), ("switch", "observer=jl"), ("mark", "x"), ("stop",), ("estop",)):
            err = _one_line(_bench(*args, "--timeout", "0.5", "--port", port), 4)
            assert err.startswith(f"bench: {args[0]}: unknown: no answer") and "live server did not answer" in err


@pytest.mark.parametrize("cmd", ["set", "switch", "mark", "stop", "estop"])
def test_the_exit_codes_are_in_the_help(cmd):
    q = _bench(cmd, "--help")
    assert q.returncode == 0 and "0 applied" in q.stdout and "2 refused" in q.stdout and "4 no answer" in q.stdout
