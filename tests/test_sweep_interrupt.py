"""bench sweep interrupted by real signals at several moments, then resumed: every case exactly once."""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from bench.errors import BadInput
from bench.workflows.sweep import spec, table
from bench.workflows.sweep.cases import expand

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ROOT / "sweeps" / "smoke.toml"
READY = "workers ready"  # the stage line after the local cluster started, before any case is submitted
TIMEOUT = 300.0  # [s] for one sweep process


class Sweep:
    """A `bench sweep run` process whose stderr is read line by line as it comes."""

    def __init__(self, spec_file: Path, out: Path, *extra: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "bench", "sweep", "run", str(spec_file), "--out", str(out),
                                      *extra], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     start_new_session=True)  # (its own process group, as a terminal's job)  # fmt: skip
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.put(line)
        self.lines.put(None)

    def wait_for(self, cond: Callable[[str], bool]) -> str:
        """The first stderr line (from here on) that meets ``cond``."""
        while True:
            line = self.lines.get(timeout=TIMEOUT)
            assert line is not None, f"the sweep ended first: {''.join(self.seen)}"
            self.seen.append(line)
            if cond(line):
                return line

    def finish(self) -> tuple[int, dict | None, str]:
        """Exit code, the JSON it printed (None if it printed none) and its stderr."""
        assert self.proc.stdout is not None
        out = self.proc.stdout.read()  # (stderr is the reader thread's)
        self.proc.wait(timeout=TIMEOUT)
        while (line := self.lines.get(timeout=TIMEOUT)) is not None:
            self.seen.append(line)
        return self.proc.returncode, json.loads(out) if out.strip() else None, "".join(self.seen)

    def interrupt(self) -> tuple[int, str]:
        """SIGINT to the process group (a Ctrl-C at the terminal: the workers get it too); exit code and stderr."""
        os.killpg(self.proc.pid, signal.SIGINT)
        code, _, err = self.finish()
        assert "Traceback" not in err and "KeyboardInterrupt" not in err, err  # none from the workers either
        assert "nothing ran" not in err, err  # (every interrupt here comes after the sweep's first stage line)
        return code, err


def _progress(line: str) -> bool:
    """A progress line of at least one finished case (``  sweep NAME: k/N (...)``, stderr not a terminal)."""
    return line.startswith("  sweep ") and "/" in line and not line.split(": ", 1)[1].startswith("0/")


def _check_complete(out: Path, spec_file: Path) -> list[dict]:
    rows = table.read(out / table.RESULTS)
    ids = [r["case_id"] for r in rows]
    assert sorted(ids) == sorted(c.case_id for c in expand(spec.load(spec_file)))  # every case, exactly once
    assert all(r["status"] == "ok" for r in rows)
    return rows


def test_a_sweep_interrupted_before_its_first_case_resumes(tmp_path: Path) -> None:
    """Ctrl-C while the local cluster starts (it was ignored there: the sweep went on), then in the next run once the
    workers are ready, before any case finished (the issue: the empty table that left, 0 rows and 0 columns, was
    "not a bench sweep results table", exit 2): exit 130 each time, and the next run resumes and writes every case
    once."""
    import pyarrow.parquet as pq

    n = len(expand(spec.load(SMOKE)))
    out = tmp_path / "smoke"
    sw = Sweep(SMOKE, out)
    sw.wait_for(lambda line: "starting a local Dask cluster" in line)
    code, err = sw.interrupt()
    assert code == 130 and "interrupted (Ctrl-C)" in err and READY not in err, err
    assert not (out / table.RESULTS).exists()  # nothing ran

    sw = Sweep(SMOKE, out)
    sw.wait_for(lambda line: READY in line)
    time.sleep(0.5)  # the cases are submitted; the first results take seconds (each worker imports first)
    code, err = sw.interrupt()
    assert code == 130 and "interrupted (Ctrl-C)" in err, err
    left = table.read(out / table.RESULTS)
    assert len(left) < n
    assert {"case_id", "status"} <= set(pq.read_schema(out / table.RESULTS).names)

    code, result, err = Sweep(SMOKE, out, "--no-progress").finish()
    assert code == 0, err
    assert result is not None and (result["skipped"], result["ran"], result["error"]) == (len(left), n - len(left), 0)
    _check_complete(out, SMOKE)


def test_a_sweep_interrupted_mid_run_twice_resumes_with_every_case_once(tmp_path: Path) -> None:
    """SIGINT after the first cases finished, again in the resumed run, then a last run: every case once, and the
    cases finished before an interrupt are kept as they were (not run again)."""
    spec_file = tmp_path / "slow.toml"  # the smoke sweep x 3 seeds, one case per task: cases finish one by one
    spec_file.write_text(SMOKE.read_text().replace("seeds = [1]", "seeds = [1, 2, 3]"))
    n = len(expand(spec.load(spec_file)))
    out = tmp_path / "slow"
    kept: dict[str, dict] = {}
    for attempt in range(2):
        sw = Sweep(spec_file, out, "--batch", "0")
        sw.wait_for(_progress)
        code, err = sw.interrupt()
        assert code == 130, err
        rows = table.read(out / table.RESULTS)
        assert len(kept) < len(rows) < n, (attempt, len(rows))  # more done, not all: interrupted mid-run
        by_id = {r["case_id"]: r for r in rows}
        assert len(by_id) == len(rows)
        for cid, r in kept.items():  # not run again
            assert (by_id[cid]["worker"], by_id[cid]["case_wall_time"]) == (r["worker"], r["case_wall_time"])
        kept = by_id
    code, result, err = Sweep(spec_file, out, "--batch", "0", "--no-progress").finish()
    assert code == 0, err
    assert result is not None and (result["skipped"], result["ran"]) == (len(kept), n - len(kept))
    rows = {r["case_id"]: r for r in _check_complete(out, spec_file)}
    assert all(rows[cid]["case_wall_time"] == r["case_wall_time"] for cid, r in kept.items())


def _sweep_folder(out: Path) -> None:
    out.mkdir()
    (out / table.SWEEP_JSON).write_text(json.dumps({"name": "smoke", "description": "", "cases": 12}))


def test_an_empty_table_in_a_sweeps_folder_holds_no_cases(tmp_path: Path) -> None:
    """What an interrupted sweep left before this version (a table of no rows and no columns), or an empty file, in a
    folder a sweep wrote (its sweep.json): no case done yet. The same without sweep.json is refused."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for name, make in (("legacy", lambda p: pq.write_table(pa.Table.from_pylist([]), p)),
                       ("empty", lambda p: p.write_bytes(b""))):  # fmt: skip
        out = tmp_path / name
        _sweep_folder(out)
        make(out / table.RESULTS)
        assert table.read(out / table.RESULTS) == []
        (out / table.SWEEP_JSON).unlink()
        with pytest.raises(BadInput):
            table.read(out / table.RESULTS)


@pytest.mark.parametrize("what", ["garbage", "foreign", "torn", "no-columns-elsewhere"])
def test_a_file_the_sweep_did_not_write_is_refused_in_one_line(tmp_path: Path, what: str) -> None:
    """results.parquet that is not a sweep's table (garbage bytes, another table, the head of a table, a table of no
    columns in a folder no sweep wrote): exit 2, one line naming the file, the file untouched."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = tmp_path / "out"
    if what == "no-columns-elsewhere":
        out.mkdir()
    else:
        _sweep_folder(out)
    path = out / table.RESULTS
    if what == "garbage":
        path.write_bytes(b"\x00not parquet\xff" * 10)
    elif what == "foreign":
        pq.write_table(pa.table({"a": [1, 2], "b": ["x", "y"]}), path)
    elif what == "torn":
        table.write(path, [{"case_id": "c", "index": 0, "status": "ok"}])
        path.write_bytes(path.read_bytes()[:-20])
    else:
        pq.write_table(pa.Table.from_pylist([]), path)
    before = path.read_bytes()
    p = subprocess.run([sys.executable, "-m", "bench", "sweep", "run", str(SMOKE), "--out", str(out), "--no-progress"],
                       cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT)  # fmt: skip
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"bench: error: {path}: not a"), p.stderr
    assert path.read_bytes() == before


def test_a_signal_during_a_table_write_leaves_the_previous_table(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGINT while the table is half written: the previous table stays whole and no temporary file is left."""
    import pyarrow.parquet as pq

    path = tmp_path / table.RESULTS
    table.write(path, [{"case_id": "a", "index": 0, "status": "ok"}])
    before = path.read_bytes()
    real = pq.write_table

    def interrupted(tbl, where, **kw):  # half a file, then a real SIGINT (Python's handler: KeyboardInterrupt)
        real(tbl, where, **kw)
        Path(where).write_bytes(Path(where).read_bytes()[:40])
        signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(pq, "write_table", interrupted)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            table.write(path, [{"case_id": c, "index": i, "status": "ok"} for i, c in enumerate("ab")])
    finally:
        signal.signal(signal.SIGINT, old)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [table.RESULTS]
