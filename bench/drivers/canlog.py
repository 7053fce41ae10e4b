"""Every CAN frame of a run into a file, by python-can's own ``can.logger`` in a separate process.

`bench run --can-log FILE.blf|.asc|.log|.csv` starts ``python -m can.logger`` on the rig's bus
(python-can picks the writer from the suffix: BLF, ASC, ...). A separate process sees the frames
the way any other node does, so it costs the loop nothing, and it works on a real bus
(``socketcan``, ``pcan``, ...) as on the loopback link to the emulators (``tcp``, which relays
every frame to every client). The in-process ``virtual`` bus cannot be watched from outside.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from bench.errors import BadInput

SUFFIXES = (".blf", ".asc", ".log", ".csv", ".trc", ".mf4", ".txt")


def check(can_cfg: dict[str, Any] | None, path: Path) -> None:
    """Refuse a CAN log that cannot work, before anything runs."""
    if can_cfg is None:
        raise BadInput("--can-log", "needs a rig with CAN drivers (rig.driver = \"drivers\")")
    if can_cfg["interface"] == "virtual":
        raise BadInput("--can-log", "the virtual CAN interface lives inside this process; use can.interface = "
                       "\"tcp\" (the emulators) or a real bus")  # fmt: skip
    if path.suffix.lower() not in SUFFIXES:
        raise BadInput("--can-log", f"file type from the suffix: one of {', '.join(SUFFIXES)}, got {path.name!r}")


class CanLogger:
    """``python -m can.logger`` on ``can_cfg``'s bus, writing ``path``; `stop` ends it cleanly (SIGINT)."""

    def __init__(self, can_cfg: dict[str, Any], path: Path, start_timeout: float = 15.0) -> None:
        args = [sys.executable, "-m", "can.logger", "-i", can_cfg["interface"], "-c", str(can_cfg["channel"]),
                "-f", str(path)]  # fmt: skip
        if can_cfg["interface"] not in ("tcp",):
            args += ["-b", str(can_cfg["bitrate"])]
        self.path = path
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)  # our Ctrl-C is not its: stop() ends it in order
        line = self._first_line(start_timeout)
        if not line.startswith("Connected to"):
            self.stop()
            raise BadInput("--can-log", f"can.logger did not connect to the bus: {line.strip() or 'no answer'}")

    def _first_line(self, timeout: float) -> str:
        import selectors

        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)  # type: ignore[arg-type]
        if not sel.select(timeout):
            return ""
        return self.proc.stdout.readline() if self.proc.stdout else ""

    def stop(self, timeout: float = 10.0) -> str | None:
        """SIGINT (can.logger closes its writer), then kill if it does not end; a problem as one line, or None."""
        if self.proc.poll() is None:
            time.sleep(0.05)  # let it read the last frames (the safe command) off its socket first
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
                return f"can.logger did not stop within {timeout:g} s and was killed; {self.path} may be incomplete"
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return None
