"""The results table, ``DIR/results.parquet`` (pyarrow): one row per case, written atomically.

Every write replaces the whole file through a temporary file and `os.replace`, so a reader (or an
interrupted sweep, or a full disk) only ever sees a complete table. Columns: the inputs first (``case_id``, ``index``,
``scenario``, ``seed``, ``label.*``, ``params.*``, ``plant.*``), then the outputs (`bench.sweep.cases`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

RESULTS = "results.parquet"
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
    """Replace ``path`` with a table of ``rows`` (sorted by ``index``), atomically (`bench.outputs.replacing`:
    a write that fails, e.g. on a full disk, leaves the previous table as it was)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from bench.outputs import replacing

    rows = sorted(rows, key=lambda r: r.get("index", 0))
    cols = columns(rows)
    table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
    with replacing(path) as tmp:
        pq.write_table(table, tmp)


def read(path: Path) -> list[dict[str, Any]]:
    """The rows of a results table (`BadInput` if it is not one)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from bench.errors import BadInput

    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise BadInput(str(path), f"not a readable results table: {exc}") from None
    if "case_id" not in table.column_names or "status" not in table.column_names:
        raise BadInput(str(path), "not a bench sweep results table (no case_id/status columns)")
    return table.to_pylist()
