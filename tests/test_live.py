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


def test_live_rig_messages_are_the_logged_ones_and_status_arrives(tmp_path):
    p, port = _start(tmp_path, "--realtime", "--duration", "4", "--live-rate", "100")

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
