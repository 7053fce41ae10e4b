"""Cost of the live stream (issue 11): real-time runs with and without `--live`, side by side.

Each pair: `bench run --realtime` of the demo on the mock rig without the live server, then with it and
one WebSocket client subscribed to every channel (the client runs here, on the same 2-core machine,
as a lab PC's Foxglove would). Per run: deadline misses, compute p50/p99.9 [us]; with the client:
delivered messages per second, the delay from a tick's log time to its arrival (p50/p99), and the
parameter round trip (a set every 0.5 s, until the loop's report of it reaches the client). The
yardstick (one plain-Python RK4 motor step) is measured in the same run.
"""

from __future__ import annotations

import asyncio
import json
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.daq.events import decode

ROOT = Path(__file__).resolve().parents[2]


async def _client(port: int, seconds: float, rtt: list[float]) -> tuple[int, list[int]]:
    """Subscribed to everything; every 0.5 s also sets speed_Kp and times the round trip until the loop's
    report of it arrives on /params (``rtt``: seconds)."""
    import websockets


    n, delays = 0, []
    sent: dict[str, float] = {}
    next_set, k = time.monotonic() + 0.5, 0
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        chans: dict[str, Any] = {}
        while len(chans) < 4:
            m = json.loads(await ws.recv())
            if m["op"] == "advertise":
                chans.update({c["topic"]: c for c in m["channels"]})
        subs = {i + 1: topic for i, topic in enumerate(chans)}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": chans[topic]["id"]} for i, topic in subs.items()]}))  # fmt: skip
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if "/params" in chans and time.monotonic() >= next_set:
                k += 1
                rid = f"perf {k}"
                sent[rid] = time.monotonic()
                await ws.send(json.dumps({"op": "setParameters", "id": rid, "parameters": [
                    {"name": "speed_Kp", "value": 0.6 + 0.01 * (k % 2), "type": "float64"}]}))  # fmt: skip
                next_set += 0.5
            try:
                b = await asyncio.wait_for(ws.recv(), 0.1)
            except asyncio.TimeoutError:
                continue
            if isinstance(b, bytes) and b[0] == 1:
                n += 1
                sid = struct.unpack_from("<I", b, 1)[0]
                delays.append(time.time_ns() - struct.unpack_from("<Q", b, 5)[0])
                if subs.get(sid) == "/params":
                    who = decode("/params", b[13:])["who"]
                    rid = who[who.find("(") + 1 : -1] if "(" in who else ""
                    if rid in sent:
                        rtt.append(time.monotonic() - sent.pop(rid))
    return n, delays


def _one(live: bool, duration: float, work: Path, tag: str) -> dict[str, Any]:
    log = work / f"{tag}.mcap"
    args = [sys.executable, "-m", "bench", "run", "--realtime", "--duration", str(duration), "--no-progress", "--log",
            str(log)] + (["--live", "--live-port", "0"] if live else [])  # fmt: skip
    p = subprocess.Popen(args, cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict[str, Any] = {"live": live}
    if live:
        port = int(p.stderr.readline().split("ws://127.0.0.1:")[1].split()[0])
        rtt: list[float] = []
        n, delays = asyncio.run(_client(port, duration - 1.0, rtt))
        delays.sort()
        rtt.sort()
        out.update(messages_per_s=n / (duration - 1.0), delay_ms_p50=delays[len(delays) // 2] / 1e6,
                   delay_ms_p99=delays[int(len(delays) * 0.99)] / 1e6, param_sets=len(rtt),
                   param_round_trip_ms_p50=rtt[len(rtt) // 2] * 1e3 if rtt else None,
                   param_round_trip_ms_max=rtt[-1] * 1e3 if rtt else None)  # fmt: skip
    p.communicate()
    s = json.loads(log.with_name(f"{tag}.summary.json").read_text())
    t = s["timing"]["compute_us"]
    out.update(exit_code=s["exit_code"], ticks=s["ticks"], deadline_misses=s["deadline_misses"],
               compute_us_p50=t["p50"], compute_us_p99_9=t["p99_9"])  # fmt: skip
    return out


def yardstick_us() -> float | None:
    """One plain-Python RK4 motor step [us], by ../shared/yardstick.py (next to the checkout, or a
    worktree's checkout one level further down); None where it is not there."""
    found = [p for p in (ROOT.parent / "shared" / "yardstick.py", ROOT.parents[1] / "shared" / "yardstick.py")
             if p.is_file()]  # fmt: skip
    yard = subprocess.run([sys.executable, str(found[0])], capture_output=True, text=True) if found else None
    return float(yard.stdout) if yard and yard.returncode == 0 and yard.stdout.strip() else None


def run(duration: float = 10.0, pairs: int = 2) -> dict[str, Any]:
    out: dict[str, Any] = {"benchmark": "live stream cost", "duration_s": duration, "runs": []}
    out["yardstick_us"] = yardstick_us()
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(pairs):
            for live in (False, True):
                out["runs"].append(_one(live, duration, Path(tmp), f"{'live' if live else 'plain'}{i}"))
    return out
