"""What each worker of the sweep's own local cluster sets up when it starts (a Dask worker plugin: a worker the nanny
restarts gets it too): Ctrl-C is this process's to handle, and Dask's own complaint that the scheduler went away
before the worker is not printed.

A Ctrl-C at the terminal goes to the whole process group; the sweep's process writes the table and closes the
cluster, so the workers ignore SIGINT (they start with it blocked: `bench.workflows.sweep.engine`). The scheduler of a
local cluster lives in the sweep's own process: when it closes (the sweep ends, or is interrupted), a worker's heartbeat
in flight fails and Dask logs that failure with a traceback at level ERROR. That is no news to anyone (the sweep knows
it is closing, and a sweep that loses its scheduler otherwise says so in one line), so that one record is dropped; every
other record of the worker goes through as before.
"""

from __future__ import annotations

import logging
import signal
import threading
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

HEARTBEAT_LOST = "Failed to communicate with scheduler during heartbeat"  # distributed.worker.Worker.heartbeat


def _not_heartbeat_lost(record: logging.LogRecord) -> bool:
    return not str(record.msg).startswith(HEARTBEAT_LOST)


class LocalWorker(WorkerPlugin):
    """Registered on the sweep's local cluster (`Client.register_plugin`); runs in each worker's event loop."""

    name = "imbench-local-worker"

    def setup(self, worker: Any) -> None:
        logger = logging.getLogger("distributed.worker")
        if _not_heartbeat_lost not in logger.filters:
            logger.addFilter(_not_heartbeat_lost)
        if threading.current_thread() is threading.main_thread():  # (signal handlers: main thread only)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
