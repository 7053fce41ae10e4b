"""imbench: test-bench driver and data acquisition for induction-motor drive research.

Package map: `bench.hal` (ports and records) -> `bench.loop` (timed loop) -> `bench.controllers`
(plugins) -> `bench.daq` (MCAP logs); `bench.session` wires a run together; `bench.cli` is the
`bench` command.
"""

__version__ = "0.1.0"
