"""An in-memory stand-in for the MCAP log: the same ``put`` as `LogWriter`, the same ``read`` as `LogReader`.

For runs that need the per-tick record only for their own numbers (sweep cases, thesis
reproductions, benchmarks without logging): nothing is written to disk and no writer process is
started. Each row is packed as float64 into fixed-size byte blocks as it arrives (as `LogWriter` packs
its ring): a 3 s case at 3 kHz kept as 9000 tuples of 57 floats was half a million Python objects,
which the garbage collector scanned during the run, numpy converted at the end (~25 ms) and freeing
took another 10-20 ms of every sweep case.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

from .schema import Topic

__all__ = ["MemoryLog"]


class MemoryLog:
    """Collects ``put(t_ns, values)`` rows; ``read(topic)`` -> ``{field: array}`` like `LogReader`."""

    fault: str | None = None  # no writer to lose (the interface of LogWriter); a bad row raises in put

    BLOCK_ROWS = 4096  # rows per byte block (~1.9 MB at 57 columns)

    def __init__(self, topics: Sequence[Topic]) -> None:
        self.topics_ = list(topics)
        self.ncols = sum(len(tp.fields) for tp in self.topics_)
        row = struct.Struct(f"<{self.ncols}d")
        self._pack, self._rowsize = row.pack_into, row.size
        self._block_bytes = self.BLOCK_ROWS * row.size
        self._blocks: list[bytearray] = []  # full blocks
        self._block = bytearray(self._block_bytes)
        self._off = 0  # bytes used in self._block
        self._cols: np.ndarray | None = None
        self.inbox = None  # no live server, no requests (a replay brings its own)
        self._events: list[dict] = []

    def event(self, ev: dict) -> None:
        """A parameter change or operator action (bench.operate.operator), as `LogWriter.event`."""
        self._events.append(dict(ev))

    def events(self) -> list[dict]:
        """Like `LogReader.events`: the reports in the order applied."""
        return sorted(self._events, key=lambda e: (e["tick"], e["seq"]))

    def put(self, t_ns: int, values: Sequence[float]) -> None:
        """One row: ``values`` is the concatenation of all topics' fields (numbers or bools), as `LogWriter.put`."""
        try:
            self._pack(self._block, self._off, *values)
        except struct.error as e:
            raise TypeError(f"put(): {e} ({self.ncols} numbers or bools per row)") from None
        self._off += self._rowsize
        if self._off == self._block_bytes:
            self._blocks.append(self._block)
            self._block = bytearray(self._block_bytes)
            self._off = 0

    def __len__(self) -> int:
        """Rows put so far."""
        return len(self._blocks) * self.BLOCK_ROWS + self._off // self._rowsize

    def _array(self) -> np.ndarray:
        n = len(self)
        if self._cols is None or len(self._cols) != n:
            data = bytearray().join([*self._blocks, self._block[: self._off]])  # writable, as np.array was
            self._cols = np.frombuffer(data, dtype="<f8").reshape(n, self.ncols)
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
        return {"rows_put": len(self), "dropped": 0, "memory": True}
