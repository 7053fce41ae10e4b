"""The live stream (issue 11, first part): a real server on 127.0.0.1, a protocol-level WebSocket client.

The client speaks the subprotocol the server announces, subscribes, decodes /rig messages with the
log's own schema and finds them, byte for byte, in the MCAP log at the same log time; /status comes
at about 10 Hz; hostile clients (garbage, one that never reads) do not disturb the run.
"""

from __future__ import annotations

import asyncio
import json
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import websockets

from bench.daq import LogReader

ROOT = Path(__file__).resolve().parents[1]


def _start(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, int]:
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--log", str(tmp_path / "run.mcap"),
                          "--live", "--live-port", "0", *args], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    line = p.stderr.readline()
    assert line.startswith("bench: live: ws://127.0.0.1:"), line
    return p, int(line.split("ws://127.0.0.1:")[1].split()[0])


async def _watch(port: int, seconds: float) -> tuple[dict[str, dict], list[tuple[int, bytes]], list[dict]]:
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                                  max_size=None) as ws:  # fmt: skip
        assert ws.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
        channels: dict[str, dict] = {}
        while "/status" not in channels or "/rig" not in channels:
            m = json.loads(await ws.recv())
            if m["op"] == "advertise":
                channels.update({c["topic"]: c for c in m["channels"]})
        subs = {1: "/rig", 2: "/status"}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sid, "channelId": channels[topic]["id"]} for sid, topic in subs.items()]}))  # fmt: skip
        rig, status = [], []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                b = await asyncio.wait_for(ws.recv(), timeout=1.0)
            except asyncio.TimeoutError:
                continue
            if isinstance(b, bytes) and b[0] == 1:  # message data: opcode, subscription id, log time, payload
                sid, ts = struct.unpack_from("<IQ", b, 1)
                (rig.append((ts, b[13:])) if subs[sid] == "/rig" else status.append(json.loads(b[13:])))
        return channels, rig, status


async def _hostile(port: int) -> None:
    """One client sends garbage, one subscribes to everything and never reads, one leaves mid-message."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"]) as bad:
        await bad.send(b"\xff" * 1000)
        await bad.send("{not json")
    stalled = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None)
    adv = json.loads(await stalled.recv())
    while adv["op"] != "advertise":
        adv = json.loads(await stalled.recv())
    await stalled.send(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": i + 1, "channelId": c["id"]} for i, c in enumerate(adv["channels"])]}))  # fmt: skip
    stalled.transport.pause_reading()  # never reads again
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n")  # and goes away mid-handshake
    writer.close()
    # a viewer that offers only the old subprotocol name (Lichtblick before 1.22.1): HTTP 400, as
    # docs/at-the-rig.md says
    try:
        await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.websocket.v1"])
        raise AssertionError("a client offering only foxglove.websocket.v1 was accepted")
    except websockets.exceptions.InvalidStatus as exc:
        assert exc.response.status_code == 400, exc


@pytest.mark.realtime
def test_live_rig_messages_are_the_logged_ones_and_status_arrives(tmp_path):
    # the gentle scenario (10 rad/s): an OS stall on a loaded machine cannot over-current the motor
    p, port = _start(tmp_path, "--realtime", "--scenario", "fig5.7", "--duration", "4", "--live-rate", "100")

    async def both() -> tuple:
        watched = asyncio.create_task(_watch(port, 2.5))
        await _hostile(port)
        return await watched

    channels, rig, status = asyncio.run(both())
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err  # no hostile client tripped or stalled the run
    assert channels["/rig"]["schemaName"] == "imbench_msgs/msg/RigTick" and channels["/rig"]["encoding"] == "cdr"
    assert len(rig) > 100  # ~2 s at 100 Hz
    log = LogReader(tmp_path / "run.mcap")
    fields = [f for f in log.fields("/rig")]
    cols = log.read("/rig", ns=True)
    by_time = {int(t): i for i, t in enumerate(cols["log_time"])}
    from bench.daq.schema import cdr_dtype

    dt = cdr_dtype(log.schema("/rig"))
    for ts, payload in rig[:50]:
        row = np.frombuffer(payload, dt)[0]
        i = by_time[ts]  # the same tick is in the log, at the same log time
        assert all(row[f] == cols[f][i] for f in fields), (ts, i)  # the very message the log holds
    ticks = np.array([int(np.frombuffer(pl, dt)[0]["tick"]) for _, pl in rig])
    # every 30th logged row (3 kHz / 100 Hz), in order; a real-time run may skip ticks between them
    assert np.all(np.diff(ticks) >= 30) and np.median(np.diff(ticks)) == 30, np.diff(ticks)
    assert 10 <= len(status) and not any(s["tripped"] for s in status), status
    t = [s["t"] for s in status]
    assert 0.07 < float(np.median(np.diff(t))) < 0.15  # about 10 Hz of loop time
    assert status[-1]["rows_written"] > status[0]["rows_written"]


def test_live_port_in_use_is_refused_before_the_run(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        p = subprocess.run([sys.executable, "-m", "bench", "run", "--live", "--live-port", str(port), "--log",
                            str(tmp_path / "x.mcap")], cwd=ROOT, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2 and "--live-port" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (tmp_path / "x.mcap").exists()


async def _status_until_closed(port: int, on_first=None) -> list[dict]:  # noqa: ANN001
    """Every /status message until the server goes away (the run ended)."""
    status = []
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        chans: dict[str, dict] = {}
        while "/status" not in chans:
            m = json.loads(await ws.recv())
            if m["op"] == "advertise":
                chans.update({c["topic"]: c for c in m["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": chans["/status"]["id"]}]}))
        try:
            async for b in ws:
                if isinstance(b, bytes) and b[0] == 1:
                    status.append(json.loads(b[13:]))
                    if on_first is not None and len(status) == 5:
                        on_first()
        except websockets.ConnectionClosed:
            pass
    return status


@pytest.mark.realtime
def test_status_tells_the_supervisor_state_and_the_trip_cause(tmp_path):
    """A SIGTERM mid-run trips it: the last /status (sent from the log's shutdown record) says why."""
    import signal

    p, port = _start(tmp_path, "--realtime", "--duration", "20")
    status = asyncio.run(_status_until_closed(port, on_first=lambda: p.send_signal(signal.SIGTERM)))
    out, err = p.communicate(timeout=60)
    assert p.returncode != 0, err
    cause = json.loads((tmp_path / "run.summary.json").read_text())["trip_cause"]
    assert cause and status[0]["state"] == "running" and status[0]["trip_cause"] == ""
    assert status[-1]["state"] == "tripped" and status[-1]["trip_cause"] == cause, status[-3:]
    assert status[-1]["t"] < 10  # it ended early, and /status said so


@pytest.mark.realtime
def test_terminal_panel_on_a_tty_realtime_run(tmp_path, run_in_pty):
    """--realtime with stderr a terminal: the progress process draws the panel from the writer's view of the rows."""
    import re

    code, text = run_in_pty([sys.executable, "-m", "bench", "run", "--realtime", "--duration", "2", "--log",
                             str(tmp_path / "tty.mcap")], columns=200)  # fmt: skip
    assert code == 0, text[-2000:]
    pat = re.compile(r"t +([\d.]+) s +\u03c9_r +(-?[\d.]+) \(ref +(-?[\d.]+)\) rad/s +\|i_s\| +([\d.]+) A +i_mR +"
                     r"([\d.]+) A +misses (\d+) +lat p99 ([\d.]+) \u00b5s +(running|TRIPPED)")  # fmt: skip
    rows = [m.groups() for m in pat.finditer(text)]
    assert len(rows) >= 3, text[-2000:]  # drawn about 5 times a second
    t = [float(r[0]) for r in rows]
    assert t == sorted(t) and t[-1] > 1.0 and all(r[7] == "running" for r in rows)
    magnetized = [r for r in rows if float(r[0]) > 0.5]
    assert magnetized and all(0.5 < float(r[3]) < 20 and 1 < float(r[4]) < 5 for r in magnetized)  # [A]
    # the signals are the logged ones: every panel line's omega_r ref is a /rig value of the log
    refs = LogReader(tmp_path / "tty.mcap").read("/rig")["omega_r_ref"]
    assert all(np.min(np.abs(refs - float(r[2]))) <= 0.051 for r in rows)


def test_stalled_client_at_full_rate_does_not_stall_the_writer(tmp_path):
    """Every tick to a client subscribed to everything that never reads (MBs beyond any socket buffer),
    in lockstep, where the loop waits for the writer: if the server's send blocked the writer, the
    put would time out and the run would trip "log writer stalled"; it ends normally instead, and a
    client that leaves in the middle of a frame changes nothing."""
    p, port = _start(tmp_path, "--lockstep", "--duration", "12", "--live-rate", "3000")

    async def stall() -> None:
        stalled = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                                           max_size=None)  # fmt: skip
        chans: list[dict] = []
        while len(chans) < 4:
            m = json.loads(await stalled.recv())
            if m["op"] == "advertise":
                chans += m["channels"]
        await stalled.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i + 1, "channelId": c["id"]} for i, c in enumerate(chans)]}))  # fmt: skip
        stalled.transport.pause_reading()
        half = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"])
        half.transport.write(b"\x81\xfe\x10\x00\x00\x00\x00\x00{\"op\":")  # a 4 kB text frame, cut short
        half.transport.abort()
        while p.poll() is None:
            await asyncio.sleep(0.2)

    asyncio.run(stall())
    out, err = p.communicate(timeout=120)
    assert p.returncode == 0, err
    s = json.loads((tmp_path / "run.summary.json").read_text())
    assert s["trip_cause"] is None and s["ticks"] == 36000 and not s["warnings"], s


def test_loop_stats_latency_p99_is_over_the_last_second_of_rows():
    """The /status and panel latency p99: the rows of the last second of loop time, whatever the block sizes."""
    import numpy as np

    from bench.daq.live import LoopStats
    from bench.daq.schema import Topic

    fields = [(n, "float64") for n in ("t", "tick", "latency_us", "overrun", "tripped")]
    stats = LoopStats([Topic("/rig", "imbench_msgs/RigTick", fields)])
    rng = np.random.default_rng(1)
    n = 9000
    rows = np.zeros((n, 5))
    rows[:, 0] = np.arange(n) / 3000
    rows[:, 1] = np.arange(n)
    rows[:, 2] = rng.exponential(10.0, n)
    a = 0
    for size in [1, 64, 1000, 7, 2500, 64, 3000, 2364]:
        stats.update(rows[a : a + size])
        a += size
        t = rows[a - 1, 0]
        want = np.percentile(rows[:a][rows[:a, 0] >= t - 1.0, 2], 99)
        assert stats.latency_p99_us() == want
    assert a == n and stats.tick == n - 1 and stats.misses == 0
