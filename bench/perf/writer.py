"""Benchmark of the MCAP logging path: ``python -m bench.perf.writer`` prints JSON.

Layout: the realistic 5-topic tick record (meas 18 fields of mixed types, cmd 5, ctrl 12,
truth 13, timing 5; one message per topic per tick). Reports

* ``ticks_per_s``: sustained end-to-end rate with the loop putting as fast as it can, so the
  writer process is the bottleneck (first put to close() returned, file finished);
* ``realtime_factor``: that rate over 3 kHz;
* ``hot.put_us``: put() cost back to back (hot caches: the inherent cost);
* ``paced_3kHz.put_us``: put() cost in a loop paced at 3 kHz (sleep, then spin), what a real
  loop sees -- on a shared VM the caches go cold between ticks and this is several times
  the hot cost;
* ``bytes_per_tick``: file size over ticks;

for the default configuration and for cheaper alternatives (lz4, bigger chunks, fewer wider topics).

``--cpu``: the writer process's CPU per row at 3 kHz with the session's own three topics, rows handed over
in 64-row batches as a real-time run does (with the live server, with a live client; lz4; message by
message), per round beside the yardstick; ``--against DIR`` measures another source tree the same way,
alternating (e.g. ``git archive <commit> | tar -x -C DIR``).

``--under-load N``: ``bench run --realtime --live`` (one client) beside N busy processes, this tree and
``--against DIR`` alternating: how each run ended (a full log ring or not) and the writer's report.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from bench.daq.schema import Topic
from bench.daq.writer import LogWriter
from bench.runtime.loop import log_topics
from bench.perf.live import yardstick_us
from bench.core.config import load as load_rig
from bench.runtime.compose import build_rig, make_controller

F64, F32, I32, U32, I64, U8, BOOL = "float64", "float32", "int32", "uint32", "int64", "uint8", "bool"
T_S = 1.0 / 3000.0
RATE_HZ = 3000.0


def realistic_topics() -> list[Topic]:
    """The 5 per-tick topics of a bench run (53 fields)."""
    meas = [("t", F64), ("i_a", F64), ("i_b", F64), ("i_c", F64), ("u_ab", F64), ("u_bc", F64),
            ("u_ca", F64), ("u_dc", F64), ("enc_count", I32), ("enc_index", U32), ("omega_r", F64),
            ("theta_r", F64), ("temp_s", F32), ("i_load", F32), ("inv_fault", BOOL), ("inv_ready", BOOL),
            ("inv_status", U32), ("seq", I64)]
    cmd = [("t", F64), ("u_a_ref", F64), ("u_b_ref", F64), ("u_c_ref", F64), ("enable", BOOL)]
    ctrl = [("t", F64), ("i_sd", F64), ("i_sq", F64), ("i_sd_ref", F64), ("i_sq_ref", F64),
            ("omega_r_hat", F64), ("omega_r_ref", F64), ("psi_r_hat", F64), ("theta_mr", F64),
            ("u_sd_ref", F64), ("u_sq_ref", F64), ("mode", U8)]
    truth = [("t", F64), ("i_sa", F64), ("i_sb", F64), ("psi_ra", F64), ("psi_rb", F64), ("omega_r", F64),
             ("theta_r", F64), ("m_e", F64), ("m_l", F64), ("u_sa", F64), ("u_sb", F64), ("r_r", F64),
             ("temp_r", F64)]
    timing = [("t", F64), ("tick", I64), ("lateness_us", F32), ("compute_us", F32), ("overrun", BOOL)]
    return [
        Topic("/rig/meas", "imbench_msgs/Meas", meas),
        Topic("/rig/cmd", "imbench_msgs/Cmd", cmd),
        Topic("/ctrl", "imbench_msgs/Ctrl", ctrl),
        Topic("/truth", "imbench_msgs/Truth", truth),
        Topic("/loop/timing", "imbench_msgs/Timing", timing),
    ]


def wide_topics(n_topics: int = 1) -> list[Topic]:
    """The same 53 values as 1 (or 2) wide topics: fewer messages per tick."""
    prefixed = [(f"{tp.name.rsplit('/', 1)[-1]}_{n}", t) for tp in realistic_topics() for n, t in tp.fields]
    if n_topics == 1:
        return [Topic("/tick", "imbench_msgs/Tick", prefixed)]
    half = len(prefixed) // 2
    return [Topic("/tick_a", "imbench_msgs/TickA", prefixed[:half]),
            Topic("/tick_b", "imbench_msgs/TickB", prefixed[half:])]


def sample_rows(topics: Sequence[Topic], n: int, seed: int = 0) -> list[tuple]:
    """Plausible tick values (sinusoids + noise, counters, rare flags), as put() would get them."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    t = k * T_S
    cols: list[Any] = []
    for tp in topics:
        for j, (name, typ) in enumerate(tp.fields):
            if typ == F64 and (name == "t" or name.endswith("_t")):
                cols.append(t.tolist())
            elif typ == BOOL:
                cols.append((rng.random(n) < 0.01).tolist())
            elif typ in (I32, I64, U32):
                cols.append((k * (j + 1) % 100000).tolist())
            elif typ == U8:
                cols.append((k // 3000 % 4).tolist())
            else:
                f = 50.0 * (1 + 0.1 * j)
                cols.append((10.0 * np.sin(2 * math.pi * f * t + j) + 0.05 * rng.standard_normal(n)).tolist())
    return list(zip(*cols))


def _percentiles(us: np.ndarray) -> dict[str, float]:
    return {
        "n": int(us.size),
        "mean": float(us.mean()),
        "p50": float(np.percentile(us, 50)),
        "p99": float(np.percentile(us, 99)),
        "p99.9": float(np.percentile(us, 99.9)),
        "max": float(us.max()),
    }


def throughput(topics: Sequence[Topic], n_ticks: int, path: str, **kw: Any) -> dict[str, Any]:
    """Put n_ticks as fast as possible; the writer process is the bottleneck."""
    pool = sample_rows(topics, 8192)
    w = LogWriter(path, topics, metadata={"bench": {"n_ticks": n_ticks}}, timing=False, **kw)
    t0_ns = 1_700_000_000_000_000_000
    dt_ns = 333_333
    put = w.put
    t0 = time.perf_counter()
    for i in range(n_ticks):
        put(t0_ns + i * dt_ns, pool[i & 8191])
    t_put = time.perf_counter() - t0
    res = w.close()
    wall = time.perf_counter() - t0
    size = os.path.getsize(path)
    return {
        "ticks": n_ticks,
        "wall_s": round(wall, 4),
        "ticks_per_s": round(n_ticks / wall),
        "realtime_factor": round(n_ticks / wall / RATE_HZ, 2),
        "writer_busy_ticks_per_s": round(n_ticks / res["busy_s"]),
        "writer_pack_share": round(res["pack_s"] / res["busy_s"], 3),
        "loop_put_phase_s": round(t_put, 4),
        "messages_per_s": round(n_ticks * len(topics) / wall),
        "bytes_per_tick": round(size / n_ticks, 1),
    }


def hot_put_cost(topics: Sequence[Topic], path: str, rounds: int = 5, per_round: int = 2000, **kw: Any) -> dict[str, Any]:
    """put() cost back to back (hot caches), in rounds short enough that the ring never fills."""
    pool = sample_rows(topics, 64)
    w = LogWriter(path, topics, timing=True, **kw)
    now = time.perf_counter_ns
    dur = np.empty(rounds * per_round, np.int64)
    put = w.put
    k = 0
    for _ in range(rounds):
        time.sleep(0.2)  # let the writer drain the ring
        for i in range(per_round):
            a = now()
            put(k * 333_333, pool[i & 63])
            dur[k] = now() - a
            k += 1
    w.close()
    return {"put_us": _percentiles(dur / 1e3), "stalls": w.stats()["stalls"]}


def _paced(n: int, call: Any, pool: list[tuple]) -> tuple[np.ndarray, int]:
    """Call ``call(t_ns, row)`` at 3 kHz (sleep to ~150 µs before the deadline, then spin)."""
    now = time.perf_counter_ns
    dur = np.empty(n, np.int64)
    period = int(1e9 / RATE_HZ)
    start = now() + 2_000_000
    late_ticks = 0
    for i in range(n):
        deadline = start + i * period
        slack = deadline - now()
        if slack > 200_000:
            time.sleep((slack - 150_000) / 1e9)
        while now() < deadline:
            pass
        a = now()
        if a - deadline > period:
            late_ticks += 1
        call(deadline, pool[i & 63])
        dur[i] = now() - a
    return dur, late_ticks


def paced_put_cost(topics: Sequence[Topic], seconds: float, path: str, **kw: Any) -> dict[str, Any]:
    """put() cost at a real 3 kHz pace, next to the same loop calling a no-op (the VM's own jitter)."""
    n = int(seconds * RATE_HZ)
    pool = sample_rows(topics, 64)
    ref, ref_late = _paced(n, lambda t, v: None, pool)
    w = LogWriter(path, topics, timing=True, **kw)
    dur, late = _paced(n, w.put, pool)
    w.close()
    st = w.stats()
    return {
        "ticks": n,
        "put_us": _percentiles(dur / 1e3),
        "put_us_internal": st.get("put_us"),
        "stalls": st["stalls"],
        "queue_hw_rows": st["queue_hw_rows"],
        "dropped": st["dropped"],
        "ticks_later_than_a_period": late,
        "reference_noop_call_us": _percentiles(ref / 1e3),
        "reference_ticks_later_than_a_period": ref_late,
    }


def _best_of(repeat: int, fn: Any, *args: Any, **kw: Any) -> dict[str, Any]:
    runs = [fn(*args, **kw) for _ in range(repeat)]
    best = max(runs, key=lambda r: r["ticks_per_s"])
    out = dict(best)
    out["ticks_per_s_runs"] = [r["ticks_per_s"] for r in runs]
    out["ticks_per_s_median"] = int(np.median(out["ticks_per_s_runs"]))
    return out


def run(n_ticks: int, paced_s: float, alternatives: bool, repeat: int = 3) -> dict[str, Any]:
    import mcap.writer

    tmp = tempfile.mkdtemp(prefix="imbench-bench-")
    topics = realistic_topics()
    out: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "loadavg_before": [round(x, 2) for x in os.getloadavg()],
            "python": platform.python_version(),
            "numpy": np.__version__,
            "mcap": mcap.writer.__version__,
        },
        "layout": {tp.name: len(tp.fields) for tp in topics},
        "fields_per_tick": sum(len(tp.fields) for tp in topics),
        "target_ticks_per_s": 60_000,
        "note": f"throughput: best of {repeat} runs of {n_ticks} ticks (median and all runs listed); "
        "the machine is shared, see loadavg. The writer packs a block of ticks into MCAP records with numpy "
        "and writes it at once (bench.daq.mcap_block); compression and the per-block work dominate. "
        "--cpu: the writer's CPU per row at 3 kHz.",
    }
    base = {"batch_ticks": 64, "chunk_size": 1 << 20, "compression": "zstd"}
    out["baseline"] = {
        "config": {"topics": len(topics), **base},
        **_best_of(repeat, throughput, topics, n_ticks, f"{tmp}/base.mcap", **base),
        "hot": hot_put_cost(topics, f"{tmp}/hot.mcap", **base),
    }
    if paced_s > 0:
        out["baseline"]["paced_3kHz"] = paced_put_cost(topics, paced_s, f"{tmp}/paced.mcap", **base)
    if alternatives:
        variants = [
            ("5 topics, lz4", topics, {**base, "compression": "lz4"}),
            ("5 topics, zstd, 4 MiB chunks", topics, {**base, "chunk_size": 4 << 20}),
            ("5 topics, no compression", topics, {**base, "compression": "none"}),
            ("5 topics, zstd, batch 256", topics, {**base, "batch_ticks": 256}),
            ("2 wide topics, zstd", wide_topics(2), base),
            ("1 wide topic, zstd", wide_topics(1), base),
            ("1 wide topic, lz4", wide_topics(1), {**base, "compression": "lz4"}),
        ]
        out["alternatives"] = []
        for i, (label, tps, cfg) in enumerate(variants):
            try:
                r = _best_of(repeat, throughput, tps, n_ticks, f"{tmp}/alt{i}.mcap", **cfg)
            except Exception as e:  # e.g. lz4 not installed
                r = {"error": f"{type(e).__name__}: {e}"}
            out["alternatives"].append({"variant": label, "topics": len(tps), **cfg, **r})
    out["machine"]["loadavg_after"] = [round(x, 2) for x in os.getloadavg()]
    for name in os.listdir(tmp):
        os.remove(os.path.join(tmp, name))
    os.rmdir(tmp)
    return out


# ---------------------------------------------------------------------------- the writer's CPU per row
# A live client for the CPU runs: subscribes to every channel and counts what arrives (own process, as a lab
# PC's Foxglove would be).
_CLIENT = """
import asyncio, json, sys, time
import websockets
async def main(port, seconds):
    n = 0
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        chans = {}
        while len(chans) < 4:
            m = json.loads(await ws.recv())
            if m["op"] == "advertise":
                chans.update({c["topic"]: c for c in m["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i + 1, "channelId": c["id"]} for i, c in enumerate(chans.values())]}))
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                b = await asyncio.wait_for(ws.recv(), 0.2)
            except asyncio.TimeoutError:
                continue
            except websockets.ConnectionClosed:  # the log was closed: the server stops
                break
            n += isinstance(b, bytes)
    print(n)
asyncio.run(main(int(sys.argv[1]), float(sys.argv[2])))
"""


def session_topics() -> list[Topic]:
    """The per-tick topics of `bench run` on the mock rig with the FOC (/rig, /ctrl, /truth): what a run logs."""

    cfg = load_rig("mock")
    rig = build_rig(cfg, 0)
    return [Topic(n, s, f) for n, s, f in log_topics(rig, make_controller(cfg, rig, "foc", {}))]


def _cpu_ns(pid: int) -> dict[str, int]:
    """Time on a CPU [ns] of each thread of a process, by thread name (summed), from /proc schedstat."""
    out: dict[str, int] = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/comm") as f:
                name = f.read().strip()
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                ns = int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        out[name] = out.get(name, 0) + ns
    return out


def writer_cpu(topics: Sequence[Topic], seconds: float, path: str, live: str = "none", idle_s: float = 2.0,
               **kw: Any) -> dict[str, Any]:  # fmt: skip
    """The writer process's CPU at 3 kHz: rows put in 64-row batches every 21.3 ms (a real-time run's
    publications, without the loop's spinning); CPU of all its threads (/proc schedstat) from the first put
    until every row is written, per row, and while idle (``idle_s`` without rows) per second. ``live``:
    "none", "server" (the live server at 100 Hz, no client) or "client" (one client subscribed to all)."""
    pool = sample_rows(topics, 4096)
    cfg = {"host": "127.0.0.1", "port": 0, "every": 30} if live != "none" else None
    w = LogWriter(path, topics, timing=False, max_wait=5.0, live=cfg, **kw)
    pid, n, batch = w.writer_pid, int(seconds * RATE_HZ) // 64 * 64, 64
    time.sleep(0.5)  # start-up settled
    a = _cpu_ns(pid)
    time.sleep(idle_s)
    b = _cpu_ns(pid)
    client = None
    if live == "client":
        client = subprocess.Popen([sys.executable, "-c", _CLIENT, str(w.live_port), str(seconds + 1.0)],
                                  stdout=subprocess.PIPE, text=True)  # fmt: skip
        time.sleep(1.0)  # connected and subscribed
        b = _cpu_ns(pid)
    t0 = time.perf_counter()
    for k in range(0, n, batch):
        wait = t0 + k / RATE_HZ - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        for i in range(k, k + batch):
            w.put(1_700_000_000_000_000_000 + i * 333_333, pool[i & 4095])
    w.flush()
    while w.stats()["rows_written"] < n:
        time.sleep(0.005)
    wall = time.perf_counter() - t0
    c = _cpu_ns(pid)
    res = w.close()
    received = int(client.communicate()[0] or 0) if client is not None else None
    per = {name: (c.get(name, 0) - b.get(name, 0)) / n / 1e3 for name in c}
    out = {
        "rows": n,
        "wall_s": round(wall, 3),
        "cpu_us_per_row": round(sum(per.values()), 3),
        "cpu_us_per_row_by_thread": {k: round(v, 3) for k, v in per.items() if v > 0.005},
        "cpu_ms_per_s_at_3kHz": round(sum(c.values()) / 1e6 / wall - sum(b.values()) / 1e6 / wall, 2),
        "idle_cpu_ms_per_s": round((sum(b.values()) - sum(a.values())) / 1e6 / idle_s, 2) if live != "client" else None,
        "bytes_per_row": round(os.path.getsize(path) / n, 1),
    }
    if "cpu_us_per_row" in res:  # the writer's own split (main thread): packing, MCAP, live stream and status
        out["writer_main_thread_us_per_row"] = {k: round(v, 3) for k, v in res["cpu_us_per_row"].items()}
    if received is not None:
        out["client_messages"] = received
    return out


def _cpu_configs(this_tree: bool) -> list[tuple[str, dict[str, Any]]]:
    """(label, LogWriter options): each tree's defaults with and without the live stream; in this tree also
    the alternatives (zstd, no coalescing, and the old way: message by message, zstd, 2 ms idle poll)."""
    import inspect

    default = inspect.signature(LogWriter).parameters["compression"].default
    out: list[tuple[str, dict[str, Any]]] = [
        (f"default ({default})", {}), (f"default ({default}), live server (no client)", {"live": "server"}),
        (f"default ({default}), live + 1 client", {"live": "client"})]  # fmt: skip
    if "block_write" in inspect.signature(LogWriter).parameters and this_tree:
        out += [("zstd", {"compression": "zstd"}), ("zstd, live + 1 client", {"compression": "zstd", "live": "client"}),
                (f"{default}, no coalescing", {"writer_coalesce_s": 0.0}),
                ("message by message, zstd, idle poll 2 ms, no coalescing",
                 {"block_write": False, "compression": "zstd", "writer_idle_s": 0.002, "writer_coalesce_s": 0.0})]  # fmt: skip
    return out


def cpu_once(seconds: float, this_tree: bool = True) -> dict[str, Any]:
    """Every CPU configuration of this tree once (JSON)."""
    topics = session_topics()
    with tempfile.TemporaryDirectory() as tmp:
        return {label: writer_cpu(topics, seconds, f"{tmp}/w.mcap", **cfg) for label, cfg in _cpu_configs(this_tree)}


def cpu_compare(seconds: float, rounds: int, against: str | None) -> dict[str, Any]:
    """`cpu_once` for this tree and, alternating round by round, for the tree ``against`` (e.g. an export of an
    earlier commit), each in a fresh process, with the yardstick (../shared/yardstick.py) before each round."""
    trees = {"this": str(Path(__file__).resolve().parents[2])}
    if against:
        trees["against"] = str(Path(against).resolve())
    out: dict[str, Any] = {"benchmark": "log writer CPU per row, 3 kHz, the session's three topics",
                           "seconds": seconds, "trees": trees, "loadavg_before": list(os.getloadavg()), "rounds": []}
    for _ in range(rounds):
        rnd: dict[str, Any] = {"yardstick_us": yardstick_us()}
        for name, tree in trees.items():
            env = {**os.environ, "PYTHONPATH": tree}
            p = subprocess.run([sys.executable, "-P", str(Path(__file__).resolve()), "--cpu-once", str(seconds)]
                               + (["--other-tree"] if name != "this" else []), env=env, capture_output=True,
                               text=True, check=True)  # fmt: skip
            rnd[name] = json.loads(p.stdout)
        out["rounds"].append(rnd)
    out["loadavg_after"] = list(os.getloadavg())
    best: dict[str, dict[str, float]] = {}  # per tree and configuration: the best round, in µs and yardsticks
    for rnd in out["rounds"]:
        y = rnd["yardstick_us"] or math.nan
        for name in trees:
            for label, r in rnd[name].items():
                us = r["cpu_us_per_row"]
                cur = best.setdefault(name, {}).get(label)
                if cur is None or us < cur["us"]:
                    best[name][label] = {"us": us, "yardsticks": round(us / y, 3), "ms_per_s": r["cpu_ms_per_s_at_3kHz"]}
    out["best_cpu_per_row"] = best
    return out


_HOG = "import os\nparent = os.getppid()\nwhile os.getppid() == parent:\n    pass\n"  # ends with its parent


def run_under_load(tree: str, hogs: int, seconds: float, log_buffer: float, work: Path) -> dict[str, Any]:
    """`bench run --realtime --live` of source tree ``tree`` (demo, mock rig) with one live client subscribed to
    everything, beside ``hogs`` busy processes at normal priority (other work on the PC): how the run ended, and
    what the log writer reported."""
    env = {**os.environ, "PYTHONPATH": tree}
    hp = [subprocess.Popen([sys.executable, "-c", _HOG]) for _ in range(hogs)]
    client = None
    try:
        time.sleep(1.0)
        args = [sys.executable, "-m", "bench", "run", "--realtime", "--duration", str(seconds), "--no-progress",
                "--log", str(work / "run.mcap"), "--force", "--live", "--live-port", "0", "--log-buffer",
                str(log_buffer)]  # fmt: skip
        load = os.getloadavg()[0]
        p = subprocess.Popen(args, cwd=work, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        line = p.stderr.readline()
        if "ws://" in line:
            port = line.split("ws://")[1].split(":")[1].split()[0]
            client = subprocess.Popen([sys.executable, "-c", _CLIENT, port, str(seconds + 5)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        p.communicate()
    finally:
        for h in hp:
            h.kill()
        if client is not None:
            client.kill()
    s = json.loads((work / "run.summary.json").read_text())
    lw = s.get("log_writer") or {}
    w = lw.get("writer") or {}
    return {"tree": tree, "hogs": hogs, "load_before": round(load, 2), "exit_code": s.get("exit_code"),
            "trip_cause": s.get("trip_cause"), "ticks": s.get("ticks"), "deadline_misses": s.get("deadline_misses"),
            "ring_high_water_rows": lw.get("queue_hw_rows"),
            "writer": {k: w[k] for k in ("rows", "cpu_s", "wall_s", "backlog_hw_rows", "renices", "io_s") if k in w}}


def under_load(hogs: int, seconds: float, runs: int, log_buffer: float, against: str | None) -> dict[str, Any]:
    """`run_under_load` of this tree and, alternating, of the tree ``against``."""
    trees = [str(Path(__file__).resolve().parents[2])] + ([str(Path(against).resolve())] if against else [])
    out: dict[str, Any] = {"benchmark": "bench run --realtime --live beside busy processes", "hogs": hogs,
                           "seconds": seconds, "log_buffer_s": log_buffer, "yardstick_us": yardstick_us(), "runs": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(runs):
            for tree in trees[::-1]:
                out["runs"].append(run_under_load(tree, hogs, seconds, log_buffer, Path(tmp)))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=int, default=60_000, help="ticks per throughput run")
    ap.add_argument("--paced-seconds", type=float, default=5.0, help="3 kHz paced run for put() cost (0: skip)")
    ap.add_argument("--repeat", type=int, default=3, help="throughput runs per configuration (best is kept)")
    ap.add_argument("--no-alternatives", action="store_true")
    ap.add_argument("--cpu", action="store_true", help="the writer process's CPU per row at 3 kHz instead")
    ap.add_argument("--cpu-seconds", type=float, default=10.0, help="rows per CPU run [s at 3 kHz]")
    ap.add_argument("--rounds", type=int, default=3, help="CPU rounds")
    ap.add_argument("--against", help="also measure this source tree (e.g. `git archive` of an earlier commit)")
    ap.add_argument("--under-load", type=int, metavar="N", help="real-time runs with --live beside N busy processes")
    ap.add_argument("--runs", type=int, default=2, help="runs per tree under load")
    ap.add_argument("--seconds", type=float, default=40.0, help="length of a run under load [s]")
    ap.add_argument("--log-buffer", type=float, default=10.0, help="--log-buffer of the runs under load [s]")
    ap.add_argument("--cpu-once", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--other-tree", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.cpu_once is not None:
        print(json.dumps(cpu_once(a.cpu_once, not a.other_tree)))
    elif a.under_load is not None:
        print(json.dumps(under_load(a.under_load, a.seconds, a.runs, a.log_buffer, a.against), indent=2))
    elif a.cpu:
        print(json.dumps(cpu_compare(a.cpu_seconds, a.rounds, a.against), indent=2))
    else:
        print(json.dumps(run(a.ticks, a.paced_seconds, not a.no_alternatives, a.repeat), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
