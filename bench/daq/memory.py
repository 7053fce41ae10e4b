"""An in-memory stand-in for the MCAP log: the same ``put`` as `LogWriter`, the same ``read`` as `LogReader`.

For runs that need the per-tick record only for their own numbers (sweep cases, thesis
reproductions, benchmarks without logging): nothing is written to disk and no writer process is
started. Rows are kept as Python tuples, then turned into one float64 array per topic field.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .schema import Topic

__all__ = ["MemoryLog"]


class MemoryLog:
    """Collects ``put(t_ns, values)`` rows; ``read(topic)`` -> ``{field: array}`` like `LogReader`."""

    fault: str | None = None  # never fails (the interface of LogWriter)

    def __init__(self, topics: Sequence[Topic]) -> None:
        self.topics_ = list(topics)
        self.rows: list[Sequence[float]] = []
        self._cols: np.ndarray | None = None
        self.inbox = None  # no live server, no requests (a replay brings its own)
        self._events: list[dict] = []

    def event(self, ev: dict) -> None:
        """A parameter change or operator action (bench.operator), as `LogWriter.event`."""
        self._events.append(dict(ev))

    def events(self) -> list[dict]:
        """Like `LogReader.events`: the reports in the order applied."""
        return sorted(self._events, key=lambda e: (e["tick"], e["seq"]))

    def put(self, t_ns: int, values: Sequence[float]) -> None:
        self.rows.append(values)

    def _array(self) -> np.ndarray:
        if self._cols is None or len(self._cols) != len(self.rows):
            ncols = sum(len(tp.fields) for tp in self.topics_)
            self._cols = np.array(self.rows, dtype=float).reshape(len(self.rows), ncols)
        return self._cols

    def topics(self) -> list[str]:
        return [tp.name for tp in self.topics_]

    def read(self, topic: str) -> dict[str, np.ndarray]:
        arr, col = self._array(), 0
        for tp in self.topics_:
            if tp.name == topic:
                return {f: arr[:, col + i] for i, (f, _) in enumerate(tp.fields)}
            col += len(tp.fields)
        raise KeyError(f"no topic {topic!r}; topics: {self.topics()}")

    def read_ticks(self, *topics: str) -> list[dict[str, np.ndarray]]:
        """Like `LogReader.read_ticks` (a memory record is never torn)."""
        return [self.read(tp) for tp in topics]

    def columns(self) -> dict[str, np.ndarray]:
        """Every field as ``"<topic>/<field>"`` -> array."""
        return {f"{tp.name}/{f}": v for tp in self.topics_ for f, v in self.read(tp.name).items()}

    def stats(self) -> dict[str, int]:
        return {"rows_put": len(self.rows), "dropped": 0, "memory": True}
