"""On-line parameters, operator actions and their replay (issue 11, parts 2-4).

In-process: the parameter space's checks, the event messages (decoded by mcap-ros2-support, not by
our own decoder), and a replayed schedule applied at its ticks in lockstep (set, override, mark,
stop; e-stop). Subprocess: a real-time `bench run --live` driven by a protocol-level WebSocket
client and by `bench set|mark|stop`, hostile requests and a flood included, then replayed offline.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from bench.daq import LogReader, LogWriter, Topic
from bench.daq.events import EVENTS, PARAMS, schema_text
from bench.errors import BadInput
from bench.operate.operator import STOP_HOLD, STOP_RAMP
from bench.operate.requests import OFF, ParamSpace
from bench.runtime.session import RunOptions, run

ROOT = Path(__file__).resolve().parents[1]
RATE = 3000.0


def _space() -> ParamSpace:
    from bench.controllers.base import ControllerContext  # noqa: F401 - the plugin's own imports
    from bench.controllers.foc import FocController
    from bench.operate.requests import session_params
    from bench.core.supervisor import Limits

    tun = {k: p for k, p in FocController.schema.items() if p.tunable}
    fixed = [k for k in FocController.schema if k not in tun]
    return ParamSpace(tun | session_params(Limits(), 15.0), {k: p.default for k, p in tun.items()}, fixed)


@pytest.mark.parametrize("name, value, words", [
    ("nope", 1.0, "unknown"),
    ("voltage_source", "measured", "cannot change while running"),
    ("speed_Kp", "fast", "must be a number"),
    ("speed_Kp", 1e9, "(0, 100]"),
    ("speed_Kp", -1.0, "(0, 100]"),
    ("speed_Kp", {"a": 1}, "must be a number"),
    ("omega_r_ref_override", 1e4, "[-320, 320]"),  # 20 % inside the over-speed trip (400)
    ("omega_r_ref_override", 330.0, "[-320, 320]"),
    ("m_l_ref_override", -12.5, "[-12, 12]"),  # inside the load drive's clip (15)
    ("i_mr_ref_override", 8.5, "(0, 8]"),  # inside I_max (10)
    ("speed_Kp", OFF, "must be a number"),  # 'off' only for overrides
    ("omega_r_ref_override", "2 rad/s", "or 'off'"),  # text that is neither a number nor 'off'
    ("omega_r_ref_override", "nan", "must be a number"),
    ("omega_r_ref_override", "1e4", "[-320, 320]"),  # a numeric string is checked like the number (0.8 omega_max)
])  # fmt: skip
def test_param_space_refuses_with_the_name_and_what_is_allowed(name, value, words):
    with pytest.raises(BadInput) as e:
        _space().check(name, value)
    assert words in str(e.value)


def test_param_space_accepts_and_normalises():
    sp = _space()
    assert sp.check("speed_Kp", 1) == 1.0 and isinstance(sp.check("speed_Kp", 1), float)
    assert sp.check("omega_r_ref_override", "off") == OFF and sp.check("omega_r_ref_override", -50) == -50.0
    # the override is advertised as the text 'off', so a client's text field sends numbers as strings
    assert sp.check("omega_r_ref_override", "2") == 2.0 and sp.check("m_l_ref_override", " -1.5 ") == -1.5
    assert sp.check("i_mr_ref_override", "OFF") == OFF
    back = ParamSpace.from_description(json.loads(json.dumps(sp.describe())))  # what the writer process gets
    assert back.params.keys() == sp.params.keys() and back.fixed == sp.fixed
    with pytest.raises(BadInput):
        back.check("speed_Kp", 1e9)


def test_event_messages_decode_with_mcap_ros2(tmp_path):
    """Our CDR of /params and /events, read by an independent decoder (mcap-ros2-support)."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    from bench.daq.events import encode

    ev = {"seq": 7, "tick": 1234, "t": 0.41133, "kind": "set", "name": "speed_Kp", "who": "client 1 (\u00e9)",
          "old": 0.6, "new": 0.75, "note": "", "status": "applied"}  # fmt: skip
    topic, data = encode(ev)
    dec = DecoderFactory().decoder_for("cdr", Schema(id=1, name=PARAMS[1], encoding="ros2msg", data=schema_text(PARAMS[2]).encode()))
    m = dec(data)
    assert topic == "/params" and (m.tick, m.t, m.name, m.old_value, m.new_value) == (1234, 0.41133, "speed_Kp", 0.6, 0.75)
    assert (m.new_text, m.who, m.status, m.seq) == ("0.75", "client 1 (\u00e9)", "applied", 7)
    topic, data = encode({**ev, "kind": "mark", "note": "rotor hot"})
    m = DecoderFactory().decoder_for("cdr", Schema(id=2, name=EVENTS[1], encoding="ros2msg", data=schema_text(EVENTS[2]).encode()))(data)
    assert topic == "/events" and (m.kind, m.note, m.tick) == ("mark", "rotor hot", 1234)


def _schedule_log(path: Path, events: list[dict]) -> Path:
    """A log holding only a schedule of applied requests (as a live run's log would)."""
    sp = _space()
    w = LogWriter(path, [Topic("/rig", "imbench_msgs/msg/Dummy", [("t", "float64"), ("tick", "int64")])],
                  metadata={"run": {"rate_hz": RATE}}, operator=sp.describe(), timing=False)  # fmt: skip
    for i, e in enumerate(events):
        base = {"seq": i + 1, "t": e["tick"] / RATE, "name": "", "who": "test", "old": None, "new": None, "note": "",
                "status": "applied", "log_time": int(e["tick"] / RATE * 1e9)}  # fmt: skip
        w.event({**base, **e})
    w.close()
    return path


def test_replay_applies_changes_and_actions_at_their_ticks(tmp_path):
    ticks = {"gain": 1500, "override": 2400, "mark": 3000, "refused": 3100, "stop": 4500}
    log = _schedule_log(tmp_path / "sched.mcap", [
        {"tick": ticks["gain"], "kind": "set", "name": "speed_Kp", "old": 0.6, "new": 0.9},
        {"tick": ticks["override"], "kind": "set", "name": "omega_r_ref_override", "old": OFF, "new": 50.0},
        {"tick": ticks["mark"], "kind": "mark", "note": "before the stop"},
        {"tick": ticks["refused"], "kind": "set", "name": "speed_Kp", "new": 1e9, "status": "refused: range"},
        {"tick": ticks["stop"], "kind": "stop"},
    ])  # fmt: skip
    summary, code = run(RunOptions(duration=5.0, replay_params=log, log_enabled=False, progress=False))
    assert code == 0 and summary["trip_cause"] is None
    op = summary["operator"]
    assert op["applied"] == 4 and op["ended_by"] == "operator stop"  # the refused one was never replayed
    rec = summary["record"]
    evs = rec.events()
    assert [(e["tick"], e["kind"], e["status"]) for e in evs] == [
        (ticks["gain"], "set", "applied"), (ticks["override"], "set", "applied"), (ticks["mark"], "mark", "applied"),
        (ticks["stop"], "stop", "applied")]  # fmt: skip
    assert evs[0]["old"] == 0.6 and evs[0]["new"] == 0.9 and evs[2]["note"] == "before the stop"
    r = rec.read("/rig")
    tick, w_ref, m_l = r["tick"].astype(int), r["omega_r_ref"], r["m_l_ref"]
    at = {k: int(np.flatnonzero(tick == v)[0]) for k, v in ticks.items()}
    assert w_ref[at["override"] - 1] != 50.0 and np.all(w_ref[at["override"] : at["stop"]] == 50.0)
    ramp = w_ref[at["stop"] :]
    expected = np.maximum(0.0, 50.0 - STOP_RAMP * (tick[at["stop"] :] - ticks["stop"]) / RATE)
    assert np.allclose(ramp, expected, atol=1e-9)  # the ramp from the reference in force, at STOP_RAMP
    assert np.all(m_l[at["stop"] :] == 0.0)  # no load command while stopping
    end = ticks["stop"] + round((50.0 / STOP_RAMP + STOP_HOLD) * RATE)
    assert abs(int(tick[-1]) - end) <= 1  # ramp, hold, then the run ends (normally)
    assert summary["ticks"] < 5.0 * RATE


def test_replayed_estop_is_safe_in_the_same_tick(tmp_path):
    log = _schedule_log(tmp_path / "sched.mcap", [{"tick": 2000, "kind": "estop"}])
    summary, code = run(RunOptions(duration=3.0, replay_params=log, log_enabled=False, progress=False))
    assert code == 1 and summary["trip_cause"].startswith("operator e-stop")
    r = summary["record"].read("/rig")
    i = int(np.flatnonzero(r["tick"] == 2000)[0])
    assert r["enable"][i - 1] and not r["enable"][i] and r["tripped"][i]  # that very tick: safe command
    assert r["u_s_ref_re"][i] == 0.0 and r["u_s_ref_im"][i] == 0.0


def test_replay_of_a_log_with_another_rate_is_refused(tmp_path):
    log = _schedule_log(tmp_path / "s.mcap", [{"tick": 10, "kind": "mark", "note": "x"}])
    other = tmp_path / "rig600.toml"
    other.write_text((ROOT / "rigs" / "mock.toml").read_text().replace("rate_hz = 3000", "rate_hz = 600"))
    if "rate_hz = 600" not in other.read_text():
        pytest.skip("mock rig file has no rate_hz line")
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--rig", str(other), "--replay-params", str(log),
                        "--log", str(tmp_path / "x.mcap")], cwd=ROOT, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2 and "--replay-params" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (tmp_path / "x.mcap").exists()


# ---------------------------------------------------------------------------------------------- live
def _bench(*args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def _assert_same_log(a: Path, b: Path) -> None:
    """Two logs hold the same rows, field for field (the loop's timing fields aside)."""
    from bench.runtime.loop import TIMING_FIELDS

    ra, rb = LogReader(a), LogReader(b)
    for topic in ("/rig", "/ctrl", "/truth"):
        ca, cb = ra.read(topic), rb.read(topic)
        for f in ca:
            if f not in TIMING_FIELDS:
                assert np.array_equal(ca[f], cb[f], equal_nan=True), (topic, f)


def _run_said(p: subprocess.Popen) -> str:
    """The run's own stderr once it has ended (why it ended early), else nothing: for an assertion's message."""
    return "" if p.poll() is None else "\nthe run ended early; it said:\n" + p.stderr.read()


def _protocol_session(port: int) -> dict:
    """What Foxglove's Parameters panel does, plus hostile requests and a flood of 1000 sets in ~1 s."""
    from websockets.sync.client import connect

    out: dict = {"status": []}
    with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        ws.send(json.dumps({"op": "getParameters", "parameterNames": [], "id": "all"}))
        while "all" not in out:
            m = json.loads(ws.recv(timeout=5))
            if m.get("op") == "parameterValues" and m.get("id") == "all":
                out["all"] = {p["name"]: p.get("value") for p in m["parameters"]}
        bad = [{"name": "nope", "value": 1.0}, {"name": "speed_Kp", "value": "fast"},
               {"name": "speed_Kp", "value": 1e9}, {"name": "voltage_source", "value": "measured"},
               {"name": "speed_Ti", "value": [1, 2]}]  # fmt: skip
        for i, p in enumerate(bad):  # one at a time, as the Parameters panel sends them (one message: one request)
            ws.send(json.dumps({"op": "setParameters", "parameters": [p], "id": f"bad{i}"}))
        ws.send(b"\x02\xff\xff\xff\xffgarbage")  # a service call to no service, cut short
        ws.send("{not json")
        t0 = time.monotonic()
        for i in range(1000):  # a flood: 1000 sets within about a second
            ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "flux_Km", "value": 4.0 + i * 1e-3,
                                                                       "type": "float64"}]}))  # fmt: skip
            if i % 100 == 99:
                time.sleep(max(0.0, (i + 1) / 1000 - (time.monotonic() - t0)))
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            try:
                m = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(m, str) and json.loads(m).get("op") == "status":
                out["status"].append(json.loads(m)["message"])
    return out


@pytest.mark.realtime
def test_live_parameters_actions_hostile_clients_and_replay(tmp_path):
    log = tmp_path / "live.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--duration", "30",
                          "--scenario", "fig5.7", "--log", str(log), "--live", "--live-port", "0"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        line = p.stderr.readline()
        assert line.startswith("bench: live: ws://127.0.0.1:"), line
        port = line.split("ws://127.0.0.1:")[1].split()[0]
        proto = _protocol_session(int(port))
        assert proto["all"]["speed_Kp"] == 0.6 and proto["all"]["omega_r_ref_override"] == OFF
        assert "voltage_source" not in proto["all"]  # not tunable: not offered
        assert any("unknown" in s for s in proto["status"]) and any("(0, 100]" in s for s in proto["status"])
        ok = _bench("set", "speed_Kp=0.7", "omega_r_ref_override=60", "--port", port)
        assert ok.returncode == 0, ok.stderr + _run_said(p)
        assert "speed_Kp: 0.6 -> 0.7 at tick" in ok.stdout and "omega_r_ref_override: off -> 60.0" in ok.stdout
        bad = _bench("set", "speed_Kp=-1", "--port", port)
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "speed_Kp" in bad.stderr, bad.stderr + _run_said(p)
        mark = _bench("mark", "gain step done", "--port", port)
        assert mark.returncode == 0 and "mark: applied at tick" in mark.stdout, mark.stderr + _run_said(p)
        stop = _bench("stop", "--port", port)
        assert stop.returncode == 0, stop.stderr + _run_said(p)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err  # the operator stop ends the run normally; nothing hostile disturbed it
    summary = json.loads((tmp_path / "live.summary.json").read_text())
    op = summary["operator"]
    assert op["ended_by"] == "operator stop" and summary["duration"] < 25
    assert op["server"]["rate_limited"] >= 800, op  # the flood: counted, at most the rate let through
    assert op["server"]["refused"] >= 6 and summary["deadline_misses"] < 0.05 * summary["ticks"], op

    evs = LogReader(log).events()
    applied = [e for e in evs if e["status"] == "applied"]
    names = [e.get("name") or e["kind"] for e in applied]
    assert names[-4:] == ["speed_Kp", "omega_r_ref_override", "mark", "stop"], names[-6:]
    refused = [e for e in evs if e["status"].startswith("refused")]
    assert {e["name"] for e in refused} >= {"nope", "speed_Kp", "voltage_source", "speed_Ti"}
    flux = [e for e in applied if e.get("name") == "flux_Km"]
    assert 20 <= len(flux) <= 150  # burst + rate x about a second of flood
    r = LogReader(log).read("/rig")
    k_override = next(e["tick"] for e in applied if e.get("name") == "omega_r_ref_override")
    i = int(np.flatnonzero(r["tick"] == k_override)[0])
    assert r["omega_r_ref"][i] == 60.0 and r["omega_r_ref"][i - 1] != 60.0  # applied at that very tick

    # replay offline (lockstep, mock rig): the same changes at the same ticks; twice the same run
    def replay(n: int) -> subprocess.CompletedProcess:
        return _bench("run", "--no-progress", "--scenario", "fig5.7", "--replay-params", str(log), "--duration", "30",
                      "--log", str(tmp_path / f"replay{n}.mcap"), timeout=120)  # fmt: skip

    with ThreadPoolExecutor(2) as pool:  # the two replays are independent processes: side by side
        done = list(pool.map(replay, (1, 2)))
    reps = []
    for n, q in zip((1, 2), done):
        assert q.returncode == 0, q.stderr
        reps.append(LogReader(tmp_path / f"replay{n}.mcap"))
    again = [e for e in reps[0].events() if e["status"] == "applied"]
    assert [(e["tick"], e["kind"], e.get("name"), e.get("new_text")) for e in again] == \
        [(e["tick"], e["kind"], e.get("name"), e.get("new_text")) for e in applied]  # fmt: skip
    a, b = reps[0].read("/ctrl"), reps[1].read("/ctrl")
    assert np.array_equal(a["omega_hat"], b["omega_hat"])  # a replay is deterministic
    # and it is the real-time run, to the bit: the same requests and the same loop stalls at the same ticks
    _assert_same_log(log, tmp_path / "replay1.mcap")


def test_lockstep_live_run_is_replayed_exactly(tmp_path):
    """A live run in lockstep, changed by a client while it runs, and its replay: the same log, field for
    field (timing fields aside)."""
    from websockets.sync.client import connect

    from bench.daq.events import decode

    # lockstep runs ~5x faster than real time: the client's connect and three round trips must fit in its few
    # seconds on a loaded machine (12 s of run ran out once); below COMPILED_FROM (25 s) the session keeps the
    # slower Python engine
    duration = 24
    log = tmp_path / "live.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--scenario", "fig5.8", "--duration",
                          str(duration), "--log", str(log), "--live", "--live-port", "0"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        port = p.stderr.readline().split("ws://127.0.0.1:")[1].split()[0]
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
            chans: dict = {}
            while "/params" not in chans:
                m = json.loads(ws.recv(timeout=10))
                if m.get("op") == "advertise":
                    chans.update({c["topic"]: c for c in m["channels"]})
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": chans["/params"]["id"]}]}))
            for name, value in (("speed_Kp", 0.9), ("omega_r_ref_override", 40.0), ("m_l_ref_override", 2.0)):
                ws.send(json.dumps({"op": "setParameters", "id": name, "parameters": [
                    {"name": name, "value": value, "type": "float64"}]}))  # fmt: skip
                while True:  # the loop's report, then the next change
                    m = ws.recv(timeout=10)
                    if isinstance(m, bytes) and m[0] == 1 and decode("/params", m[13:])["name"] == name:
                        break
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    applied = [e for e in LogReader(log).events() if e["status"] == "applied"]
    assert [e["name"] for e in applied] == ["speed_Kp", "omega_r_ref_override", "m_l_ref_override"]
    assert applied[-1]["tick"] < duration * RATE - 1  # all three came while it ran
    q = _bench("run", "--no-progress", "--scenario", "fig5.8", "--duration", str(duration), "--replay-params", str(log),
               "--log", str(tmp_path / "replay.mcap"), timeout=180)  # fmt: skip
    assert q.returncode == 0, q.stderr
    _assert_same_log(log, tmp_path / "replay.mcap")


@pytest.mark.realtime
def test_live_estop_is_safe_within_a_tick(tmp_path):
    log = tmp_path / "e.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--scenario", "fig5.7",
                          "--duration", "30", "--log", str(log), "--live", "--live-port", "0"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        port = p.stderr.readline().split("ws://127.0.0.1:")[1].split()[0]
        time.sleep(1.0)
        e = _bench("estop", "--port", port)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert e.returncode == 0 and "estop: applied at tick" in e.stdout, e.stderr
    assert p.returncode == 1 and "operator e-stop" in err, err
    k = int(e.stdout.split("tick ")[1].split()[0])
    r = LogReader(log).read("/rig")
    i = int(np.flatnonzero(r["tick"] == k)[0])
    assert r["tripped"][i] and not r["enable"][i:].any() and np.all(r["m_l_ref"][i:] == 0.0)  # that very tick
    assert r["enable"][:i].any()  # it was running before


# ------------------------------------------------------------------------- e-stop path, sizes, bounds
def test_inbox_gives_the_flags_first_and_never_blocks_on_a_torn_frame():
    """The loop's end of the requests, on a real pipe: e-stop and stop come from shared memory ahead of
    anything in the pipe; half a frame does not stall the loop, it marks the channel broken (a trip)."""
    import multiprocessing as mp
    import os
    import threading

    from bench.daq.writer import RequestInbox
    from bench.daq.writer_process import ESTOP, IDX_SLOTS, POSTED, STOP
    from bench.operate.requests import Request

    r, w = mp.Pipe(duplex=False)
    idx = mp.RawArray("q", IDX_SLOTS)
    inbox = RequestInbox(idx, r)
    assert not inbox.pending()
    w.send_bytes(Request(1, "set", "speed_Kp", 0.7, "t").encode())
    idx[POSTED] += 1
    os.write(w.fileno(), struct.pack("!i", 100) + b"x" * 10)  # a header promising 100 bytes, and 10 of them
    idx[POSTED] += 1
    idx[ESTOP] = 7
    assert inbox.pending()
    got: list = []
    th = threading.Thread(target=lambda: got.append(inbox.take(0)), daemon=True)
    th.start()
    th.join(5.0)
    assert not th.is_alive(), "the loop blocked on half a frame"
    (reqs,) = got
    assert [(q.kind, q.seq) for q in reqs] == [("estop", 7), ("set", 1)]
    assert inbox.broken and inbox.broken.startswith("live request channel broken")
    idx[STOP] = 9  # the flags still come through a broken pipe
    assert inbox.pending() and [(q.kind, q.seq) for q in inbox.take(1)] == [("stop", 9)]
    assert not inbox.pending()
    r.close()
    w.close()


def test_live_control_estop_bypasses_the_rate_limit_and_oversized_requests_are_never_written():
    """The server's side (in-process, the pipe and the flag replaced by recorders): with the rate limit
    exhausted, a set is refused but e-stops and a stop are flagged, even with a body of garbage or of
    1 MB (never parsed); the loop's answer to the latest e-stop answers an earlier one it superseded; a
    70 000-character note, a body above MAX_BODY and a 1000-character note that encodes to more than a
    pipe's atomic write are refused (and logged cut short) before anything is written; a
    1000-character ASCII note is written, whole."""
    import threading
    from types import SimpleNamespace

    from bench.daq.live_control import MAX_BODY, MAX_FRAME, LiveControl

    posted: list[bytes] = []
    flags: list[tuple[str, int]] = []
    lc = LiveControl(_space(), lambda frame: posted.append(frame) or True, lambda kind, seq: flags.append((kind, seq)))
    flood = lc._bucket("flood")  # the flooding client's budget: exhausted, for good
    flood.tokens, flood.rate = 0.0, 0.0
    resp = lc._request("set", [("speed_Kp", 0.7)], None, "flood", "flood", None)
    assert resp["state"] == "refused" and resp["status"] == "refused: rate limit: 50 requests/s per client", resp

    def call(body: bytes, encoding: str = "json") -> SimpleNamespace:
        return SimpleNamespace(client_id=3, encoding=encoding, payload=body)

    def flagged(kind: str, req: SimpleNamespace, out: dict) -> None:
        out[kind, req.payload[:8]] = lc._flagged(kind, req)

    answers: dict = {}
    calls = [("estop", call(b"\xff not json")), ("estop", call(b"{" * (1 << 20))), ("stop", call(b'{"who": "op"}'))]
    threads = []
    for kind, req in calls:  # one after the other, each flag raised before the next call
        threads.append(threading.Thread(target=flagged, args=(kind, req, answers), daemon=True))
        threads[-1].start()
        end = time.monotonic() + 5
        while len(flags) < len(threads) and time.monotonic() < end:
            time.sleep(0.001)
    assert [k for k, _ in flags] == ["estop", "estop", "stop"] and posted == []  # never through the pipe
    for kind, seq in flags[1:]:  # the loop reads the latest of each flag: the first e-stop is superseded
        ev = {"seq": seq, "kind": kind, "name": "", "who": "live client", "status": "applied", "tick": 7, "t": 0.1}
        lc.reported(ev)
        assert ev["who"] == "foxglove client 3" + (" (op)" if kind == "stop" else "")  # the log names the client
    for th in threads:
        th.join(5)
    assert len(answers) == 3 and all(a["ok"] and a["status"] == "applied" and a["tick"] == 7
                                     for a in answers.values()), answers  # fmt: skip

    for note, words in (("n" * 70_000, "at most 1000 characters, got 70000"),
                        ("\U0001F600" * 1000, "bytes as encoded")):  # fmt: skip
        resp = lc._request("mark", [], note, "hostile", "hostile", None)  # another client: its own budget
        assert not resp["ok"] and words in resp["status"], resp
        assert len(lc.refusals[-1]["note"]) <= 81  # the log keeps a cut copy
    resp = json.loads(lc._handler("mark")(call(json.dumps({"note": "n" * 70_000}).encode())))
    assert not resp["ok"] and f"at most {MAX_BODY} bytes" in resp["status"] and "refused" in lc.refusals[-1]["status"]
    for name, value in (("flux_Km", "x" * 1_000_000), ("y" * 1_000_000, 1.0)):  # a set of megabytes: not even repr'd
        lc.on_set_parameters(SimpleNamespace(id=4), [SimpleNamespace(name=name, get_value=lambda v=value: v)])
        ev = lc.refusals[-1]
        assert "too large" in ev["status"] and len(ev["name"]) <= 100 and len(str(ev["new"])) <= 100, ev
    assert posted == []
    resp = lc._request("mark", [], "n" * 1000, "operator", "operator", None)
    assert resp["state"] == "pending" and len(posted) == 1 and len(posted[0]) <= MAX_FRAME


def test_bench_mark_refuses_an_oversized_note_as_bad_input():
    p = _bench("mark", "n" * 70_000, "--port", "1")  # checked before connecting: no session needed
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "note: at most 1000 characters" in p.stderr, p.stderr


@pytest.mark.realtime
def test_live_estop_with_a_garbage_body_is_not_refused(tmp_path):
    """An e-stop whose payload is not JSON still stops the run (the server's checks of a body apply to notes,
    never to an e-stop)."""
    from websockets.sync.client import connect

    log = tmp_path / "g.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--scenario", "fig5.7",
                          "--duration", "30", "--log", str(log), "--live", "--live-port", "0"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        port = p.stderr.readline().split("ws://127.0.0.1:")[1].split()[0]
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
            sid = None
            while sid is None:
                m = ws.recv(timeout=10)
                if isinstance(m, str) and json.loads(m).get("op") == "advertiseServices":
                    sid = next(s["id"] for s in json.loads(m)["services"] if s["name"] == "/estop")
            time.sleep(1.0)
            ws.send(struct.pack("<BIII", 2, sid, 1, 4) + b"json" + b"\xff\x00 not json")
            while True:
                m = ws.recv(timeout=10)
                if isinstance(m, bytes) and m[0] == 3:  # serviceCallResponse
                    resp = json.loads(m[13 + struct.unpack_from("<III", m, 1)[2] :])
                    break
                assert not (isinstance(m, str) and json.loads(m).get("op") == "serviceCallFailure"), m
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert resp["ok"] and resp["status"] == "applied", resp
    assert p.returncode == 1 and "operator e-stop" in err, err
    r = LogReader(log).read("/rig")
    i = int(np.flatnonzero(r["tick"] == resp["tick"])[0])
    assert r["tripped"][i] and not r["enable"][i:].any() and r["enable"][:i].any()


def _rig_file(path: Path, omega_max: float, I_max: float, torque_limit: float) -> Path:
    text = (ROOT / "rigs" / "mock.toml").read_text()
    text = text.replace("omega_max = 400.0", f"omega_max = {omega_max}").replace("I_max = 10.0", f"I_max = {I_max}")
    assert f"omega_max = {omega_max}" in text and f"I_max = {I_max}" in text
    path.write_text(text + f"\n[mock.load]\ntorque_limit = {torque_limit}\n")
    return path


def test_overrides_are_bounded_by_the_rig_file(tmp_path):
    """Bounds from the rig's own limits (here not the defaults), OVERRIDE_MARGIN inside them: a value just
    inside is applied, just outside refused, by the loop of a real session."""
    from bench.operate.requests import OVERRIDE_MARGIN

    rig = _rig_file(tmp_path / "rig.toml", omega_max=300.0, I_max=6.0, torque_limit=10.0)
    keep = 1 - OVERRIDE_MARGIN
    w, m, i = keep * 300.0, keep * 10.0, keep * 6.0
    sched = [("omega_r_ref_override", w + 0.5), ("omega_r_ref_override", -w),
             ("m_l_ref_override", m + 0.1), ("m_l_ref_override", -m),
             ("i_mr_ref_override", i + 0.1), ("i_mr_ref_override", 2.0)]  # fmt: skip
    log = _schedule_log(tmp_path / "sched.mcap", [{"tick": 1500 + 100 * n, "kind": "set", "name": name, "new": v}
                                                  for n, (name, v) in enumerate(sched)])  # fmt: skip
    summary, code = run(RunOptions(rig=str(rig), duration=2.5, replay_params=log, log_enabled=False, progress=False))
    assert code == 0, summary["trip_cause"]
    evs = summary["record"].events()
    got = [(e["name"], e["status"].split(":")[0]) for e in evs]
    assert got == [(name, "refused" if n % 2 == 0 else "applied") for n, (name, _) in enumerate(sched)], got
    assert f"[{-w:g}, {w:g}] rad/s" in evs[0]["status"] and f"[{-m:g}, {m:g}] N m" in evs[2]["status"]
    assert f"(0, {i:g}] A" in evs[4]["status"]


def test_the_stock_rig_at_its_override_limits_stays_below_the_trips(tmp_path):
    """Why the margin: speed reversals between the override's limits, then load steps between its limits
    at that speed, on the mock rig with the stock controller: no trip, the speed stays below omega_max
    (measured: peak 342 rad/s of 400; at 0.9 omega_max a reversal overshot to 404 and tripped)."""
    from bench.core.config import load as load_rig
    from bench.operate.requests import OVERRIDE_MARGIN
    from bench.runtime.compose import build_rig

    cfg = load_rig("mock")
    keep = 1 - OVERRIDE_MARGIN
    w, m = keep * cfg.limits.omega_max, keep * build_rig(cfg, 0).load.torque_limit
    steps = [("omega_r_ref_override", w), ("omega_r_ref_override", -w), ("omega_r_ref_override", w),
             ("m_l_ref_override", -m), ("m_l_ref_override", m), ("m_l_ref_override", 0.0)]  # fmt: skip
    log = _schedule_log(tmp_path / "sched.mcap", [{"tick": 3000 * (n + 1), "kind": "set", "name": name, "new": v}
                                                  for n, (name, v) in enumerate(steps)])  # fmt: skip
    for scenario in ("fig5.7", "demo"):
        summary, code = run(RunOptions(scenario=scenario, duration=7.5, replay_params=log, log_enabled=False,
                                       progress=False))  # fmt: skip
        assert code == 0 and summary["operator"]["applied"] == len(steps), summary["trip_cause"]
        peak = float(np.max(np.abs(summary["record"].read("/truth")["omega_r"])))
        assert w < peak < cfg.limits.omega_max - 0.5 * OVERRIDE_MARGIN * cfg.limits.omega_max, (scenario, peak)


def test_an_estop_that_ends_the_run_gets_its_answer_before_the_server_stops():
    """The loop answers the e-stop and the run ends at once: the server (real, on 127.0.0.1) lets the
    answer out before it closes the connections, so `bench estop` says "applied", not "closed"."""
    import threading

    from bench.daq import Topic
    from bench.daq.live import LiveStream
    from bench.daq.live_control import LiveControl
    from bench.operate.live_client import call

    for _ in range(3):
        flags: list[tuple[str, int]] = []
        lc = LiveControl(_space(), lambda frame: True, lambda kind, seq: flags.append((kind, seq)))
        live = LiveStream([Topic("/rig", "imbench_msgs/msg/Dummy", [("t", "float64"), ("tick", "int64")])],
                          "127.0.0.1", 0, 1, lc)  # fmt: skip
        out: dict = {}

        def client() -> None:
            try:
                out["answer"] = call("estop", port=live.port)["status"]
            except Exception as exc:  # noqa: BLE001
                out["answer"] = repr(exc)

        th = threading.Thread(target=client, daemon=True)
        th.start()
        end = time.monotonic() + 10
        while not flags and time.monotonic() < end:
            time.sleep(0.0005)
        kind, seq = flags[0]
        lc.reported({"seq": seq, "kind": kind, "name": "", "who": "", "status": "applied", "tick": 1, "t": 0.1})
        live.stop()  # what the writer does once the run has ended and the log is finished
        th.join(10)
        assert out["answer"] == "applied", out
