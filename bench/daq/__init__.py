"""imbench data acquisition: per-tick MCAP logging that Foxglove can plot, and reading it back.

Loop side::

    from bench.daq import LogWriter, Topic
    topics = [Topic("/rig/meas", "imbench_msgs/Meas", [("t", "float64"), ("enc_count", "int32")]), ...]
    with LogWriter("runs/x.mcap", topics, metadata={"run": {"seed": 1}}) as w:
        w.put(t_ns, values)          # once per tick, all topics' fields concatenated

Analysis side::

    from bench.daq import LogReader
    cols = LogReader("runs/x.mcap").read("/rig/meas")   # {"log_time": s, "t": ..., "enc_count": ...}

Messages are ros2msg schemas with CDR encoding, one message per topic per tick.
"""

from .reader import LogReader
from .schema import FIELD_TYPES, Topic, cdr_dtype, parse_ros2msg
from .version import code_version
from .writer import LogWriter, LogWriterError

__all__ = [
    "FIELD_TYPES",
    "LogReader",
    "LogWriter",
    "LogWriterError",
    "Topic",
    "cdr_dtype",
    "code_version",
    "parse_ros2msg",
]
