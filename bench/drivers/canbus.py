"""The CAN link: one python-can bus shared by the CAN drivers, the DBC codec and the SYNC producer.

Messages and the bus: `bench.wire.canbus` (the DBC with the rig file's frame ids, encoded with cantools).

`CanLink` is a `Device`. When ``can.sync`` is on it sends SYNC (tick number modulo 256) at the
start of every tick (`acquire`), after the other CAN drivers have flushed what they owe for the
previous tick - or, with ``can.sync_early`` (emulated rigs), right after the last write of the
previous tick (`end_of_tick`), which hides the emulator's compute time in the loop's idle time.
A real rig keeps SYNC at the start of the tick, on the deadline grid, so its sampling instants do
not jitter with the loop's compute time. Sampled devices act on SYNC, CANopen-style: the
inverter applies the set-point it holds, the front-end samples. Because SYNC and the set-points
share one bus, the emulator sees them in order, which is what makes emulated runs deterministic
(docs/protocols.md, section 1).

Received frames are dispatched by id to handlers that drivers register (`subscribe`); `poll`
drains the receive queue without blocking. Bus errors on send are counted and reported, not
raised: the supervisor trips on their consequences (missing heartbeat), and the loop goes on.

Transport: any python-can interface. ``virtual`` (default in rigs/emulated.toml) works inside one
process; ``tcp`` (bench.drivers.tcpcan, channel ``127.0.0.1:PORT``) connects to `bench emulate` in
another process; ``socketcan`` with ``vcan0`` works across processes where the kernel has vcan.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import can
import cantools

from bench.errors import LinkError
from bench.wire.canbus import load_dbc, open_bus

class CanLink:
    """Shared CAN bus + DBC + SYNC producer (a `Device`)."""

    def __init__(self, can_cfg: dict[str, Any], T_s: float) -> None:
        self.cfg = can_cfg
        self.T_s = T_s
        self.db = load_dbc(can_cfg)
        self.sync_msg = self.db.get_message_by_name("SYNC")
        self.bus: can.BusABC | None = None
        self._handlers: dict[int, Callable[[can.Message], None]] = {}
        self.send_errors = 0
        self.tick = 0
        self._pre_sync: list[Callable[[], None]] = []
        self._synced: int | None = None
        self._ticking = False

    def message(self, name: str) -> cantools.database.can.Message:
        return self.db.get_message_by_name(name)

    def subscribe(self, frame_id: int, handler: Callable[[can.Message], None]) -> None:
        self._handlers[frame_id] = handler

    def send(self, frame_id: int, data: bytes) -> bool:
        if self.bus is None:
            return False
        try:
            self.bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
            return True
        except can.CanError:
            self.send_errors += 1
            return False

    def poll(self) -> None:
        """Dispatch every frame waiting in the receive queue."""
        bus = self.bus
        if bus is None:
            return
        handlers = self._handlers
        while (msg := bus.recv(0.0)) is not None:
            h = handlers.get(msg.arbitration_id)
            if h is not None:
                h(msg)

    def wait(self, timeout: float) -> bool:
        """Wait for one frame up to ``timeout`` s and dispatch it; True if one came."""
        if self.bus is None:
            return False
        msg = self.bus.recv(timeout)
        if msg is None:
            return False
        h = self._handlers.get(msg.arbitration_id)
        if h is not None:
            h(msg)
        return True

    # --- Device ---------------------------------------------------------------------------------
    def configure(self) -> None:
        if self.bus is None:
            try:
                self.bus = open_bus(self.cfg)
            except (can.CanError, OSError, ValueError) as exc:
                where = f"{self.cfg['interface']}:{self.cfg['channel']}"
                raise LinkError("can.channel", f"cannot open CAN {where}: {exc}") from None

    def activate(self) -> None:
        self._synced, self._ticking = None, False

    def deactivate(self) -> None:
        self._ticking = False

    def close(self) -> None:
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None

    def add_pre_sync(self, hook: Callable[[], None]) -> None:
        """Call ``hook`` right before each SYNC (the inverter flushes its keep-alive set-point)."""
        self._pre_sync.append(hook)

    def sync(self, tick: int) -> None:
        for hook in self._pre_sync:
            hook()
        if self.cfg["sync"]:
            self.send(self.sync_msg.frame_id, self.sync_msg.encode({"TICK": tick & 0xFF}))
        self._synced = tick

    def acquire(self, t: float) -> None:
        self.tick = int(round(t / self.T_s))
        self._ticking = True
        if self._synced != self.tick:
            self.sync(self.tick)

    def end_of_tick(self) -> None:
        """Called by the last driver the `Rig` writes to (the load). With ``can.sync_early`` the
        SYNC of the next tick goes out now, so an emulator computes the next sample while the
        loop waits for its deadline (same frame order as SYNC-at-acquire, so the same results)."""
        if self._ticking and self.cfg["sync_early"]:
            self.sync(self.tick + 1)
