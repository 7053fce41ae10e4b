"""The results table, ``DIR/results.parquet`` (pyarrow): one row per case, written atomically.

Every write replaces the whole file through a temporary file, flushed to disk, and `os.replace`, so a reader (or an
interrupted sweep, or a full disk) only ever sees a complete table; a sweep interrupted before its first case leaves
a table of no rows that still has the ``case_id`` and ``status`` columns. Columns: the inputs first (``case_id``,
``index``, ``scenario``, ``seed``, ``label.*``, ``params.*``, ``plant.*``), then the outputs
(`bench.workflows.sweep.cases`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bench.core.outputs import replacing
from bench.errors import BadInput

RESULTS = "results.parquet"
SWEEP_JSON = "sweep.json"  # what the sweep is, written into DIR before any case runs (bench.workflows.sweep.engine)
_FIRST = ("case_id", "index", "scenario", "seed", "duration_set", "controller")


def columns(rows: list[dict[str, Any]]) -> list[str]:
    """Every column of ``rows``: the inputs in a fixed order, then the rest as first seen."""
    seen: dict[str, None] = {}
    for r in rows:
        seen.update(dict.fromkeys(r))
    first = [c for c in _FIRST if c in seen]
    inputs = sorted(c for c in seen if c.startswith(("label.", "params.", "plant.")))
    rest = [c for c in seen if c not in first and c not in inputs]
    return first + inputs + rest


def write(path: Path, rows: list[dict[str, Any]]) -> None:
    """Replace ``path`` with a table of ``rows`` (sorted by ``index``; none: the ``case_id`` and ``status`` columns
    alone), atomically (`bench.core.outputs.replacing`: a write that fails, e.g. on a full disk, or is interrupted
    leaves the previous table as it was)."""
    import pyarrow as pa
    import pyarrow.parquet as pq


    rows = sorted(rows, key=lambda r: r.get("index", 0))
    if rows:
        cols = columns(rows)
        table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
    else:  # (from_pylist([]) has no columns: no reader could tell it from any other empty file)
        table = pa.table({"case_id": pa.array([], pa.string()), "status": pa.array([], pa.string())})
    with replacing(path) as tmp:
        pq.write_table(table, tmp)


def _in_a_sweep_folder(path: Path) -> bool:
    """Whether ``path``'s folder is one a sweep has written into (its ``sweep.json``)."""
    try:
        about = json.loads((path.parent / SWEEP_JSON).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(about, dict) and isinstance(about.get("name"), str) and isinstance(about.get("cases"), int)


def read(path: Path) -> list[dict[str, Any]]:
    """The rows of a results table (`BadInput` if it is not one).

    In a sweep's folder (`SWEEP_JSON`) an empty file, or a table of no rows and no columns (what a sweep interrupted
    before its first case wrote before the table kept its columns), holds no case: no rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq


    try:
        if path.stat().st_size == 0 and _in_a_sweep_folder(path):
            return []
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise BadInput(str(path), f"not a readable results table: {exc}") from None
    if table.num_rows == 0 and table.num_columns == 0 and _in_a_sweep_folder(path):
        return []
    if "case_id" not in table.column_names or "status" not in table.column_names:
        raise BadInput(str(path), "not a bench sweep results table (no case_id/status columns)")
    return table.to_pylist()
