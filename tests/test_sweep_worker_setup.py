"""The sweep's local workers drop Dask's heartbeat-lost record (the scheduler closing first) and nothing else."""

from __future__ import annotations

import logging
import signal
import types

import pytest

from bench.workflows.sweep import worker_setup


def test_the_heartbeat_lost_record_is_dropped_and_others_go_through(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("distributed.worker")
    old_sigint = signal.getsignal(signal.SIGINT)
    try:
        worker_setup.LocalWorker().setup(types.SimpleNamespace())
        worker_setup.LocalWorker().setup(types.SimpleNamespace())  # (a restarted plugin adds no second filter)
        assert logger.filters.count(worker_setup._not_heartbeat_lost) == 1
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        with caplog.at_level(logging.INFO, logger="distributed.worker"):
            try:
                raise OSError("Stream is closed")
            except OSError:
                logger.exception("Failed to communicate with scheduler during heartbeat.")
                logger.exception("Unexpected exception during heartbeat. Closing worker.")
            logger.error("a task failed")
        seen = [r.getMessage() for r in caplog.records if r.name == "distributed.worker"]
        assert seen == ["Unexpected exception during heartbeat. Closing worker.", "a task failed"]
    finally:
        logger.removeFilter(worker_setup._not_heartbeat_lost)
        signal.signal(signal.SIGINT, old_sigint)
