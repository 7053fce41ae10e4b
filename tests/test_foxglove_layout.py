"""The shipped Foxglove layout (docs/foxglove/imbench.json): what `bench layout` builds, and every
plotted field exists in a run's log."""

from __future__ import annotations

import json
from pathlib import Path

from bench.daq import LogReader
from bench.operate.foxglove_layout import layout_json, paths
from bench.runtime.session import RunOptions, run

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_layout_is_the_generated_one():
    shipped = (ROOT / "docs" / "foxglove" / "imbench.json").read_text()
    assert shipped == layout_json(), "regenerate: bench layout > docs/foxglove/imbench.json"
    text = json.dumps(json.loads(shipped))
    for needle in ('"panelType": "Parameters"', '"serviceName": "/estop"', '"topicPath": "/status"',
                   '"topicPath": "/params"', '"topicPath": "/events"'):  # fmt: skip
        assert needle in text, needle


def test_every_plotted_field_is_in_a_run_log(tmp_path):
    summary, code = run(RunOptions(duration=0.2, log=tmp_path / "r.mcap", progress=False))
    assert code == 0
    log = LogReader(tmp_path / "r.mcap")
    missing = [p for p in paths() if p.rsplit(".", 1)[1] not in log.fields(p.rsplit(".", 1)[0])]
    assert not missing, missing
