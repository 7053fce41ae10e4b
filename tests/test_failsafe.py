"""Fail-safe at the rig (issue 10): every way a run ends reaches the safe state, the log and a summary.

The fault matrix (harness/fault_matrix.py) runs real `bench` processes and does real things to them:
signals at several moments, SIGKILL/SIGSTOP of the log writer, SIGKILL of the emulator, a third
party stopping the drive over Modbus, a driver exception, a stalled tick, lockstep on a real rig.
"""

from __future__ import annotations

import json
import os
import pty
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from harness import fault_matrix
from bench.daq import LogReader, LogWriter, Topic
from bench.daq.live_control import MAX_BODY
from bench.core.encoder import EncoderSpeed
from bench.errors import BadInput

ROOT = Path(__file__).resolve().parents[1]
CASES = list(fault_matrix.cases())


@pytest.mark.parametrize("case", CASES)
@pytest.mark.realtime
def test_fault_matrix(case, tmp_path):
    if case.startswith("disk-full") and os.geteuid() != 0:
        pytest.skip("mounting the 2 MB tmpfs of a full disk needs root")
    (o,) = fault_matrix.run([case], tmp_path, progress=False)
    assert o.exit_code == o.expected_exit, (o.cause, o.notes)
    assert o.safe_within_one_tick is not False, o
    assert o.log_intact is not False, o
    assert o.summary_written is not False, o
    assert o.leftover_processes == 0, o
    assert o.ok
    if o.expected_exit == 0:
        assert o.cause is None
    elif o.expected_exit != 2:
        assert o.cause, o
    expected_cause = {"sigint": "interrupted (Ctrl-C)", "sigterm": "interrupted (SIGTERM)",
                      "sighup": "interrupted (SIGHUP", "sigint-twice": "interrupted (Ctrl-C)",
                      "sigterm-then-sigint": "interrupted (SIGTERM)", "writer-killed": "log writer died",
                      "writer-stalled": "log writer stalled", "driver-exception": "rig read failed: OSError",
                      "loop-stall": "loop stall", "drive-stopped": "inverter state: commanded enabled",
                      "stall-past-ride-through": "inverter fault reported: set-point watchdog; 0.0 ms after a ",
                      "over-speed": "over-speed", "sigint-at-start": "interrupted (Ctrl-C)",
                      "ctrl-c-terminal": "interrupted (Ctrl-C)", "terminal-closed": "interrupted (SIGHUP",
                      "ctrl-z": "interrupted (Ctrl-Z", "ctrl-z-terminal": "interrupted (Ctrl-Z",
                      "ctrl-z-terminal-emulated": "interrupted (Ctrl-Z",
                      "ctrl-backslash-terminal": "interrupted (SIGQUIT)",
                      "disk-full": "log writer died (OSError: [Errno 28] No space left on device)",
                      "disk-full-at-start": "start-up failed: LogWriterError: writer process for ",
                      "estop-under-flood": "operator e-stop",
                      "request-channel-broken": "live request channel broken"}  # fmt: skip
    if case in expected_cause:
        assert o.cause.startswith(expected_cause[case]), o.cause
    if case == "sigint-during-summary":  # the summary and the plot still came, and say so
        s = json.loads((tmp_path / case / "run.summary.json").read_text())
        assert any("during the shutdown" in w for w in s["warnings"]) and (tmp_path / case / "run.png").exists()
    if o.max_shutdown_s is not None:  # keys typed at a pty: the run ended promptly, not one row lost
        assert o.shutdown_s is not None and o.shutdown_s <= o.max_shutdown_s, o
        s = json.loads((tmp_path / case / "run.summary.json").read_text())
        assert s["log_writer"]["dropped"] == 0 and s["log_writer"]["rows_written"] == s["ticks"], s["log_writer"]
    if case == "host-killed":  # nothing on the PC could act: the drive's own timeout did
        assert o.safe_within_one_tick is True, o.notes
    if case == "disk-full":  # the room set aside at the start kept summary.json on the disk the log filled
        assert not any("on stderr" in n for n in o.notes), o.notes
    if case == "normal-end":  # no temporary or reserved file left beside the outputs
        assert not list((tmp_path / case).glob(".*"))
    if case == "writer-killed":  # what is reported lost is what the file lacks
        s = json.loads((tmp_path / case / "run.summary.json").read_text())
        (rig,) = LogReader(tmp_path / case / "run.mcap").read_ticks("/rig")
        assert s["log_writer"]["rows_written"] == len(rig["tick"]) < s["ticks"]
        assert s["log_writer"]["dropped"] == s["ticks"] - len(rig["tick"]), s["log_writer"]
    if case in ("estop-under-flood", "stop-under-flood"):  # through the floods, at once, and the run ended by it
        d = o.details
        assert d["response"]["ok"] and d["response"]["status"] == "applied", o.notes
        assert d["latency_ms"] < 250, o.notes  # from the call to the tick it was applied at (measured: 0.6-7 ms)
        assert d["ended_after_s"] < 30, o.notes
        assert d["flood_sent"]["set"] >= 500 and d["flood_sent"]["mark"] >= 20, o.notes  # the floods really ran
        s = json.loads(next(tmp_path.glob(f"{case}/**/run.summary.json")).read_text())
        served = s["operator"]["server"]
        assert served["rate_limited"] >= 300, served  # the flood of sets: most of it stopped by the rate limit
        log = next(tmp_path.glob(f"{case}/**/run.mcap"))
        marks = [e for e in LogReader(log).events() if e["kind"] == "mark"]  # the notes past the rate limit
        assert marks and all(f"at most {MAX_BODY} bytes" in e["status"] for e in marks), marks[:3]  # not even parsed
        if case == "estop-under-flood":  # the safe command from the very tick the e-stop was applied at
            rig, = LogReader(log).read_ticks("/rig")
            k = int(np.flatnonzero(rig["tripped"])[0])
            assert int(rig["tick"][k]) == d["response"]["tick"], (rig["tick"][k], o.notes)
        else:
            assert s["operator"]["ended_by"] == "operator stop" and s["duration"] < 20, s["operator"]
    if case in ("writer-paused", "writer-stalled"):  # the writer came back: not one row lost
        s = json.loads((tmp_path / case / "run.summary.json").read_text())
        assert s["log_writer"]["dropped"] == 0 and s["log_writer"]["rows_written"] == s["ticks"]


def _spawn(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "bench", *args], cwd=kw.pop("cwd", ROOT), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)  # fmt: skip


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.3, 0.5, 0.7])
def test_ctrl_c_while_starting_leaves_quietly(tmp_path, delay):
    """Ctrl-C at moments of bench's start-up, counted from the first moment bench's code holds the signals: the
    package imported (``-X importtime`` reports it on stderr). Before it the interpreter is starting and runpy
    locating the module: a signal there is Python's, not ours, and on a loaded machine a fixed delay from the
    spawn can land there."""
    p = subprocess.Popen([sys.executable, "-X", "importtime", "-m", "bench", "run", "--realtime", "--duration", "20",
                          "--no-progress", "--log", str(tmp_path / "x.mcap")], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    assert p.stderr is not None
    seen = []
    while not (seen and seen[-1].rstrip().endswith("| bench")):
        seen.append(p.stderr.readline())
        assert seen[-1], "".join(seen)  # the interpreter ended before its own start-up was over
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    err = "".join(ln for ln in err.splitlines(keepends=True) if not ln.startswith("import time:"))
    assert p.returncode == 130, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    if (tmp_path / "x.summary.json").exists():  # the session had started: it ended through the shutdown path
        assert json.loads((tmp_path / "x.summary.json").read_text())["exit_code"] == 130
    else:
        assert not any(tmp_path.iterdir()) and "nothing ran" in err, err


def _bench(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=cwd, timeout=120)


def _one_line_exit_2(p: subprocess.CompletedProcess, *words: str) -> str:
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench: error:"), p.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def test_existing_outputs_are_not_overwritten_without_force(tmp_path):
    log = tmp_path / "a.mcap"
    log.write_bytes(b"keep me")
    p = _bench("run", "--duration", "0.2", "--no-progress", "--log", str(log))
    _one_line_exit_2(p, "--log", "exists", "--force")
    assert log.read_bytes() == b"keep me"
    assert not (tmp_path / "a.summary.json").exists()
    summary = tmp_path / "s.json"
    summary.write_text("{}")
    p = _bench("run", "--duration", "0.2", "--no-progress", "--log", str(tmp_path / "b.mcap"), "--summary", str(summary))
    _one_line_exit_2(p, "--summary", "exists")
    assert not (tmp_path / "b.mcap").exists()  # refused before the run: nothing written
    p = _bench("run", "--duration", "0.2", "--no-progress", "--log", str(log), "--force")
    assert p.returncode == 0, p.stderr
    assert LogReader(log).summary()["topics"]["/rig"]["messages"] == 600


def test_unwritable_output_paths_are_refused_before_the_run(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    for opt in ("--log", "--summary", "--plot"):
        args = ["run", "--duration", "0.2", "--no-progress", opt, str(blocker / "x.out")]
        if opt != "--log":
            args += ["--log", str(tmp_path / f"ok{opt}.mcap")]
        t0 = time.monotonic()
        _one_line_exit_2(_bench(*args), opt, "cannot write")
        assert time.monotonic() - t0 < 30
    _one_line_exit_2(_bench("run", "--no-progress", "--log", str(tmp_path)), "--log")  # a directory
    assert not list(tmp_path.glob("ok*"))


def test_two_runs_in_the_same_second_get_their_own_folders(tmp_path):
    procs = [_spawn("run", "--duration", "0.2", "--no-progress", "--out", str(tmp_path), "-p", f"speed_Kp={kp}")
             for kp in (0.5, 0.6)]  # fmt: skip
    outs = [json.loads(p.communicate(timeout=120)[0]) for p in procs]
    assert outs[0]["log"] != outs[1]["log"]
    kps = sorted(json.loads(Path(o["summary"]).read_text())["controller_params"]["speed_Kp"] for o in outs)
    assert kps == [0.5, 0.6]


@pytest.mark.parametrize("duration", ["1e-9", "0", "inf", "nan", "7200"])
def test_duration_out_of_range(duration):
    _one_line_exit_2(_bench("run", "--duration", duration, "--no-progress"), "duration")


def test_stdout_stays_json_when_stderr_is_a_terminal(tmp_path):
    """The progress bar goes to stderr: `bench run > s.json` in a terminal gives clean JSON."""
    master, slave = pty.openpty()
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--duration", "1", "--out", str(tmp_path)],
                         cwd=ROOT, stdout=subprocess.PIPE, stderr=slave, text=True)  # fmt: skip
    os.close(slave)
    out, _ = p.communicate(timeout=120)
    drawn = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:
            break
        if not chunk:
            break
        drawn += chunk
    os.close(master)
    assert p.returncode == 0
    assert json.loads(out)["ticks"] == 3000
    assert b"bench run" in drawn  # the bar was drawn, on the terminal


def _foreign_mcap(path: Path) -> None:
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/other", "json", sid)
        w.add_message(cid, 0, b'{"a": 1}', 0)
        w.finish()


def test_readers_refuse_junk_with_one_line(tmp_path):
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "random.mcap").write_bytes(np.random.default_rng(0).bytes(4096))
    (tmp_path / "text.mcap").write_text("hello")
    _foreign_mcap(tmp_path / "foreign.mcap")
    for name, why in (("empty", "not an MCAP log"), ("random", "not an MCAP log"), ("text", "not an MCAP log"),
                      ("foreign", "not an imbench run log")):  # fmt: skip
        f = str(tmp_path / f"{name}.mcap")
        _one_line_exit_2(_bench("plot", f, "--out", str(tmp_path / f"{name}.png")), name, why)
        if name != "foreign":  # inspect shows any MCAP file's topics and metadata
            _one_line_exit_2(_bench("inspect", f), name, why)
    assert _bench("inspect", str(tmp_path / "foreign.mcap")).returncode == 0


def test_torn_logs_read_and_plot_up_to_the_tear(tmp_path):
    log = tmp_path / "run.mcap"
    assert _bench("run", "--duration", "1.5", "--no-progress", "--log", str(log)).returncode == 0
    data = log.read_bytes()
    for frac in (0.3, 0.6, 0.9):
        torn = tmp_path / f"torn{frac}.mcap"
        torn.write_bytes(data[: int(len(data) * frac)])
        r = LogReader(torn)
        rig, ctrl = r.read_ticks("/rig", "/ctrl")
        assert len(rig["t"]) == len(ctrl["omega_hat"]) > 0
        assert np.all(np.diff(rig["tick"]) == 1)
        p = _bench("plot", str(torn), "--out", str(tmp_path / f"torn{frac}.png"))
        assert p.returncode == 0, p.stderr
    p = _bench("plot", str(log), "--out", str(tmp_path / "torn0.3.png"))  # exists: not overwritten silently
    _one_line_exit_2(p, "--out", "exists")


def test_encoder_speed_uses_the_real_elapsed_time():
    """A 3 ms stall (9 skipped ticks) at 100 rad/s must not read as a speed jump (it did: 184 rad/s)."""
    T, cpr, Z_p = 1 / 3000, 4096, 2
    enc = EncoderSpeed(cpr, 1 << 16, Z_p, T, tau=0.002)
    w_mech = 100.0 / Z_p
    t, worst = 0.0, 0.0
    for k in range(3000):
        t = k * T if k < 1500 else (k + 9) * T  # ticks 1500..1508 skipped
        count = int(w_mech * t * cpr / (2 * np.pi)) % (1 << 16)
        w = enc.update(count, t)
        if k > 300:
            worst = max(worst, abs(w - 100.0))
    assert worst < 5.0  # quantisation: one count per tick is 4.6 rad/s


def test_log_writer_in_real_time_faults_instead_of_waiting(tmp_path):
    """max_wait=0: a stopped writer makes put() declare a fault at once, never block; the reserve takes the trip
    rows."""
    faults: list[str] = []
    topics = [Topic("/x", "t/X", [("v", "float64")])]
    w = LogWriter(tmp_path / "x.mcap", topics, batch_ticks=16, ring_ticks=256, reserve_ticks=64, max_wait=0.0,
                  on_fault=faults.append, timing=False)  # fmt: skip
    os.kill(w.writer_pid, signal.SIGSTOP)
    from bench.daq.diagnose import proc_state

    for _ in range(10_000):  # a signal takes effect once the process is scheduled
        if proc_state(w.writer_pid) == "T":
            break
        time.sleep(0.001)
    try:
        worst = 0.0
        for k in range(400):
            t0 = time.perf_counter()
            w.put(k, (float(k),))
            worst = max(worst, time.perf_counter() - t0)
            if faults and k > 300:
                break
        assert faults and faults[0].startswith("log writer stalled: its ring (") and "is full" in faults[0]
        assert "the writer process is stopped" in faults[0]  # the cause, not a slow disk or a busy machine
        assert worst < 0.05  # never waited for the stopped writer
    finally:
        os.kill(w.writer_pid, signal.SIGCONT)
    try:
        w.close()
    except Exception:  # rows beyond the reserve were dropped: close says so
        pass
    rows = LogReader(tmp_path / "x.mcap").read("/x")["v"]
    assert len(rows) >= 256 - 16 and np.all(np.diff(rows) == 1)  # everything up to and into the reserve


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs a CPU for the loop and one for the writer")
def test_log_writer_starved_of_cpu_trips_naming_the_cause(tmp_path):
    """A real-time log (max_wait=0, a 0.3 s ring at 3 kHz) whose writer gets almost no CPU -- the writer pinned to
    one CPU at SCHED_IDLE beside a busy process, the loop on another -- trips with a message that says the writer
    was CPU-starved and the machine overloaded (not the disk); the file keeps every row put, up to the fault and
    into the reserve."""
    faults: list[str] = []
    topics = [Topic("/x", "t/X", [("v", "float64")] + [(f"a{i}", "float64") for i in range(40)])]
    w = LogWriter(tmp_path / "x.mcap", topics, batch_ticks=64, ring_ticks=900 + 256, reserve_ticks=256, max_wait=0.0,
                  on_fault=faults.append, timing=False)  # fmt: skip
    mine = os.sched_getaffinity(0)
    cpus = sorted(mine)
    hog = subprocess.Popen([sys.executable, "-c", f"import os\nos.sched_setaffinity(0, {{{cpus[0]}}})\nwhile True: pass"])
    k = 0
    try:
        os.sched_setaffinity(0, {cpus[-1]})
        os.sched_setaffinity(w.writer_pid, {cpus[0]})
        os.sched_setscheduler(w.writer_pid, os.SCHED_IDLE, os.sched_param(0))
        t0, rest = time.perf_counter(), (0.0,) * 40
        while not faults and k < 3000 * 60:  # paced at 3 kHz, as a real-time loop puts
            while time.perf_counter() < t0 + k / 3000:
                pass
            w.put(k * 333_333, (float(k), *rest))
            k += 1
        for j in range(100):  # the trip's rows: into the reserve
            w.put((k + j) * 333_333, (float(k + j), *rest))
    finally:
        hog.kill()
        hog.wait()
        os.sched_setaffinity(0, mine)
        os.sched_setscheduler(w.writer_pid, os.SCHED_OTHER, os.sched_param(0))
    assert faults, "the starved writer kept up"
    assert faults[0].startswith("log writer stalled: its ring (0.3 s, 960 rows) is full: "), faults[0]
    assert "CPU-starved" in faults[0] and "the machine is overloaded" in faults[0] and "disk" not in faults[0]
    w.close()
    v = LogReader(tmp_path / "x.mcap").read("/x")["v"]
    np.testing.assert_array_equal(v, np.arange(k + 100))  # nothing lost, in order


def test_stall_cause_names_disk_cpu_and_cost(monkeypatch):
    """The diagnosis from the writer's samples and its state now: a writer that spent its time in file writes is
    I/O bound (the disk), one that got its CPU and still fell behind logs too much, one that got none was starved."""
    from bench.daq import diagnose

    idx = [0] * diagnose.SLOTS_END
    now = time.monotonic_ns()

    def cause(cpu_s: float, io_s: float, state: str, wait_s: float = 0.0) -> str:
        idx[diagnose.REF : diagnose.REF + 4] = [now - 5_000_000_000, 0, 0, 0]
        idx[diagnose.NEW : diagnose.NEW + 4] = [now, int(cpu_s * 1e9), 0, int(io_s * 1e9)]
        monkeypatch.setattr(diagnose, "schedstat", lambda path: (int(cpu_s * 1e9), int(wait_s * 1e9)))
        monkeypatch.setattr(diagnose, "proc_state", lambda pid: state)
        return diagnose.stall_cause(idx, 1234)

    assert "the disk is too slow" in cause(0.3, 4.0, "S")
    assert "the disk is too slow" in cause(0.1, 0.2, "D")
    assert "CPU-starved" in cause(0.05, 0.0, "R") and "overloaded" in cause(0.05, 0.0, "R")
    assert "waited 3.0 s for one" in cause(1.0, 0.0, "S", wait_s=3.0)
    assert "logging needs more CPU" in cause(4.5, 0.1, "R")
    assert "stopped" in cause(0.0, 0.0, "T")


def test_real_rig_without_realtime_scheduling_is_refused(monkeypatch):
    import bench.runtime.session as session

    monkeypatch.setattr(session, "realtime_setup", lambda: {"affinity": None, "sched_fifo": False})
    with pytest.raises(BadInput, match="--allow-soft-realtime"):
        session.prepare(session.RunOptions(rig=str(ROOT / "rigs" / "lab-example.toml"), realtime=True))
    plan = session.prepare(session.RunOptions(rig=str(ROOT / "rigs" / "lab-example.toml"), allow_soft_realtime=True))
    assert plan.realtime  # a real rig runs in real time without being asked
    with pytest.raises(BadInput, match="--lockstep"):
        session.prepare(session.RunOptions(rig=str(ROOT / "rigs" / "lab-example.toml"), realtime=False))
    assert not session.prepare(session.RunOptions(rig="emulated")).realtime  # emulators may run lockstep


def test_unreachable_real_rig_is_one_line_and_leaves_nothing_running(tmp_path):
    """The lab template's devices (can0, a serial port) are absent here: refused at start-up, field named."""
    log = tmp_path / "lab.mcap"
    p = _bench("run", "--rig", str(ROOT / "rigs" / "lab-example.toml"), "--no-progress", "--log", str(log),
               "--allow-soft-realtime")  # fmt: skip
    _one_line_exit_2(p, "cannot connect")
    assert not log.exists()  # the devices are opened before the log: nothing was written


def test_collect_narx_does_not_overwrite_its_data_set(tmp_path):
    out = tmp_path / "train.mcap"
    out.write_bytes(b"an earlier data set")
    _one_line_exit_2(_bench("collect", "narx", "--out", str(out), "--samples", "200", "--no-progress"), "exists")
    assert out.read_bytes() == b"an earlier data set"


def test_a_failing_writer_names_its_error_in_the_fault(tmp_path):
    faults: list[str] = []
    w = LogWriter(tmp_path / "x.mcap", [Topic("/x", "t/X", [("v", "float64")])], batch_ticks=4, max_wait=0.0,
                  on_fault=faults.append)  # fmt: skip
    w._control(b"bogus")  # the writer process fails on it (as it would on a full disk)
    deadline = time.monotonic() + 20
    k = 0
    while not faults and time.monotonic() < deadline:
        w.put(k, (float(k),))
        k += 1
        time.sleep(0.001)
    assert faults == ["log writer died (ValueError: unknown control frame b'bogus')"]


def test_reproduce_writes_under_runs_lists_naturally_and_keeps_earlier_results(tmp_path):
    listing = _bench("reproduce", cwd=tmp_path).stdout.split()
    names = [w for w in listing if w.startswith("fig4.")]
    assert names.index("fig4.6") < names.index("fig4.10")
    p = _bench("reproduce", "fig4.6", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "runs" / "reproduce" / "fig4.6.png").exists() and "wrote" in p.stderr
    _one_line_exit_2(_bench("reproduce", "fig4.6", cwd=tmp_path), "--out", "exists", "--force")
    assert _bench("reproduce", "fig4.6", "--force", cwd=tmp_path).returncode == 0


def test_a_killed_writer_is_reported_dead_at_once_and_its_loss_counted(tmp_path):
    """SIGKILL of the writer, then close(): "failed" with the exit code within seconds (not "did not finish
    within 30 s"), and `dropped` = rows put - rows the file holds (the open chunk is lost too)."""
    from bench.daq import LogWriterError

    topics = [Topic("/x", "t/X", [("v", "float64")])]
    w = LogWriter(tmp_path / "x.mcap", topics, batch_ticks=16, close_timeout=30.0, timing=False)
    for k in range(5000):
        w.put(k, (float(k),))
    w.flush(chunk=True)  # one complete chunk on disk ...
    deadline = time.monotonic() + 20
    while w.stats()["chunk_flushes"] < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    for k in range(5000, 8000):  # ... and rows in the open chunk, lost with the writer
        w.put(k, (float(k),))
    w.flush()
    time.sleep(0.3)
    os.kill(w.writer_pid, signal.SIGKILL)
    t0 = time.monotonic()
    with pytest.raises(LogWriterError, match="failed") as err:
        w.close()
    assert time.monotonic() - t0 < 10 and "did not finish" not in str(err.value)
    in_file = len(LogReader(tmp_path / "x.mcap").read("/x")["v"])
    st = w.stats()
    assert 5000 <= in_file < 8000
    assert st["rows_written"] == in_file and st["dropped"] == 8000 - in_file


def test_an_output_file_is_written_whole_or_not_at_all(tmp_path):
    """bench.core.outputs.replacing: a write that fails (a full disk, an exception) leaves the old file and no temp."""
    from bench.core.outputs import replacing, write_text

    target = tmp_path / "summary.json"
    write_text(target, "old")
    with pytest.raises(OSError):
        with replacing(target) as tmp:
            tmp.write_text("half")
            raise OSError(28, "No space left on device")
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["summary.json"]
    write_text(target, "new")
    assert target.read_text() == "new" and len(list(tmp_path.iterdir())) == 1
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask  # an ordinary new file, not mkstemp's 0600
    from bench.core.outputs import free_room, reserve_room

    spare = reserve_room(target, 64 * 1024)
    assert spare is not None and spare.name.startswith(".") and spare.stat().st_blocks * 512 >= 64 * 1024
    free_room(spare)
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_what_a_run_wrote_is_said_as_it_is():
    from bench.core.outputs import written_note

    assert written_note({"log": "a", "summary": "b", "plot": "c"}) == "log, summary, plot written"
    note = written_note({"log": "a", "log_writer": {"dropped": 17}, "summary": None, "plot": None})
    assert note == "log (17 rows lost) written; summary, plot NOT written"
    assert written_note({"log": None, "summary": None, "plot": None}) == "log, summary, plot NOT written"


def test_a_summary_that_cannot_be_written_is_printed_in_full(tmp_path, monkeypatch, capsys):
    """No root needed: every summary.json write fails (ENOSPC). The run still has its summary (returned, and
    printed in full on stderr by bench run), the plot is written, and no temporary file is left."""
    import errno

    import bench.runtime.run_summary as run_summary
    from bench.cli import _report_end
    from bench.runtime.session import RunOptions, run

    def full(path, text):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(run_summary, "write_text", full)  # the summary's writer, as run_summary imported it
    summary, code = run(RunOptions(log=tmp_path / "r.mcap", duration=0.2, progress=False))
    assert code == 0 and summary["summary"] is None and summary["ticks"] == 600
    assert summary["plot"] == str(tmp_path / "r.png") and (tmp_path / "r.png").stat().st_size > 10_000
    assert any("summary not written: No space left on device" in w for w in summary["warnings"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mcap", "r.png"]  # no temporary or reserved file
    _report_end({**summary, "trip_cause": "over-speed", "trip_time": 0.1}, 1, ("ticks",))
    err = capsys.readouterr().err
    shown, _ = json.JSONDecoder().raw_decode(err.split("(its file could not be written):\n", 1)[1])
    assert shown["ticks"] == 600 and shown["speed_error"] == summary["speed_error"]
    assert "(rig safe; log, plot written; summary NOT written)" in err


def test_an_interrupt_swallowed_by_a_c_callback_is_not_reported():
    """A start-up Ctrl-C whose `Interrupted` lands in a ctypes callback (numba's object-cache notify) is recorded by
    the guard and acted on when the run starts; the interpreter's "Exception ignored" report of it is dropped,
    any other unraisable exception still reported (a real ctypes callback raising, in a subprocess)."""
    code = (
        "import ctypes, sys\n"
        "from bench.core.shutdown import COMMAND_SIGNALS, Interrupted, SignalGuard\n"
        "with SignalGuard(COMMAND_SIGNALS):\n"
        "    for exc in (Interrupted(2), ValueError('other')):\n"
        "        def cb(x, exc=exc):\n"
        "            raise exc\n"
        "        ctypes.CFUNCTYPE(None, ctypes.c_int)(cb)(1)\n"
        "print('done')\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert p.returncode == 0 and p.stdout.strip() == "done", p.stderr
    assert "Interrupted" not in p.stderr and "ValueError: other" in p.stderr, p.stderr
