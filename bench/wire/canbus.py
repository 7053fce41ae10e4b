"""The rig's CAN messages and its bus: the DBC (default: the packaged ``imbench.dbc``, encoded and decoded with
cantools) with the frame ids of the rig file's ``[can]`` table (``sync_id``, ``setpoint_id``, ``load_id``,
``status_id``; they override the DBC's, so a lab can move frames without editing the DBC), and the python-can bus
the table names. The drivers (`bench.drivers.canbus`, `vlt`, `load`) and the emulated devices use the same.
"""

from __future__ import annotations

from importlib import resources
from typing import Any

import can
import cantools

DBC_DEFAULT = "imbench.dbc"
_ID_KEYS = {"SYNC": "sync_id", "VLT_SETPOINT": "setpoint_id", "LOAD_TORQUE": "load_id", "VLT_STATUS": "status_id"}


def load_dbc(can_cfg: dict[str, Any]) -> cantools.database.can.Database:
    """The DBC database with the frame ids of the rig file applied."""
    path = can_cfg.get("dbc") or ""
    if path:
        db = cantools.database.load_file(path)
    else:
        db = cantools.database.load_string(resources.files("bench.wire").joinpath(DBC_DEFAULT).read_text(), "dbc")
    for name, key in _ID_KEYS.items():
        if key in can_cfg:
            db.get_message_by_name(name).frame_id = can_cfg[key]
    db.refresh()
    return db


def open_bus(can_cfg: dict[str, Any], **kw: Any) -> can.BusABC:
    """A python-can bus for the rig file's ``[can]``; ``tcp`` (the loopback link to `bench emulate`,
    bench.drivers.tcpcan, records of `bench.wire.tcpcan`) is registered as a python-can interface (entry point ``can.interface``)."""
    interface = can_cfg["interface"]
    extra: dict[str, Any] = {}
    if interface not in ("virtual", "tcp"):
        extra["bitrate"] = can_cfg["bitrate"]
    return can.Bus(interface=interface, channel=can_cfg["channel"], **extra, **kw)


def fault_names(msg_st: cantools.database.can.Message) -> dict[int, str]:
    """VLT_STATUS.FAULT's value table (code -> name), empty for a DBC without the signal."""
    sig = next((s for s in msg_st.signals if s.name == "FAULT"), None)
    return {int(k): str(v) for k, v in (sig.choices or {}).items()} if sig is not None else {}
