"""Digests of a run's outputs, small enough to keep in the repository, and their comparison bit for bit.

A per-tick log column is kept as the SHA-256 of its values' raw float64 bytes, the SHA-256 (first 64 bits) of each
1-s block of them, to say where a difference starts, and its first, last and a few sampled values, to show what
changed; its topic keeps the row count and the schema (field names and logged types). Floats are stored as JSON numbers, which Python writes with ``repr``: they read back
to the same bits (NaN and the infinities as ``NaN``/``Infinity``). Summaries and identification results are kept
whole, without the fields that depend on the wall clock, the host or the output paths (`normalise_summary`).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

BLOCK_S = 1.0  # [s] of loop time per block hash
N_SAMPLES = 5  # sampled values per column, evenly spaced (besides the first and the last)
# per-tick fields that are not the run's behaviour: the log time is the wall-clock start epoch + t (the field t is
# kept), the others are the loop's own timing of each tick on this machine
WALL_CLOCK_FIELDS = ("log_time", "compute_us", "latency_us", "overrun")
EVENT_TOPICS = ("/params", "/events")  # kept whole, as `LogReader.events` reads them
# summary.json fields of the wall clock, the host, the log writer's pacing or the output paths
VOLATILE_SUMMARY = ("wall_time", "realtime_factor", "timing", "start_epoch_ns", "realtime_setup", "log_writer",
                    "log", "plot", "summary", "record", "engines")  # fmt: skip
MAX_MESSAGES = 12  # differences listed per comparison (the rest counted)
NOTE = "recorded at commit"  # the line that names the recording's commit and environment (not a difference)


def _py(x: Any) -> Any:
    """A JSON-able Python value of a numpy scalar (float64 stays a float: its repr round-trips)."""
    return x.item() if hasattr(x, "item") else x


def _bytes(a: np.ndarray) -> bytes:
    """The column's raw bytes, little-endian."""
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


def column(a: np.ndarray, block_rows: int) -> dict[str, Any]:
    """The digest of one column (module docstring)."""
    n = len(a)
    idx = sorted({n * k // (N_SAMPLES + 1) for k in range(1, N_SAMPLES + 1)}) if n else []
    return {
        "sha256": hashlib.sha256(_bytes(a)).hexdigest(),
        "blocks": [hashlib.sha256(_bytes(a[i:i + block_rows])).hexdigest()[:16] for i in range(0, n, block_rows)],
        "first": _py(a[0]) if n else None,
        "last": _py(a[-1]) if n else None,
        "samples": [[i, _py(a[i])] for i in idx],
    }


def log(topics: dict[str, dict[str, np.ndarray]], schema: dict[str, list[tuple[str, str]]], events: list[dict[str, Any]],
        T_s: float) -> dict[str, Any]:
    """The digest of a run's per-tick record: every topic's schema and columns (not the wall-clock ones), and its
    parameter changes and operator actions whole. The columns are hashed as float64 (every logged integer and bool
    is exact in it): the MCAP log's typed columns and the in-memory record's float rows give the same digest, and
    the schema keeps the types."""
    block = int(round(BLOCK_S / T_s))
    out = {}
    for tp, cols in topics.items():
        keep = {f: np.asarray(a, dtype=np.float64) for f, a in cols.items() if f not in WALL_CLOCK_FIELDS}
        n = {len(a) for a in keep.values()}
        out[tp] = {"rows": n.pop() if len(n) == 1 else sorted(n), "schema": [list(f) for f in schema[tp]],
                   "columns": {f: column(a, block) for f, a in keep.items()}}  # fmt: skip
    return {"block_rows": block, "T_s": T_s, "topics": out, "events": events}


def from_mcap(path: Path, T_s: float) -> dict[str, Any]:
    """`log` of an MCAP run log (`bench.daq.LogReader`)."""
    from bench.daq import LogReader

    r = LogReader(path)
    names = [tp for tp in r.topics() if tp not in EVENT_TOPICS]
    return log({tp: r.read(tp) for tp in names}, {tp: r.schema(tp) for tp in names}, r.events(), T_s)


def from_memory(record: Any, T_s: float) -> dict[str, Any]:
    """`log` of a run's in-memory record (`bench.daq.memory.MemoryLog`, a session with ``log_enabled=False``); its
    events through the log's own codec (`bench.daq.events`), as the MCAP log holds them."""
    from bench.daq import events as codec

    evs = []
    for ev in record.events():
        ev = codec.decode(*codec.encode(ev))
        ev["kind"] = ev.get("kind", "set")
        evs.append(ev)
    evs.sort(key=lambda e: (e["tick"], e["seq"]))
    return log({tp.name: record.read(tp.name) for tp in record.topics_},
               {tp.name: list(tp.fields) for tp in record.topics_}, evs, T_s)  # fmt: skip


def normalise_summary(summary: dict[str, Any]) -> dict[str, Any]:
    """summary.json without what depends on the wall clock, the host, the output paths or the engine (the same
    behaviour is recorded once for both engines); numba's notes about its cache are not the run's either."""
    out = {k: v for k, v in summary.items() if k not in VOLATILE_SUMMARY}
    if isinstance(out.get("controller_params"), dict):
        out["controller_params"] = {k: v for k, v in out["controller_params"].items() if k != "engine"}
    out["warnings"] = [w for w in out.get("warnings") or () if not str(w).startswith("numba cache:")]
    return json.loads(json.dumps(out, default=str))  # as it reads back from the recorded file


def _cells_sha(values: list[Any]) -> str:
    """The first 64 bits of the SHA-256 of ``values`` as JSON (floats by ``repr``: equal text is equal bits)."""
    return hashlib.sha256(json.dumps(values).encode()).hexdigest()[:16]


def table(rows: list[dict[str, Any]], every: int) -> dict[str, Any]:
    """The digest of a results table: a hash per column and per row, and every ``every``-th row whole. A
    difference is then placed by its rows and columns, and shown where sampled. The columns are those of all
    rows in the order first met (a row without one: None, as in the sweep's parquet table)."""
    rows = json.loads(json.dumps(rows))  # as it reads back from the recorded file
    cols = list(dict.fromkeys(c for r in rows for c in r))
    rows = [{c: r.get(c) for c in cols} for r in rows]
    return {"n_rows": len(rows), "columns": cols,
            "column_sha": {c: _cells_sha([r[c] for r in rows]) for c in cols},
            "row_sha": [_cells_sha([r[c] for c in cols]) for r in rows],
            "sample_every": every, "sampled": [[r[c] for c in cols] for r in rows[::every]]}  # fmt: skip


def _is_table(x: Any) -> bool:
    return isinstance(x, dict) and "row_sha" in x and "column_sha" in x


def _table_diff(where: str, rec: dict[str, Any], now: dict[str, Any]) -> list[str]:
    if rec["columns"] != now["columns"] or rec["n_rows"] != now["n_rows"]:
        return [f"{where}: {rec['n_rows']} rows of {len(rec['columns'])} columns recorded, {now['n_rows']} of "
                f"{len(now['columns'])} now; columns recorded only: {sorted(set(rec['columns']) - set(now['columns']))}"
                f", now only: {sorted(set(now['columns']) - set(rec['columns']))}"]  # fmt: skip
    rows = [i for i, (a, b) in enumerate(zip(rec["row_sha"], now["row_sha"])) if a != b]
    cols = [c for c in rec["columns"] if rec["column_sha"][c] != now["column_sha"][c]]
    out = [f"{where}: {len(rows)} of {rec['n_rows']} rows differ (rows {rows[:10]}{' ...' if len(rows) > 10 else ''}) "
           f"in {len(cols)} column(s): {', '.join(cols)}"]  # fmt: skip
    k = rec["sample_every"]
    for j, (a, b) in enumerate(zip(rec["sampled"], now["sampled"])):
        cells = [f"{c} {x!r} -> {y!r}" for c, x, y in zip(rec["columns"], a, b) if not same(x, y)]
        if cells:
            key = ", ".join(f"{c}={v}" for c, v in zip(rec["columns"], a) if c in ("case_id", "index"))
            out.append(f"{where} row {j * k} ({key}): recorded -> now: {'; '.join(cells)}")
    return out


def _is_column(x: Any) -> bool:
    return isinstance(x, dict) and "sha256" in x and "blocks" in x


def same(a: Any, b: Any) -> bool:
    """Equal to the bit, types included (1 is not 1.0; NaN equals NaN; 0.0 is not -0.0)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b) if a == a else b != b
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def _column_diff(where: str, rec: dict[str, Any], now: dict[str, Any], block_s: float) -> str:
    nb = min(len(rec["blocks"]), len(now["blocks"]))
    first = next((i for i in range(nb) if rec["blocks"][i] != now["blocks"][i]), nb)
    at = f"from the 1-s block {first} (t = {first * block_s:g}..{(first + 1) * block_s:g} s) on"
    vals = [f"first {rec['first']!r} -> {now['first']!r}"] if not same(rec["first"], now["first"]) else []
    vals += [f"[{i}] {x!r} -> {y!r}" for (i, x), (j, y) in zip(rec["samples"], now["samples"])
             if i == j and not same(x, y)]  # fmt: skip
    vals += [f"last {rec['last']!r} -> {now['last']!r}"] if not same(rec["last"], now["last"]) else []
    return f"{where}: differs {at}; recorded -> now: {', '.join(vals) or 'sampled values equal'}"


def diff(rec: Any, now: Any, where: str = "", block_s: float = BLOCK_S) -> list[str]:
    """What differs between a recorded digest and today's, one line each, in order: a column by the first 1-s
    block that differs and its values, any other value by its path."""
    if same(rec, now):
        return []
    if _is_column(rec) and _is_column(now):
        return [_column_diff(where, rec, now, block_s)]
    if _is_table(rec) and _is_table(now):
        return _table_diff(where, rec, now)
    if isinstance(rec, dict) and isinstance(now, dict):
        out = [f"{where}.{k}: recorded, missing now" for k in rec if k not in now]
        out += [f"{where}.{k}: new (not recorded)" for k in now if k not in rec]
        for k in rec:
            if k in now:
                out += diff(rec[k], now[k], f"{where}.{k}" if where else str(k), block_s)
        return out
    if isinstance(rec, list) and isinstance(now, list) and len(rec) == len(now):
        return [m for i, (x, y) in enumerate(zip(rec, now)) for m in diff(x, y, f"{where}[{i}]", block_s)]
    return [f"{where}: recorded {_short(rec)}, now {_short(now)}"]


def _short(x: Any) -> str:
    text = repr(x)
    return text if len(text) <= 160 else text[:150] + f"... ({len(text)} chars)"


def _first_block(problem: str) -> tuple[int, int]:
    m = re.search(r"from the 1-s block (\d+) ", problem)
    return (0, int(m.group(1))) if m else (1, 0)


def report(name: str, problems: list[str], most: int = MAX_MESSAGES) -> str:
    """The failure text of one run: its name, then at most ``most`` differences, the columns that differ earliest
    first (where a difference starts is what to look at)."""
    problems = sorted(problems, key=_first_block)
    n = sum(not p.startswith(NOTE) for p in problems)
    lines = [f"golden run {name}: {n} difference(s) from the recorded digest"]
    lines += [f"  {p}" for p in problems[:most]]
    if len(problems) > most:
        lines.append(f"  ... and {len(problems) - most} more")
    return "\n".join(lines)


def dumps(obj: Any, level: int = 0) -> str:
    """JSON, one key per line, lists of numbers and strings on one line (floats by ``repr``): a recorded file that
    is small and whose ``git diff`` shows the columns, blocks and rows that changed."""
    pad = " " * (level + 1)
    if isinstance(obj, dict) and obj:
        items = ",\n".join(f"{pad}{json.dumps(k)}: {dumps(v, level + 1)}" for k, v in obj.items())
        return "{\n" + items + "\n" + " " * level + "}"
    if isinstance(obj, list) and any(isinstance(x, (dict, list)) for x in obj):
        return "[\n" + ",\n".join(pad + dumps(x, level + 1) for x in obj) + "\n" + " " * level + "]"
    return json.dumps(obj)
