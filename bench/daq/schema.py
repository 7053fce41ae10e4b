"""Flat ros2msg schemas and their CDR layout as numpy structured dtypes.

A :class:`Topic` is a flat ROS 2 message: a list of (name, primitive type) pairs. Its CDR
encoding (little-endian, XCDR1 "plain" CDR as written by ROS 2 and read by Foxglove) is a
4-byte encapsulation header ``00 01 00 00`` followed by the fields, each aligned to its own
size *relative to the end of the header*, with no trailing padding.

:func:`cdr_dtype` turns a field list into a numpy structured dtype whose field offsets
reproduce exactly that layout, header included (field ``_cdr_header``). One row of an
array of that dtype is therefore one complete CDR message: packing a batch is a handful of
vectorised column assignments plus ``tobytes()``, and decoding a batch is one
``np.frombuffer``. We pack CDR ourselves because no maintained Python library serialises
thousands of messages per second vectorised (mcap-ros2-support's encoder works per message
and per field in Python); its *decoder* is used in the tests as the independent check.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from .units import unit_of

__all__ = [
    "CDR_HEADER",
    "CDR_LE_HEADER",
    "FIELD_TYPES",
    "HEADER_FIELD",
    "Topic",
    "cdr_dtype",
    "decode_cdr",
    "encode_cdr",
    "parse_ros2msg",
]

#: ros2msg primitive type -> little-endian numpy dtype string. Every one is fixed-size and
#: aligned to its own size in CDR.
FIELD_TYPES: dict[str, str] = {
    "float64": "<f8",
    "float32": "<f4",
    "int64": "<i8",
    "uint64": "<u8",
    "int32": "<i4",
    "uint32": "<u4",
    "int16": "<i2",
    "uint16": "<u2",
    "int8": "i1",
    "uint8": "u1",
    "bool": "?",
}
# Variable-size types: only in the event topics (/params, /events: bench.daq.events), never per tick.
VAR_TYPES = frozenset({"string"})
# Names a foreign ros2msg file may use for 1-byte types; read, never written.
_READ_ALIASES = {"byte": "uint8", "char": "uint8", "octet": "uint8"}

CDR_LE_HEADER = b"\x00\x01\x00\x00"  # representation id CDR_LE, options 0
CDR_HEADER = np.frombuffer(CDR_LE_HEADER, np.uint8)
HEADER_FIELD = "_cdr_header"  # cannot clash: ROS 2 field names start with a letter
RESERVED_FIELDS = frozenset({"log_time"})  # the reader adds this column

# The same rules rosidl (and so mcap-ros2-support and Foxglove) apply.
_FIELD_NAME = re.compile(r"^(?!.*__)(?!.*_$)[a-z][a-z0-9_]*$")
_PKG_NAME = _FIELD_NAME
_MSG_NAME = re.compile(r"^[A-Z][A-Za-z0-9]*$")


def _check_type_name(type_name: str) -> None:
    parts = type_name.split("/")
    ok = (
        len(parts) in (2, 3)
        and _PKG_NAME.match(parts[0]) is not None
        and _MSG_NAME.match(parts[-1]) is not None
        and (len(parts) == 2 or parts[1] == "msg")
    )
    if not ok:
        raise ValueError(
            f"message type {type_name!r} must look like 'pkg_name/MsgName' or 'pkg_name/msg/MsgName'"
        )


@dataclass(frozen=True)
class Topic:
    """One MCAP channel: topic name, ros2msg type name and flat field list.

    ``Topic("/rig/meas", "imbench_msgs/Meas", [("t", "float64"), ("enc_count", "int32")])``.
    Field names follow ROS 2 rules (lower-case snake case: ``i_mr``, not ``i_mR``).
    Raises ValueError naming the offending field or type.
    """

    name: str
    type: str
    fields: tuple[tuple[str, str], ...]
    units: tuple[str, ...] = ()  # per field; default: by name (bench.daq.units)

    def __post_init__(self) -> None:
        fields = tuple((str(n), str(t)) for n, t in self.fields)
        object.__setattr__(self, "fields", fields)
        units = tuple(self.units) if self.units else tuple(unit_of(n) for n, _ in fields)
        if len(units) != len(fields):
            raise ValueError(f"topic {self.name!r}: {len(units)} units for {len(fields)} fields")
        object.__setattr__(self, "units", units)
        if not self.name or not isinstance(self.name, str):
            raise ValueError("topic name must be a non-empty string")
        _check_type_name(self.type)
        if not fields:
            raise ValueError(f"topic {self.name!r} has no fields")
        seen: set[str] = set()
        for fname, ftype in fields:
            if ftype not in FIELD_TYPES:
                raise ValueError(
                    f"topic {self.name!r}: field {fname!r} has unsupported type {ftype!r}; "
                    f"supported: {', '.join(FIELD_TYPES)}"
                )
            if not _FIELD_NAME.match(fname) or fname in RESERVED_FIELDS:
                raise ValueError(
                    f"topic {self.name!r}: field name {fname!r} is not a valid ROS 2 field name "
                    "(lower-case letters, digits and single underscores, starting with a letter; "
                    "'log_time' is reserved)"
                )
            if fname in seen:
                raise ValueError(f"topic {self.name!r}: field {fname!r} appears twice")
            seen.add(fname)

    @property
    def field_names(self) -> list[str]:
        return [n for n, _ in self.fields]

    def schema_text(self) -> str:
        """The ros2msg definition stored in the MCAP Schema record, units as comments (``float64 i_a  # [A]``)."""
        return "".join(f"{t} {n}  # [{u}]\n" if u else f"{t} {n}\n" for (n, t), u in zip(self.fields, self.units))

    def dtype(self) -> np.dtype:
        """Structured dtype of one complete CDR message (header included)."""
        return cdr_dtype(self.fields)


def cdr_dtype(fields: Sequence[tuple[str, str]], byteorder: str = "<") -> np.dtype:
    """Structured dtype reproducing the CDR layout of ``fields``, 4-byte header included.

    Offsets are ``4 + align(pos, size)``; itemsize is the end of the last field (CDR has
    no trailing padding), so consecutive rows of an array are consecutive messages.
    """
    names = [HEADER_FIELD]
    formats: list = [("u1", (4,))]
    offsets = [0]
    pos = 0  # relative to the end of the encapsulation header
    for fname, ftype in fields:
        if ftype not in FIELD_TYPES:
            raise ValueError(f"field {fname!r}: {ftype} has no fixed CDR layout (decode it with decode_cdr)")
        np_type = np.dtype(FIELD_TYPES[ftype]).newbyteorder(byteorder)
        size = np_type.itemsize
        pos = (pos + size - 1) // size * size
        names.append(fname)
        formats.append(np_type)
        offsets.append(4 + pos)
        pos += size
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": 4 + pos})


def parse_ros2msg(text: str) -> list[tuple[str, str]]:
    """Parse the flat primitive subset of a ros2msg definition into (name, type) pairs.

    Comments, blank lines, constants (``int32 FOO=1``) and default values are accepted; ``string``
    fields too (the event topics); arrays and nested message types raise ValueError (imbench never
    writes them).
    """
    fields: list[tuple[str, str]] = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if re.match(r"^={3,}$", line) or line.startswith("MSG:"):
            raise ValueError("nested ros2msg definitions are not supported by the imbench reader")
        parts = line.split()
        if len(parts) < 2:
            raise ValueError(f"cannot parse ros2msg line {raw!r}")
        ftype, fname = parts[0], parts[1]
        if "=" in line:
            continue  # constant (NAME=value): no storage in the message
        ftype = _READ_ALIASES.get(ftype, ftype)
        if ftype not in FIELD_TYPES and ftype not in VAR_TYPES:
            raise ValueError(f"field {fname!r}: type {ftype!r} is outside the flat primitive subset")
        fields.append((fname, ftype))
    if not fields:
        raise ValueError("ros2msg definition has no fields")
    return fields


def concat_fields(topics: Iterable[Topic]) -> list[tuple[str, str, str]]:
    """(topic, field, type) for every value of one ``put()`` row, in order."""
    return [(tp.name, n, t) for tp in topics for n, t in tp.fields]


# One message at a time, for the few variable-size event messages (a parameter change, an operator
# action). Hand-written because the per-tick path packs with numpy (above) and mcap-ros2-support
# serialises only through its own file writer; this is the same CDR (XCDR1, little-endian): each
# primitive aligned to its size from the end of the 4-byte header, a string as uint32 length
# (with the NUL) + UTF-8 bytes + NUL.
def encode_cdr(fields: Sequence[tuple[str, str]], values: Sequence[Any]) -> bytes:
    """One CDR_LE message of ``fields`` (primitives and strings) holding ``values``."""
    out = bytearray(CDR_LE_HEADER)
    for (fname, ftype), v in zip(fields, values, strict=True):
        if ftype == "string":
            data = str(v).encode("utf-8", "replace") + b"\0"
            out += b"\0" * (-(len(out) - 4) % 4) + struct.pack("<I", len(data)) + data
        else:
            fmt = np.dtype(FIELD_TYPES[ftype])
            out += b"\0" * (-(len(out) - 4) % fmt.itemsize) + np.array(v, fmt).tobytes()
    return bytes(out)


def decode_cdr(fields: Sequence[tuple[str, str]], data: bytes) -> tuple[Any, ...]:
    """The values of one CDR_LE message of ``fields`` (`encode_cdr`'s inverse)."""
    if data[:2] != CDR_LE_HEADER[:2]:
        raise ValueError("unsupported CDR encapsulation (only CDR_LE)")
    pos, vals = 4, []
    for _fname, ftype in fields:
        if ftype == "string":
            pos += -(pos - 4) % 4
            (n,) = struct.unpack_from("<I", data, pos)
            vals.append(bytes(data[pos + 4 : pos + 3 + n]).decode("utf-8", "replace"))
            pos += 4 + n
        else:
            fmt = np.dtype(FIELD_TYPES[ftype])
            pos += -(pos - 4) % fmt.itemsize
            vals.append(np.frombuffer(data, fmt, count=1, offset=pos)[0].item())
            pos += fmt.itemsize
    return tuple(vals)
