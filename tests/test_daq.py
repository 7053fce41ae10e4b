"""Tests of bench.daq: CDR layout, MCAP round trips, Foxglove (mcap-ros2) compatibility, crash safety."""

from __future__ import annotations

import contextlib
import inspect
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from bench.daq import FIELD_TYPES, LogReader, LogWriter, LogWriterError, Topic, cdr_dtype, code_version, parse_ros2msg
from bench.perf.writer import realistic_topics, sample_rows
from bench.daq.mcap_block import BlockWriter, RowLayout
from bench.daq.writer_process import Packer

REPO = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000_000_000_000
DT = 333_333

# every supported type, with the alignment traps: 1-byte and 4-byte fields followed by 8-byte ones
ALL_TYPES = [
    ("flag", "bool"),
    ("x", "float64"),
    ("count", "int32"),
    ("y", "float64"),
    ("small", "uint8"),
    ("ratio", "float32"),
    ("big", "int64"),
    ("status", "uint32"),
    ("last_flag", "bool"),
]


def all_types_topics() -> list[Topic]:
    return [
        Topic("/all", "imbench_msgs/AllTypes", ALL_TYPES),
        Topic("/tail", "imbench_msgs/msg/Tail", [("n", "int32"), ("b", "bool")]),
    ]


def all_types_row(i: int) -> tuple:
    """Values as a loop would give them: Python bools, ints and floats mixed."""
    return (
        i % 3 == 0,  # bool as bool
        i * 0.5 - 3.25,
        -(2**31) + i if i % 2 else 2**31 - 1 - i,  # int32 extremes
        math.pi * i,
        float(i % 256),  # uint8 given as float
        1.1 * i,  # float32: rounds
        (-1) ** i * (2**53 - i),  # int64 at the float64-exact limit
        2**32 - 1 - i,  # uint32 max
        1.0 if i % 5 else 0.0,  # bool as float
        i,
        i % 2,  # bool as int
    )


def expected_columns(rows: list[tuple], topics: list[Topic]) -> dict[str, dict[str, np.ndarray]]:
    out, col = {}, 0
    for tp in topics:
        out[tp.name] = {}
        for name, typ in tp.fields:
            out[tp.name][name] = np.array([r[col] for r in rows], dtype=np.float64).astype(FIELD_TYPES[typ])
            col += 1
    return out


def wait_finished(path: Path, timeout: float = 30.0) -> None:
    from bench.daq.reader import is_finished

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if is_finished(path):
            return
        time.sleep(0.05)
    raise AssertionError(f"{path} was not finished within {timeout} s")


# ---------------------------------------------------------------------------- schema / CDR layout


def test_cdr_offsets_follow_natural_alignment_after_header():
    dt = cdr_dtype(ALL_TYPES)
    offsets = {name: dt.fields[name][1] for name, _ in ALL_TYPES}
    # positions relative to the end of the 4-byte header: bool 0, f64 8, i32 16, f64 24, u8 32,
    # f32 36, i64 40, u32 48, bool 52 -> end 53; +4 for the header
    assert offsets == {"flag": 4, "x": 12, "count": 20, "y": 28, "small": 36, "ratio": 40,
                       "big": 44, "status": 52, "last_flag": 56}
    assert dt.itemsize == 57  # no trailing padding in CDR


def test_schema_text_round_trips_through_parser():
    tp = Topic("/all", "imbench_msgs/AllTypes", ALL_TYPES)
    assert parse_ros2msg(tp.schema_text()) == ALL_TYPES
    text = "# comment\nfloat64 x  # speed\n\nint32 MODE_A=1\nbool ok true\nbyte raw\n"
    assert parse_ros2msg(text) == [("x", "float64"), ("ok", "bool"), ("raw", "uint8")]
    assert parse_ros2msg("string name\n") == [("name", "string")]  # event topics (bench.daq.events) only
    with pytest.raises(ValueError, match="name"):
        cdr_dtype(parse_ros2msg("string name\n"))  # no fixed layout: never a per-tick topic
    with pytest.raises(ValueError, match="arr"):
        parse_ros2msg("float64[] arr\n")


def test_bad_field_type_names_the_field():
    with pytest.raises(ValueError, match="'i_q'.*float128"):
        Topic("/ctrl", "imbench_msgs/Ctrl", [("t", "float64"), ("i_q", "float128")])
    with pytest.raises(ValueError, match="'i_mR'"):
        Topic("/ctrl", "imbench_msgs/Ctrl", [("i_mR", "float64")])  # ROS 2 names are lower case
    with pytest.raises(ValueError, match="'t' appears twice"):
        Topic("/ctrl", "imbench_msgs/Ctrl", [("t", "float64"), ("t", "int32")])
    with pytest.raises(ValueError, match="log_time"):
        Topic("/ctrl", "imbench_msgs/Ctrl", [("log_time", "float64")])
    with pytest.raises(ValueError, match="message type"):
        Topic("/ctrl", "Ctrl", [("t", "float64")])


_field_type = st.sampled_from(sorted(FIELD_TYPES))


def _value(ftype: str) -> st.SearchStrategy:
    ints = {"int8": (-128, 127), "uint8": (0, 255), "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
            "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1), "int64": (-(2**53), 2**53),
            "uint64": (0, 2**53)}
    if ftype == "bool":
        return st.booleans()
    if ftype in ints:
        return st.integers(*ints[ftype])
    if ftype == "float32":
        return st.floats(-1e30, 1e30, allow_nan=False)
    return st.floats(allow_nan=False, allow_infinity=True)


@st.composite
def layouts_and_rows(draw):
    types = draw(st.lists(_field_type, min_size=1, max_size=10))
    fields = [(f"f{i}", t) for i, t in enumerate(types)]
    n = draw(st.integers(1, 4))
    rows = [tuple(draw(_value(t)) for _, t in fields) for _ in range(n)]
    return fields, rows


@settings(max_examples=60, deadline=None)
@given(layouts_and_rows())
def test_packed_cdr_decodes_with_mcap_ros2(case):
    """Independent check: mcap-ros2-support (what Foxglove-compatible tooling uses) decodes our bytes."""
    fields, rows = case
    tp = Topic("/p", "prop_msgs/Prop", fields)
    (buf, size), = Packer([tp]).pack(np.array(rows, dtype=np.float64).reshape(len(rows), len(fields)))
    schema = Schema(id=1, name=tp.type, encoding="ros2msg", data=tp.schema_text().encode())
    decode = DecoderFactory().decoder_for("cdr", schema)
    assert size == tp.dtype().itemsize and len(buf) == size * len(rows)
    ours = np.frombuffer(buf, cdr_dtype(parse_ros2msg(tp.schema_text())))
    for k, row in enumerate(rows):
        msg = decode(buf[k * size : (k + 1) * size])
        for (name, typ), v in zip(fields, row):
            want = np.array([v], np.float64).astype(FIELD_TYPES[typ])[0]
            got = getattr(msg, name)
            assert got == want or (typ == "float32" and np.float32(got) == want), (name, typ, v, got)
            assert ours[name][k] == want
    # the writer's whole-record packing gives the same message bytes, for one topic and between two others
    other = Topic("/o", "prop_msgs/Other", [("a", "uint8"), ("b", "float64")])
    for topics, j in (([tp], 0), ([other, tp, other], 1)):
        vals = np.zeros((len(rows), sum(len(t.fields) for t in topics)))
        vals[:, 2 * j : 2 * j + len(fields)] = np.array(rows, dtype=np.float64).reshape(len(rows), len(fields))
        layout = RowLayout(topics, range(1, len(topics) + 1))
        recs = layout.pack(T0 + np.arange(len(rows)) * DT, vals, 2**32 - 1)
        assert [layout.message(recs, k, j) for k in range(len(rows))] == [
            buf[k * size : (k + 1) * size] for k in range(len(rows))]  # fmt: skip


def _mcap_bytes(topics: list[Topic], rows: list[tuple], chunk_size: int, blocks: bool) -> bytes:
    """An MCAP file of ``rows`` in blocks of varying size, with an event message and now and then a flush
    between blocks: message by message through mcap's Writer, or a block at a time through BlockWriter."""
    import io

    from mcap.writer import CompressionType, Writer

    vals = np.array(rows, np.float64)
    t = T0 + np.arange(len(rows)) * DT
    f = io.BytesIO()
    w = (BlockWriter if blocks else Writer)(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    w.start(profile="ros2")
    cids = [w.register_channel(tp.name, "cdr", w.register_schema(tp.type, "ros2msg", tp.schema_text().encode()))
            for tp in topics]  # fmt: skip
    ev = w.register_channel("/events", "json", 0)
    layout = RowLayout(topics, cids)
    s = i = 0
    while s < len(rows):
        n = (5, 64, 1, 200, 7)[i % 5]
        if blocks:
            assert w.blocks  # the installed mcap's Writer is the one BlockWriter knows
            w.add_rows(layout, layout.pack(t[s : s + n], vals[s : s + n], s))
        else:
            packed = Packer(topics).pack(vals[s : s + n])
            for k in range(min(n, len(rows) - s)):
                for cid, (b, sz) in zip(cids, packed):
                    w.add_message(cid, int(t[s + k]), b[k * sz : (k + 1) * sz], int(t[s + k]), s + k)
        s += n
        i += 1
        w.add_message(ev, int(t[min(s, len(rows)) - 1]), b"{}", int(t[min(s, len(rows)) - 1]), i)
        if i % 7 == 0:  # a message of a tick channel between blocks, as add_message takes it
            w.add_message(cids[-1], int(t[min(s, len(rows)) - 1]), b"\x00\x01\x00\x00", 0, 2**32 - 1)
        if i % 9 == 0:
            w.flush()
    w.finish()
    return f.getvalue()


@pytest.mark.parametrize("chunk_size", [300, 4096, 1 << 20])
def test_block_writer_file_is_the_message_by_message_file(chunk_size):
    """A block at a time (whole records packed with numpy, one write per chunk part) gives the same file, byte for
    byte, as mcap's Writer fed message by message: chunks closed after the same message (mid-tick with small
    chunks), the same message indexes, statistics and summary."""
    for topics, rows in ((all_types_topics(), [all_types_row(i) for i in range(700)]),
                         (realistic_topics(), sample_rows(realistic_topics(), 1500, seed=3))):  # fmt: skip
        assert _mcap_bytes(topics, rows, chunk_size, True) == _mcap_bytes(topics, rows, chunk_size, False)


# ---------------------------------------------------------------------------- write / read round trips


def test_all_types_round_trip_and_mcap_ros2_cross_check(tmp_path):
    topics = all_types_topics()
    rows = [all_types_row(i) for i in range(200)]
    path = tmp_path / "all.mcap"
    with LogWriter(path, topics, batch_ticks=16) as w:
        for i, row in enumerate(rows):
            w.put(T0 + i * DT, row)
    st_ = w.stats()
    assert st_["dropped"] == 0 and st_["rows_written"] == 200 and st_["writer"]["ended_by"] == "close"
    assert st_["publishes"] == 13 and st_["rows_put"] == 200

    r = LogReader(path)
    assert r.topics() == ["/all", "/tail"]
    assert r.fields("/all") == [n for n, _ in ALL_TYPES]
    assert r.schema("/tail") == [("n", "int32"), ("b", "bool")]
    want = expected_columns(rows, topics)
    for tp in topics:
        cols = r.read(tp.name)
        np.testing.assert_array_equal(r.read(tp.name, ns=True)["log_time"], T0 + np.arange(200) * DT)
        assert cols["log_time"].dtype == np.float64
        np.testing.assert_allclose(cols["log_time"], (T0 + np.arange(200) * DT) / 1e9, rtol=0, atol=1e-6)
        for name, typ in tp.fields:
            assert cols[name].dtype == np.dtype(FIELD_TYPES[typ]), name
            np.testing.assert_array_equal(cols[name], want[tp.name][name], err_msg=name)

    # Foxglove-style decoding, independent of our reader: schema text + CDR via mcap-ros2-support
    seen = {"/all": 0, "/tail": 0}
    with open(path, "rb") as f:
        for schema, channel, message, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert message.data[:4] == b"\x00\x01\x00\x00"
            k = seen[channel.topic]
            seen[channel.topic] += 1
            assert message.log_time == message.publish_time == T0 + k * DT
            assert message.sequence == k
            tp = topics[0] if channel.topic == "/all" else topics[1]
            for name, _ in tp.fields:
                assert getattr(decoded, name) == want[tp.name][name][k], (channel.topic, name, k)
    assert seen == {"/all": 200, "/tail": 200}


def test_metadata_round_trip(tmp_path):
    run = {"seed": 42, "scenario": "flux_step", "gains": {"kp": 1.5, "ki": [1, 2, 3]}, "note": "Ω≈ω_r", "none": None}
    rig = {"name": "mock", "T_s": 1 / 3000, "rated": {"p_w": 1500.0}}
    path = tmp_path / "meta.mcap"
    with LogWriter(path, all_types_topics(), metadata={"run": run, "rig": rig}) as w:
        w.put(T0, all_types_row(0))
        w.add_metadata("result", {"tripped": False, "rms_error": 0.012})
    md = LogReader(path).metadata()
    assert md["run"] == run and md["rig"] == rig
    assert md["result"] == {"tripped": False, "rms_error": 0.012}
    assert md["daq"]["code_version"] == code_version()
    assert md["daq"]["topics"] == ["/all", "/tail"]
    # raw MCAP records (what Foxglove shows): names as in the README, strings plain, the rest JSON
    with open(path, "rb") as f:
        reader = make_reader(f)
        raw = {m.name: m.metadata for m in reader.iter_metadata()}
        assert reader.get_header().profile == "ros2"
    assert raw["run"]["scenario"] == "flux_step" and raw["run"]["note"] == "Ω≈ω_r"
    assert json.loads(raw["run"]["gains"]) == run["gains"] and raw["run"]["seed"] == "42"
    assert "/all/f64" not in raw["units"] and md["units"] == raw["units"]  # only fields with a unit
    with pytest.raises(TypeError, match="JSON"):
        LogWriter(tmp_path / "bad.mcap", all_types_topics(), metadata={"run": {"x": object()}})
    with pytest.raises(ValueError, match="reserved"):
        LogWriter(tmp_path / "bad.mcap", all_types_topics(), metadata={"daq": {}})


def test_logs_of_the_old_layout_still_read(tmp_path):
    """Before Nov 2026: records named imbench.<name>, every value JSON, no profile, schema names without /msg/."""
    from mcap.writer import Writer

    path = tmp_path / "old.mcap"
    tp = Topic("/rig", "imbench_msgs/RigTick", [("t", "float64"), ("tick", "int64")])
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="imbench-daq/old")
        w.add_metadata("imbench.run", {"scenario": json.dumps("demo"), "seed": "3"})
        cid = w.register_channel("/rig", "cdr", w.register_schema(tp.type, "ros2msg", b"float64 t\nint64 tick\n"))
        for k in range(5):
            row = np.zeros(1, tp.dtype())
            row["_cdr_header"] = np.frombuffer(b"\x00\x01\x00\x00", np.uint8)
            row["t"], row["tick"] = k / 3000, k
            w.add_message(cid, k * 333333, row.tobytes(), k * 333333)
        w.finish()
    r = LogReader(path)
    assert r.metadata()["run"] == {"scenario": "demo", "seed": 3}
    assert r.read("/rig")["tick"].tolist() == [0, 1, 2, 3, 4]


def test_units_in_schema_comments_and_metadata(tmp_path):
    tp = Topic("/rig", "imbench_msgs/msg/RigTick", [("t", "float64"), ("i_a", "float64"), ("omega_r_ref", "float64"),
                                                    ("m_l_ref", "float64"), ("psi_r_re", "float64"), ("rho", "float64"),
                                                    ("compute_us", "float64"), ("gain", "float64")])  # fmt: skip
    assert tp.units == ("s", "A", "rad/s", "N m", "Wb", "rad", "µs", "")
    assert "float64 i_a  # [A]" in tp.schema_text() and "float64 gain\n" in tp.schema_text()
    assert parse_ros2msg(tp.schema_text()) == list(tp.fields)


def test_30000_ticks_realistic_layout_round_trip_exact(tmp_path):
    topics = realistic_topics()
    rows = sample_rows(topics, 30_000, seed=7)
    path = tmp_path / "many.mcap"
    with LogWriter(path, topics, metadata={"run": {"seed": 7}}) as w:
        for i, row in enumerate(rows):
            w.put(T0 + i * DT, row)
    st_ = w.stats()
    assert st_["rows_written"] == 30_000 and st_["dropped"] == 0
    assert st_["put_us"]["n"] == 30_000
    r = LogReader(path)
    s = r.summary()
    assert s["finalised"] and not s["truncated"]
    assert s["message_count"] == 5 * 30_000
    assert all(v["messages"] == 30_000 for v in s["topics"].values())
    assert s["start_ns"] == T0 and s["end_ns"] == T0 + 29_999 * DT
    want = expected_columns(rows, topics)
    for tp in topics:
        cols = r.read(tp.name)
        for name, _ in tp.fields:
            np.testing.assert_array_equal(cols[name], want[tp.name][name], err_msg=f"{tp.name}.{name}")


@pytest.mark.parametrize("notify", [False, True], ids=["store", "notify"])
def test_small_ring_wraps_and_waits_without_loss(tmp_path, notify):
    """A 64-row ring, odd flush points and a loop far faster than the writer: wrap-around,
    partial publications and back-pressure, in both publication modes."""
    path = tmp_path / "ring.mcap"
    with LogWriter(path, all_types_topics(), batch_ticks=16, ring_ticks=64, notify=notify) as w:
        for i in range(3000):
            w.put(T0 + i * DT, all_types_row(i))
            if i % 97 == 0:
                w.flush()
    st_ = w.stats()
    assert st_["notify"] is notify and st_["ring_ticks"] == 64
    assert st_["stalls"] > 0 and st_["dropped"] == 0 and st_["rows_written"] == 3000
    cols = LogReader(path).read("/all")
    want = expected_columns([all_types_row(i) for i in range(3000)], all_types_topics())["/all"]
    for name, _ in ALL_TYPES:
        np.testing.assert_array_equal(cols[name], want[name], err_msg=name)


def test_exception_inside_with_still_gives_valid_file(tmp_path):
    path = tmp_path / "exc.mcap"
    with pytest.raises(RuntimeError, match="trip"):
        with LogWriter(path, all_types_topics(), batch_ticks=64) as w:
            for i in range(100):  # one full batch + a partial one
                w.put(T0 + i * DT, all_types_row(i))
            raise RuntimeError("overcurrent trip")
    r = LogReader(path)
    assert r.summary()["finalised"]
    np.testing.assert_array_equal(r.read("/tail")["n"], np.arange(100))
    with pytest.raises(ValueError, match="closed"):
        w.put(T0, all_types_row(0))
    assert w.close()["rows"] == 100  # idempotent


def test_put_validation(tmp_path):
    with LogWriter(tmp_path / "v.mcap", all_types_topics()) as w:
        with pytest.raises(ValueError, match="got 3 values.*11 fields"):
            w.put(T0, (1.0, 2.0, 3.0))
        with pytest.raises(TypeError, match="t_ns"):
            w.put(T0 / 1.0, all_types_row(0))
        with pytest.raises(TypeError):
            w.put(T0, (None,) + all_types_row(0)[1:])
        w.put(T0, all_types_row(0))  # a failed put leaves no trace
    assert LogReader(tmp_path / "v.mcap").summary()["message_count"] == 2


def test_writer_that_cannot_open_file_fails_loudly(tmp_path):
    (tmp_path / "dir.mcap").mkdir()
    with pytest.raises(LogWriterError, match="IsADirectoryError"):
        LogWriter(tmp_path / "dir.mcap", all_types_topics())


# ---------------------------------------------------------------------------- crashes and signals

CRASH_CHILD = """
import math, os, sys
sys.path.insert(0, {repo!r})
from bench.daq import LogWriter, Topic
{row_source}
topics = [Topic("/all", "imbench_msgs/AllTypes", {all_types!r}),
          Topic("/tail", "imbench_msgs/msg/Tail", [("n", "int32"), ("b", "bool")])]
w = LogWriter({path!r}, topics, batch_ticks=64)
for i in range(1000):          # 15 full batches sent (960 rows), 40 rows pending
    w.put({t0} + i * {dt}, all_types_row(i))
w.flush()                      # the 40 pending rows go now: 1000 rows are safe
for i in range(1000, 1030):    # 30 rows in the partial batch
    w.put({t0} + i * {dt}, all_types_row(i))
{ending}
"""


@pytest.mark.parametrize(
    "ending, code, rows",
    [
        ("os._exit(1)", 1, 1000),  # hard death: no close(), no atexit, no finally -> partial batch lost
        ("sys.exit(3)", 3, 1030),  # normal exit without close(): the atexit hook closes properly
    ],
)
def test_loop_process_exits_without_close_writer_finishes_file(tmp_path, ending, code, rows):
    path = tmp_path / "crash.mcap"
    src = CRASH_CHILD.format(
        repo=str(REPO), row_source=inspect.getsource(all_types_row), all_types=ALL_TYPES, path=str(path),
        t0=T0, dt=DT, ending=ending,
    )
    proc = subprocess.run([sys.executable, "-c", src], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert proc.returncode == code, proc.stderr
    wait_finished(path)
    r = LogReader(path)
    s = r.summary()
    assert s["finalised"] and not s["truncated"]
    assert s["topics"]["/all"]["messages"] == rows  # everything that was sent
    cols = r.read("/all")
    want = expected_columns([all_types_row(i) for i in range(rows)], all_types_topics())["/all"]
    for name, _ in ALL_TYPES:
        np.testing.assert_array_equal(cols[name], want[name], err_msg=name)


CTRL_C_CHILD = """
import faulthandler, math, signal, sys
faulthandler.dump_traceback_later(40)  # a hang shows where (stderr), before the test gives up at 60 s
# Ctrl-C raises KeyboardInterrupt, as in any Python program started from a terminal, even when the test
# runner was started in the background (a shell without job control starts background jobs with SIGINT
# ignored, children inherit that, and Python then leaves it ignored: this test hung there)
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.path.insert(0, {repo!r})
from bench.daq import LogWriter, Topic
{row_source}
topics = [Topic("/all", "imbench_msgs/AllTypes", {all_types!r}),
          Topic("/tail", "imbench_msgs/msg/Tail", [("n", "int32"), ("b", "bool")])]
w = LogWriter({path!r}, topics, batch_ticks=16)
n = 0
try:
    with w:
        while True:                 # as fast as it goes: sends often block on a full pipe
            w.put({t0} + n * {dt}, all_types_row(n))
            n += 1
            if n == 3000:
                print("running", flush=True)
finally:
    print("puts", n, flush=True)
"""


def test_ctrl_c_to_the_process_group_closes_the_log(tmp_path):
    """Ctrl-C hits loop and writer alike: the writer ignores it, the loop's `with` closes the file."""
    path = tmp_path / "ctrl_c.mcap"
    src = CTRL_C_CHILD.format(
        repo=str(REPO), row_source=inspect.getsource(all_types_row), all_types=ALL_TYPES, path=str(path), t0=T0, dt=DT
    )
    proc = subprocess.Popen([sys.executable, "-c", src], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == "running", proc.stderr.read()
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            pytest.fail(f"the interrupted loop did not exit within 60 s (puts: {out!r}); its stacks at 40 s:\n{err}")
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # the writer too, whatever happened
    assert "KeyboardInterrupt" in err
    _, n_put = out.split()
    n_put = int(n_put)
    r = LogReader(path)
    assert r.summary()["finalised"]
    n = r.read("/tail")["n"]
    np.testing.assert_array_equal(n, np.arange(len(n)))  # an exact prefix of what was put
    assert len(n) in (n_put, n_put + 1)  # +1: the interrupted put() had packed its row


def test_writer_ignores_sigint(tmp_path):
    path = tmp_path / "int.mcap"
    with LogWriter(path, all_types_topics(), batch_ticks=8) as w:
        for i in range(50):
            w.put(T0 + i * DT, all_types_row(i))
        os.kill(w.writer_pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
        time.sleep(0.2)
        assert w.healthy
        for i in range(50, 100):
            w.put(T0 + i * DT, all_types_row(i))
    np.testing.assert_array_equal(LogReader(path).read("/tail")["n"], np.arange(100))


def test_writer_killed_loop_keeps_running_close_reports(tmp_path):
    path = tmp_path / "killed.mcap"
    w = LogWriter(path, all_types_topics(), batch_ticks=8, chunk_size=1024)
    for i in range(200):
        w.put(T0 + i * DT, all_types_row(i))
    w.flush(chunk=True)
    deadline = time.monotonic() + 10
    while w.stats()["chunk_flushes"] < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    os.kill(w.writer_pid, signal.SIGKILL)
    time.sleep(0.2)
    for i in range(200, 300):  # must neither raise nor block
        w.put(T0 + i * DT, all_types_row(i))
    assert not w.healthy
    with pytest.raises(LogWriterError, match="failed"):
        w.close()
    assert w.stats()["dropped"] == 100
    # no summary, but every complete chunk is readable
    r = LogReader(path)
    s = r.summary()
    assert not s["finalised"]
    np.testing.assert_array_equal(r.read("/tail")["n"], np.arange(200))


def test_reader_reads_unfinished_file_up_to_the_torn_chunk(tmp_path):
    full = tmp_path / "full.mcap"
    with LogWriter(full, all_types_topics(), batch_ticks=32, chunk_size=4096) as w:
        for i in range(2000):
            w.put(T0 + i * DT, all_types_row(i))
    size = full.stat().st_size
    torn = tmp_path / "torn.mcap"
    with open(full, "rb") as f:
        torn.write_bytes(f.read(int(size * 0.6)))
    r = LogReader(torn)
    s = r.summary()
    assert not s["finalised"] and s["truncated"]
    n = r.read("/tail")["n"]
    assert 500 < len(n) < 2000
    np.testing.assert_array_equal(n, np.arange(len(n)))  # an exact prefix
    assert r.metadata()["daq"]["topics"] == ["/all", "/tail"]


def test_code_version_without_git(monkeypatch):
    v = code_version()
    assert v.startswith("0.") or v.startswith("0+")
    code_version.cache_clear()
    monkeypatch.setenv("PATH", "/nonexistent")
    try:
        assert code_version().split("+git")[0] == v.split("+git")[0]
    finally:
        code_version.cache_clear()


def test_memory_log_keeps_rows_exactly_across_blocks():
    """The in-memory record (sweep cases, reproductions) packs float64 rows in blocks: every value comes back
    as np.array(rows, float) would give it, across block boundaries and for reads between puts."""
    from bench.daq.memory import MemoryLog

    topics = realistic_topics()
    n = 2 * MemoryLog.BLOCK_ROWS + 17
    rows = sample_rows(topics, n, seed=3)
    log = MemoryLog(topics)
    for i, row in enumerate(rows[:100]):
        log.put(T0 + i * DT, row)
    assert len(log.read(topics[0].name)[topics[0].fields[0][0]]) == 100  # a read mid-run
    for i, row in enumerate(rows[100:], 100):
        log.put(T0 + i * DT, row)
    assert len(log) == n and log.stats()["rows_put"] == n
    want = np.array(rows, dtype=float)
    cols = log.columns()
    assert len(cols) == want.shape[1]
    for j, (name, col) in enumerate(cols.items()):
        np.testing.assert_array_equal(col, want[:, j], err_msg=name)
    with pytest.raises(TypeError, match="numbers or bools per row"):
        log.put(T0, rows[0][:3])
    with pytest.raises(TypeError):
        log.put(T0, (None,) + tuple(rows[0][1:]))
    assert len(log) == n  # a failed put leaves no trace
