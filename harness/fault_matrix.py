"""The fault matrix: every way a run can end, tried on real processes with real signals.

Each case starts ``python -m bench ...`` (or a short script around `bench.runtime.session.run` where a
fault has to be planted in the process) as a subprocess, does something to it at a bad moment
(a signal, Ctrl-Z or Ctrl-\\ typed at its terminal (a pty, `_TerminalProc`), SIGKILL/SIGSTOP of its
log writer, SIGKILL of the emulator, a third party stopping the drive over Modbus, an exception in a
driver, a stalled tick, a disk that fills up), and checks the same four things:

* **exit code** as documented (0 ok, 1 tripped, 2 bad input, 128 + signal);
* **safe within one tick**: the first logged row with ``tripped`` already carries the safe command
  (inverter disabled, zero reference, load 0) and so does every row after it;
* **log intact**: the MCAP file reads, ticks rise, and every tick of the summary is in it (a
  killed writer: every complete chunk, to the fault);
* **summary written** with the trip cause and the exit code (a full disk: on the disk, or in full on
  stderr, whose last line says what was and was not written, and no empty file left).

A case at a terminal also bounds the time from the key to the exit (``shutdown_s``).

``python3 -m harness.fault_matrix [--out DIR] [CASE ...]`` prints the table as JSON (docs/RESULTS.md);
tests/test_failsafe.py runs the same cases and asserts each row.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.core.config import load as load_rig_cfg, load as load_rig
from bench.errors import BadInput
from bench.operate.live_client import call, set_params
from bench.wire.fc_profile import STW_RUNNING, STW_TRIP
from bench.daq import LogReader
from bench.daq.reader import is_finished
from mock_hw.emulators.testing import emulated_data, write_rig

ROOT = Path(__file__).resolve().parents[1]
RIGS = ROOT / "rigs"
_MARK = "IMBENCH_FAULT_MATRIX"  # env marker: finds processes a case left behind


@dataclass
class Outcome:
    case: str
    fault: str
    expected_exit: int
    exit_code: int | None = None
    cause: str | None = None
    safe_within_one_tick: bool | None = None  # None: not applicable (no row after the fault can be logged)
    log_intact: bool | None = None
    summary_written: bool | None = None
    leftover_processes: int = 0
    seconds: float = 0.0
    shutdown_s: float | None = None  # from the fault to the exit, where a case bounds it (terminal keys)
    max_shutdown_s: float | None = None
    notes: list[str] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)  # case-specific measurements

    @property
    def ok(self) -> bool:
        prompt = self.shutdown_s is None or self.max_shutdown_s is None or self.shutdown_s <= self.max_shutdown_s
        return (self.exit_code == self.expected_exit and self.safe_within_one_tick is not False
                and self.log_intact is not False and self.summary_written is not False
                and self.leftover_processes == 0 and prompt)  # fmt: skip



def writer_pid(pid: int, timeout: float = 10.0) -> int:
    """The log-writer child (multiprocessing spawn) of process ``pid``, once it runs (Linux /proc)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            kids = open(f"/proc/{pid}/task/{pid}/children").read().split()
        except FileNotFoundError:
            break
        for kid in kids:
            try:
                if "spawn_main" in open(f"/proc/{kid}/cmdline").read():
                    return int(kid)
            except FileNotFoundError:
                continue
        time.sleep(0.02)
    raise RuntimeError("no log writer process found")

class _Proc:
    """One subprocess of the bench, in its own process group, with a marker in its environment."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.mark = uuid.uuid4().hex
        env = {**os.environ, _MARK: self.mark, "PYTHONUNBUFFERED": "1"}
        self.p = subprocess.Popen([sys.executable, *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
        self.t0 = time.monotonic()

    def writer_pid(self, timeout: float = 10.0) -> int:
        """The log-writer child (multiprocessing spawn), once it runs."""
        return writer_pid(self.p.pid, timeout)

    def wait(self, timeout: float = 120.0) -> tuple[int, str, str]:
        out, err = self.p.communicate(timeout=timeout)
        return self.p.returncode, out, err

    def kill_all(self) -> None:
        """SIGKILL every process of this case (stopped ones too)."""
        for pid in self._marked():
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)

    def _marked(self) -> list[int]:
        pids = []
        for d in Path("/proc").iterdir():
            if d.name.isdigit():
                try:
                    if f"{_MARK}={self.mark}".encode() in (d / "environ").read_bytes():
                        pids.append(int(d.name))
                except OSError:
                    continue
        return pids

    def leftovers(self) -> int:
        """Processes still alive that carry this case's marker (an orphaned writer, a hung child)."""
        return len(self._marked())


# A job-control shell in miniature: the session leader, it runs the command in a process group of its own and
# makes that group the terminal's foreground one, as bash does. This matters: with the bench itself as the session
# leader its group would be orphaned (no parent in the session outside it), and the kernel discards Ctrl-Z
# (SIGTSTP) for orphaned groups, so a child that a real shell's Ctrl-Z stops would run on. Like bash, the job gets
# the default dispositions (a harness started in the background may ignore SIGINT and SIGQUIT, and ignored
# signals are inherited), and the shell ignores the keys itself. A job that stops is reported ("[job stopped]")
# and killed; the exit status is a shell's.
_STOPPED = "[job stopped]"
_SHELL = f"""
import os, signal, subprocess, sys
KEYS = (signal.SIGINT, signal.SIGQUIT, signal.SIGTSTP, signal.SIGTTIN, signal.SIGTTOU)
def job_defaults():
    for s in KEYS:
        signal.signal(s, signal.SIG_DFL)
for s in KEYS:
    signal.signal(s, signal.SIG_IGN)
p = subprocess.Popen(sys.argv[1:], process_group=0, preexec_fn=job_defaults)
os.tcsetpgrp(0, p.pid)
while True:
    _, status = os.waitpid(p.pid, os.WUNTRACED)
    if not os.WIFSTOPPED(status):
        break
    print("{_STOPPED}", file=sys.stderr, flush=True)
    os.killpg(p.pid, signal.SIGKILL)
rc = os.waitstatus_to_exitcode(status)
sys.exit(rc if rc >= 0 else 128 - rc)
"""


class _TerminalProc(_Proc):
    """The bench at a real terminal: a pty is the controlling terminal of a session whose leader (a
    miniature shell, `_SHELL`) runs the bench as the foreground job, so a key written to the pty
    (`key`: Ctrl-Z ``b"\\x1a"``, Ctrl-\\ ``b"\\x1c"``) makes the kernel signal every process of the bench's
    group at once (the loop, the log writer, the progress bar, multiprocessing's resource tracker), as
    an interactive shell's terminal does. Everything printed (stdout and stderr share the terminal) is
    collected; the bar is drawn as at a desk."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        import fcntl
        import termios
        import threading

        self.mark = uuid.uuid4().hex
        env = {**os.environ, _MARK: self.mark, "PYTHONUNBUFFERED": "1", "TERM": "xterm-256color"}
        master, slave = os.openpty()
        try:
            # setsid (start_new_session) first, then the pty becomes the new session's controlling terminal
            self.p = subprocess.Popen([sys.executable, "-c", _SHELL, sys.executable, *args], cwd=cwd, env=env,
                                      stdin=slave, stdout=slave, stderr=slave, start_new_session=True,
                                      preexec_fn=lambda: fcntl.ioctl(0, termios.TIOCSCTTY, 0))  # fmt: skip
        finally:
            os.close(slave)
        self.t0 = time.monotonic()
        self.t_key: float | None = None
        self._master, self._out = master, bytearray()
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    def _drain(self) -> None:
        while True:
            try:
                chunk = os.read(self._master, 65536)
            except OSError:  # EIO: no process holds the terminal any more
                return
            if not chunk:
                return
            self._out += chunk

    def key(self, key: bytes) -> None:
        """Type ``key`` at the terminal (the line discipline turns ^Z, ^\\, ^C into signals)."""
        self.t_key = time.monotonic()
        os.write(self._master, key)

    def wait(self, timeout: float = 60.0) -> tuple[int, str, str]:
        try:
            self.p.wait(timeout)
        finally:
            self._reader.join(5.0)
        text = self._out.decode(errors="replace")
        return self.p.returncode, text, text


def _check(o: Outcome, log: Path, summary: Path) -> None:
    s: dict[str, Any] = {}
    if o.expected_exit == 2:  # bad input: refused before anything was opened or written
        o.summary_written = None if not summary.exists() else False
        o.log_intact = None if not log.exists() else False
        return
    if summary.exists():
        s = json.loads(summary.read_text())
        o.summary_written = "trip_cause" in s and s.get("exit_code") == o.exit_code
        o.cause = s.get("trip_cause")
    else:
        o.summary_written = False
    if not log.exists():  # interrupted before the writer made the file: nothing to log, if nothing ran
        o.log_intact = None if s.get("ticks") == 0 else False
        return
    try:
        rig, = LogReader(log).read_ticks("/rig")
    except BadInput as exc:
        o.log_intact, o.notes = False, [*o.notes, str(exc)]
        return
    ticks = rig["tick"]
    rows = len(ticks)
    complete = rows == s.get("ticks") or (o.case.startswith("writer-killed") and 0 < rows <= s.get("ticks", 0))
    o.log_intact = bool(complete and (rows < 2 or np.all(np.diff(ticks) > 0)))
    tripped = rig["tripped"].astype(bool)
    if rows == 0:  # interrupted before the first tick: the rig was never enabled
        o.safe_within_one_tick = None
        return
    if not tripped.any():
        o.safe_within_one_tick = None if (o.expected_exit == 0 or o.case.startswith("writer-killed")) else False
        return
    k = int(np.argmax(tripped))
    after = slice(k, None)
    o.safe_within_one_tick = bool(tripped[after].all() and not rig["enable"][after].any()
                                  and np.all(rig["m_l_ref"][after] == 0.0)
                                  and np.all(rig["u_s_ref_re"][after] == 0.0)
                                  and np.all(rig["u_s_ref_im"][after] == 0.0))  # fmt: skip


def _run_case(case: str, fault: str, expected: int, args: list[str], work: Path,
              act: Callable[[_Proc], None] | None = None, log_name: str = "run.mcap",
              terminal: bool = False, max_shutdown_s: float | None = None) -> Outcome:  # fmt: skip
    """``terminal``: the bench runs at a pty (`_TerminalProc`); ``max_shutdown_s`` bounds the time from
    its key press to the exit."""
    o = Outcome(case, fault, expected, max_shutdown_s=max_shutdown_s)
    proc = _TerminalProc(args, work) if terminal else _Proc(args, work)
    try:
        if act is not None:
            act(proc)
        o.exit_code, out, err = proc.wait()
    except Exception as exc:  # noqa: BLE001 - a case that hangs or breaks is a failed row, not a crash
        proc.kill_all()  # a hung case leaves nothing behind
        o.exit_code, out, err = proc.p.wait(), "", ""
        o.notes.append(f"hung: no exit within {exc.timeout:g} s" if isinstance(exc, subprocess.TimeoutExpired)
                       else f"{type(exc).__name__}: {exc}")  # fmt: skip
    o.seconds = round(time.monotonic() - proc.t0, 2)
    if terminal and _STOPPED in err:
        o.notes.append("the bench was stopped (suspended) by the key")
    if terminal and proc.t_key is not None and o.exit_code is not None:
        o.shutdown_s = round(time.monotonic() - proc.t_key, 2)
    time.sleep(0.2)
    o.leftover_processes = proc.leftovers()
    if "Traceback" in err:
        o.notes.append("traceback on stderr")
        o.summary_written = False
    log = work / log_name
    _check(o, log, log.with_name(log.stem + ".summary.json"))
    if "Traceback" in err:
        o.summary_written = False
    return o


def _bench(*args: str) -> list[str]:
    return ["-m", "bench", *args]


def _run_args(log: str = "run.mcap", *extra: str) -> list[str]:
    return _bench("run", "--no-progress", "--log", log, *extra)


def _script(body: str) -> list[str]:
    """``python -c``: a session with something planted in the process (a failing driver, a slow tick)."""
    head = "import sys\nfrom pathlib import Path\nfrom bench.runtime.session import RunOptions, run\n"
    tail = "\nsummary, code = run(opts)\nsys.exit(code)\n"
    return ["-c", head + textwrap.dedent(body) + tail]


# Real-time cases turn the motor gently (10 rad/s, fig5.7): the drive rides through an OS stall of the loop
# (up to limits.ride_through), and a longer one at low speed and load is no over-current either: a true trip,
# but not the fault a case is about.
GENTLE = ("--scenario", "fig5.7")


def _signal(sig: int, *more: tuple[float, int]) -> Callable[[_Proc], None]:
    def fn(p: _Proc) -> None:
        p.p.send_signal(sig)
        for delay, s in more:
            time.sleep(delay)
            p.p.send_signal(s)

    return fn


def _writer(*steps: tuple[int, float]) -> Callable[[_Proc], None]:
    def fn(p: _Proc) -> None:
        pid = p.writer_pid()
        for sig, hold in steps:
            os.kill(pid, sig)
            time.sleep(hold)

    return fn


def _when_ticking(log: Path, then: Callable[[_Proc], None], delay: float = 0.5,
                  timeout: float = 30.0) -> Callable[[_Proc], None]:
    """Wait until the log holds its first ticks (the loop runs), then ``delay``: a loaded machine may
    take seconds to start the writer process, and a fault before that tests the start-up instead."""

    def act(p: _Proc) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end and p.p.poll() is None:
            try:
                if LogReader(log).summary()["topics"].get("/rig", {}).get("messages", 0) > 0:
                    break
            except Exception:  # noqa: BLE001 - not there yet, or mid-write
                pass
            time.sleep(0.05)
        time.sleep(delay)
        then(p)

    return act


def _when_log_closed(log: Path, then: Callable[[_Proc], None]) -> Callable[[_Proc], None]:
    """Wait until the MCAP file is finished, i.e. the run is in its summary/plot phase."""
    def act(p: _Proc) -> None:
        end = time.monotonic() + 120
        while time.monotonic() < end and p.p.poll() is None and not is_finished(log):
            time.sleep(0.001)
        then(p)

    return act


class _Emulator:
    """`bench emulate` in its own process on free ports, and a rig file that talks to it."""

    def __init__(self, work: Path) -> None:
        data = emulated_data("tcp")
        data["emulator"]["autostart"] = "always"
        # These cases test how a kill or a STOP ends a run, not the watchdogs' margins: three processes on
        # two loaded cores stall for 10-100 ms now and then (CI), and the rig file's 50 ms heartbeat and
        # 0.1 s control-word timeout would end the run before the fault under test. The watchdogs'
        # own reactions are tested on their own (tests/test_supervisor_faults.py, tests/test_emulators.py).
        data["can"]["heartbeat_timeout"] = 0.1
        data["emulator"]["control_timeout"] = 0.3
        self.rig_emu = write_rig(work / "emu-side.toml", data)
        self.proc = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(self.rig_emu),
                                      "--duration", "120"], cwd=work, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
        line = self.proc.stdout.readline()
        ports = json.loads(line)
        host, port = ports["modbus"].rsplit(":", 1)
        data["can"]["channel"] = ports["can"]["channel"]
        data["serial"]["port"] = ports["serial"]
        data["modbus"]["host"], data["modbus"]["port"] = host, int(port)
        data["emulator"]["autostart"] = "auto"  # it answers: the host uses the drivers, starts nothing
        self.rig = write_rig(work / "host-side.toml", data)
        mb = load_rig(str(self.rig)).hw["modbus"]
        self.modbus = (host, int(port), mb["unit"], mb["control_word"])

    def stop_drive(self) -> None:
        """A third party on the Modbus network writes the FC-profile STOP control word (0x043C)."""
        from pymodbus.client import ModbusTcpClient

        host, port, unit, ctw = self.modbus
        c = ModbusTcpClient(host, port=port, timeout=2)
        c.connect()
        c.write_register(ctw, 0x043C, device_id=unit)
        c.close()

    def status_word(self) -> int:
        """The drive's FC-profile status word, read by a third party over Modbus."""
        from pymodbus.client import ModbusTcpClient

        host, port, unit, _ = self.modbus
        sw = load_rig_cfg(str(self.rig)).hw["modbus"]["status_word"]
        c = ModbusTcpClient(host, port=port, timeout=2)
        c.connect()
        try:
            return int(c.read_holding_registers(sw, count=1, device_id=unit).registers[0])
        finally:
            c.close()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


class _Flood:
    """Hostile loopback clients of a live run, each on its own connection and thread: one sends
    ``setParameters`` every 1 ms (far above the rate limit), one calls /mark with a 70 000-character
    note every 20 ms (a frame larger than the request pipe). They run until `stop`; ``sent`` counts
    what each sent."""

    NOTE = "n" * 70_000

    def __init__(self, port: int) -> None:
        import threading

        self.port, self.sent = port, {"set": 0, "mark": 0}
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=f, daemon=True) for f in (self._sets, self._marks)]
        self.errors: list[str] = []

    def __enter__(self) -> "_Flood":
        for t in self._threads:
            t.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(5)

    def _connect(self) -> Any:
        from websockets.sync.client import connect

        return connect(f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"], max_size=None,
                       open_timeout=10)  # fmt: skip

    @staticmethod
    def _drain(ws: Any) -> list[Any]:
        out = []
        while True:
            try:
                out.append(ws.recv(timeout=0))
            except TimeoutError:
                return out

    def _sets(self) -> None:
        try:
            with self._connect() as ws:
                i, t0 = 0, time.monotonic()
                while not self._stop.is_set():
                    ws.send(json.dumps({"op": "setParameters", "id": f"flood {i}", "parameters": [
                        {"name": "flux_Km", "value": 4.0 + 1e-3 * (i % 2), "type": "float64"}]}))  # fmt: skip
                    i += 1
                    self.sent["set"] = i
                    if i % 50 == 0:
                        self._drain(ws)
                    time.sleep(max(0.0, t0 + i * 1e-3 - time.monotonic()))  # every 1 ms
        except Exception as exc:  # noqa: BLE001 - the run ended and closed the connection
            self.errors.append(f"sets: {type(exc).__name__}: {exc}")

    def _marks(self) -> None:
        import struct

        try:
            with self._connect() as ws:
                sid = None
                while sid is None:
                    m = ws.recv(timeout=10)
                    if isinstance(m, str) and json.loads(m).get("op") == "advertiseServices":
                        sid = next((x["id"] for x in json.loads(m)["services"] if x["name"] == "/mark"), None)
                payload = json.dumps({"note": self.NOTE, "who": "flood"}).encode()
                i = 0
                while not self._stop.is_set():
                    i += 1
                    ws.send(struct.pack("<BIII", 2, sid, i, 4) + b"json" + payload)  # callService
                    self.sent["mark"] = i
                    self._drain(ws)
                    self._stop.wait(0.02)
        except Exception as exc:  # noqa: BLE001
            self.errors.append(f"marks: {type(exc).__name__}: {exc}")


def _live_port(p: _Proc) -> int:
    """The live server's port, from the run's first line on stderr."""
    line = p.p.stderr.readline()
    if "ws://127.0.0.1:" not in line:
        raise RuntimeError(f"no live server announced: {line!r}")
    return int(line.split("ws://127.0.0.1:")[1].split()[0])


def _action_under_flood(action: str, details: dict[str, Any], flood_s: float = 1.5) -> Callable[[_Proc], None]:
    """Floods running, then an operator ``action`` (stop, estop) with the client of `bench stop|estop`;
    the floods go on until the run has ended. ``details`` gets the answer, what the floods sent and
    how long the run took to end after the answer."""

    def act(p: _Proc) -> None:
        port = _live_port(p)
        with _Flood(port) as flood:
            time.sleep(flood_s)
            try:
                resp = call(action, port=port)
                if resp["state"] == "unknown":  # no answer: the run had ended before (see the summary)
                    details["error"] = resp["status"]
                else:
                    details["response"] = resp
            except (BadInput, ConnectionError, TimeoutError) as exc:  # the run had ended before: see the summary
                details["error"] = str(exc)
            t_answer = time.monotonic()
            try:
                p.p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                pass
            details["ended_after_s"] = round(time.monotonic() - t_answer, 3)
            details["flood_sent"] = dict(flood.sent)

    return act


def _operator_case(name: str, action: str, expected: int) -> Callable[[Path], Outcome]:
    """A live run, the floods of `_Flood`, then `action`; the latency from the call to the tick it was
    applied at is the wall clock of that tick (the run's start epoch + t) minus when the call left."""

    def run(w: Path) -> Outcome:
        fault = (f"`bench {action}` while one client sends setParameters every 1 ms and another calls /mark with "
                 "a 70 000-character note")  # fmt: skip
        notes = []
        for attempt in (1, 2):
            # the fault under test is the action during the floods: a run that ended before it (on a loaded
            # 2-core machine an OS stall of the loop can trip it first, a true trip) did not receive it, so the
            # set-up is repeated once, and said
            wa = w if attempt == 1 else w / f"attempt{attempt}"
            wa.mkdir(exist_ok=True)
            details: dict[str, Any] = {}
            o = _run_case(name, fault, expected, _run_args("run.mcap", "--realtime", "--duration", "25", *GENTLE,
                                                           "--live", "--live-port", "0"), wa,
                          _when_ticking(wa / "run.mcap", _action_under_flood(action, details)))  # fmt: skip
            if "response" in details:
                break
            notes.append(f"attempt {attempt}: the run ended before the {action} ({o.cause}): {details.get('error')}")
        o.notes = notes + o.notes
        resp = details.get("response", {})
        summary = wa / "run.summary.json"
        if summary.exists() and isinstance(resp.get("t"), float):
            epoch = json.loads(summary.read_text()).get("start_epoch_ns") or 0
            details["latency_ms"] = round((epoch + resp["t"] * 1e9 - resp["sent_ns"]) / 1e6, 2)
        o.details = details
        o.notes.append(f"{action}: {resp.get('status')} at tick {resp.get('tick')}; latency "
                       f"{details.get('latency_ms')} ms; run ended {details.get('ended_after_s')} s after the answer; "
                       f"flood sent {details.get('flood_sent')}")  # fmt: skip
        return o

    return run


def _host_killed(w: Path) -> Outcome:
    """SIGKILL of the bench itself: nothing on the PC can send the safe command; the drive's own
    control-word timeout must coast the motor, and the next session must start cleanly."""
    o = Outcome("host-killed", "SIGKILL of the bench mid-run: the emulated drive coasts by its control-word "
                "timeout, the next session starts cleanly", 0)
    emu = _Emulator(w)
    try:
        for attempt in (1, 2):
            # the fault under test is the kill of a *running* session: a first session that ended before it (on
            # a 2-core machine, an OS stall at its start can hold the magnetising voltage long enough for a true
            # over-current trip) did not receive the fault, so the set-up is repeated once, and said
            log = f"first{'' if attempt == 1 else attempt}.mcap"
            first = _Proc(_run_args(log, "--rig", str(emu.rig), *GENTLE, "--realtime", "--duration", "20"), w)
            _when_ticking(w / log, lambda p: None, delay=1.0)(first)
            before = emu.status_word()
            if first.p.poll() is None and before & STW_RUNNING:
                break
            o.notes.append(f"first session (attempt {attempt}) was no longer running at the kill "
                           f"(exit code {first.p.poll()}, drive status 0x{before:04X})")  # fmt: skip
            if attempt == 1:
                first.p.kill()
                first.wait()
        first.p.kill()
        first.wait()
        t_kill = time.monotonic()
        timeout = load_rig_cfg(str(emu.rig)).hw["emulator"]["control_timeout"]
        sw = emu.status_word()
        while sw & STW_RUNNING and not sw & STW_TRIP and time.monotonic() - t_kill < 5.0:
            sw = emu.status_word()
        coasted = time.monotonic() - t_kill
        o.notes.append(f"drive status word 0x{before:04X} before the kill, 0x{sw:04X} {coasted:.3f} s after it "
                       f"(control_timeout {timeout:g} s)")  # fmt: skip
        o.safe_within_one_tick = (bool(before & STW_RUNNING) and bool(sw & STW_TRIP) and not sw & STW_RUNNING
                                  and coasted < timeout + 0.5)  # fmt: skip
        time.sleep(0.2)
        o.leftover_processes = first.leftovers()
        o = _finish_second_session(o, emu, w)
    finally:
        emu.close()
    return o


def _key(key: bytes) -> Callable[[_Proc], None]:
    def fn(p: _Proc) -> None:
        p.key(key)  # type: ignore[attr-defined]

    return fn


def _terminal_emulated(case: str, key: bytes, expected: int, what: str) -> Callable[[Path], Outcome]:
    """A terminal key during a real-time run on the emulated rig (real drivers, device emulators in their own
    process, which the key does not reach): the drive must be stopped by the bench's safe command (RUNNING
    clear within a second of the key, no control-word-timeout trip), not coasted later by its own watchdog."""
    def run(w: Path) -> Outcome:
        emu = _Emulator(w)
        seen: dict[str, Any] = {}

        def act(p: _Proc) -> None:
            seen["before"] = emu.status_word()
            p.key(key)  # type: ignore[attr-defined]
            t0 = time.monotonic()
            sw = emu.status_word()
            while sw & STW_RUNNING and time.monotonic() - t0 < 5.0:
                sw = emu.status_word()
            seen["stopped_after"], seen["sw"] = time.monotonic() - t0, sw

        try:
            o = _run_case(case, what, expected, _bench("run", "--log", "run.mcap", "--rig", str(emu.rig),
                                                       "--realtime", "--duration", "20", *GENTLE), w,
                          _when_ticking(w / "run.mcap", act), terminal=True, max_shutdown_s=10.0)  # fmt: skip
            after = emu.status_word()
        finally:
            emu.close()
        if "before" in seen:
            o.notes.append(f"drive status word 0x{seen['before']:04X} before the key, 0x{seen['sw']:04X} "
                           f"{seen['stopped_after']:.3f} s after it, 0x{after:04X} after the exit")  # fmt: skip
            stopped = (bool(seen["before"] & STW_RUNNING) and not seen["sw"] & STW_RUNNING
                       and seen["stopped_after"] < 1.0)  # fmt: skip
            o.safe_within_one_tick = bool(o.safe_within_one_tick is not False and stopped and not after & STW_TRIP)
        return o

    return run


_FULL_NOTE = "the summary in full (its file could not be written):"


def _disk_full(case: str, free: int, what: str, expected_cause: str) -> Callable[[Path], Outcome]:
    """The run's files on a 2 MB tmpfs (mounted for the case: needs root) with ``free`` bytes left: whatever the
    disk takes, the rig is made safe, the exit code is 1 with a one-line cause, the summary is in
    ``summary.json`` or, when that cannot be written, in full on stderr, stderr's last line says which files
    were and were not written, the log's loss is counted as the file shows it, and no empty file is left."""

    def run(w: Path) -> Outcome:
        o = Outcome(case, what, 1)
        disk = w / "disk"
        disk.mkdir(exist_ok=True)
        mount = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)], capture_output=True,
                               text=True)  # fmt: skip
        if mount.returncode != 0:
            o.notes.append(f"not run: cannot mount a tmpfs ({mount.stderr.strip() or 'needs root'})")
            return o
        try:
            room = os.statvfs(disk)
            (disk / "filler").write_bytes(bytes(max(0, room.f_bavail * room.f_frsize - free)))
            proc = _Proc(_run_args(str(disk / "run.mcap"), "--duration", "20"), w)
            o.exit_code, out, err = proc.wait()
            o.seconds = round(time.monotonic() - proc.t0, 2)
            time.sleep(0.2)
            o.leftover_processes = proc.leftovers()
            _check_disk_full(o, disk, out, err, expected_cause)
        finally:
            subprocess.run(["umount", "-l", str(disk)], capture_output=True)
        return o

    return run


def _check_disk_full(o: Outcome, disk: Path, out: str, err: str, expected_cause: str) -> None:
    log, summary = disk / "run.mcap", disk / "run.summary.json"
    empty = sorted(p.name for p in disk.iterdir() if p.is_file() and p.stat().st_size == 0)
    empty += sorted(p.name for p in disk.iterdir() if p.name.startswith("."))  # temporary or reserved files
    if empty:
        o.notes.append(f"empty or temporary files left: {empty}")
    if "Traceback" in err:
        o.notes.append("traceback on stderr")
    if summary.exists():
        s = json.loads(summary.read_text())
    elif _FULL_NOTE in err:
        text = err.split(_FULL_NOTE, 1)[1]
        s = json.JSONDecoder().raw_decode(text.lstrip())[0]
        o.notes.append("summary.json not written: the summary is on stderr in full")
    else:
        s = {}
    o.cause = s.get("trip_cause")
    last = [ln for ln in err.splitlines() if ln.startswith("bench: TRIPPED")]
    said = last[-1] if last else ""
    m = re.search(r"[(;] ?([\w, ]+) NOT written", said)
    missing = {w.strip() for w in m.group(1).split(",")} if m else set()
    on_disk = {"log": log.exists(), "summary": summary.exists(), "plot": (disk / "run.png").exists()}
    told = bool(said) and missing == {k for k, there in on_disk.items() if not there}  # stderr says what is on disk
    o.summary_written = bool(s and s.get("exit_code") == o.exit_code and (o.cause or "").startswith(expected_cause)
                             and "\n" not in o.cause and told and not empty and "Traceback" not in err)  # fmt: skip
    if not told:
        o.notes.append(f"stderr says: {said!r}")
    if not log.exists():
        o.log_intact = None if s.get("ticks") == 0 else False
        return
    (rig,) = LogReader(log).read_ticks("/rig")
    lw = s.get("log_writer") or {}
    rows = len(rig["tick"])
    o.log_intact = bool((rows < 2 or np.all(np.diff(rig["tick"]) == 1)) and lw.get("rows_written") == rows
                        and lw.get("dropped") == s.get("ticks", 0) - rows)  # fmt: skip
    o.notes.append(f"{rows} of {s.get('ticks')} rows in the log, {lw.get('dropped')} reported lost")


def _finish_second_session(o: Outcome, emu: "_Emulator", w: Path) -> Outcome:
    second = _run_case(o.case, o.fault, 0, _run_args("run.mcap", "--rig", str(emu.rig), "--realtime", *GENTLE,
                                                     "--duration", "1.0"), w)  # fmt: skip
    second.notes = o.notes + second.notes
    second.safe_within_one_tick = o.safe_within_one_tick  # here: the drive coasted by its own timeout
    second.leftover_processes += o.leftover_processes
    return second


def cases() -> dict[str, Callable[[Path], Outcome]]:
    """Case name -> function(work dir) -> Outcome."""
    rt = ("--realtime", "--duration", "20", *GENTLE)

    def over_speed(w: Path) -> Outcome:  # the set-points stay inside the margins: the fault is injected by name
        return _run_case("over-speed", "supervisor trip (over-speed injected, mock rig)", 1,
                         _run_args("run.mcap", "--inject-fault", "over-speed"), w)  # fmt: skip

    def emulated(name: str, fault: str, expected: int, act: Callable[[_Proc, _Emulator], None]) -> Callable:
        def run(w: Path) -> Outcome:
            emu = _Emulator(w)
            try:
                return _run_case(name, fault, expected, _run_args("run.mcap", "--rig", str(emu.rig), *rt),
                                 w, _when_ticking(w / "run.mcap", lambda p: act(p, emu)))  # fmt: skip
            finally:
                emu.close()

        return run

    read_fails = _script("""
        from mock_hw.plant import MockPlant
        orig = MockPlant.acquire
        def acquire(self, t):
            if t >= 0.5:
                raise OSError("front-end cable pulled")
            return orig(self, t)
        MockPlant.acquire = acquire
        opts = RunOptions(log=Path("run.mcap"), duration=1.0, progress=False)
    """)
    def stall_of(seconds: float, ride_through: float = 0.05) -> list[str]:  # one tick at t >= 1 s takes so long
        return _script(f"""
            import dataclasses, time
            from bench.core.config import load
            cfg = load("mock")
            cfg = dataclasses.replace(cfg, limits=dataclasses.replace(cfg.limits, ride_through={ride_through}))
            from bench.controllers.foc import FocController
            orig = FocController.step
            stalled = []
            def step(self, meas, w, i):
                if meas.t >= 1.0 and not stalled:  # the first tick from t = 1 s on (a real-time loop may skip 1.0)
                    stalled.append(meas.t)
                    time.sleep({seconds})
                return orig(self, meas, w, i)
            FocController.step = step
            opts = RunOptions(rig=cfg, log=Path("run.mcap"), duration=2.0, realtime=True, progress=False)
        """)

    channel_breaks = _script("""
        from bench.daq import writer
        orig = writer.RequestInbox.take
        def take(self, k):
            if self._idx[writer.POSTED] != self._seen:  # a request waits: its pipe breaks under it
                self._conn.close()
            return orig(self, k)
        writer.RequestInbox.take = take
        opts = RunOptions(log=Path("run.mcap"), duration=20.0, realtime=True, progress=False, scenario="fig5.7",
                          live_port=0)
    """)

    def set_once(p: _Proc) -> None:
        try:
            set_params({"speed_Kp": 0.7}, port=_live_port(p))
        except (TimeoutError, ConnectionError):  # no answer: the run tripped on it
            pass

    return {
        "normal-end": lambda w: _run_case("normal-end", "none (lockstep run to the end)", 0,
                                          _run_args("run.mcap", "--duration", "1"), w),
        "over-speed": over_speed,
        "sigint": lambda w: _run_case("sigint", "SIGINT (Ctrl-C) mid-run", 130, _run_args("run.mcap", *rt), w,
                                      _when_ticking(w / "run.mcap", _signal(signal.SIGINT))),
        "sigterm": lambda w: _run_case("sigterm", "SIGTERM mid-run", 143, _run_args("run.mcap", *rt), w,
                                       _when_ticking(w / "run.mcap", _signal(signal.SIGTERM))),
        "sighup": lambda w: _run_case("sighup", "SIGHUP (terminal closed) mid-run", 129, _run_args("run.mcap", *rt),
                                      w, _when_ticking(w / "run.mcap", _signal(signal.SIGHUP))),
        "ctrl-c-terminal": lambda w: _run_case("ctrl-c-terminal", "SIGINT to the whole process group (Ctrl-C in a "
                                               "terminal: loop, log writer, progress bar)", 130,
                                               _bench("run", "--log", "run.mcap", *rt), w,
                                               _when_ticking(w / "run.mcap", lambda p: os.killpg(p.p.pid, signal.SIGINT))),
        "terminal-closed": lambda w: _run_case("terminal-closed", "SIGHUP to the whole process group (terminal "
                                               "closed)", 129, _run_args("run.mcap", *rt), w,
                                               _when_ticking(w / "run.mcap", lambda p: os.killpg(p.p.pid, signal.SIGHUP))),
        "ctrl-z": lambda w: _run_case("ctrl-z", "SIGTSTP (Ctrl-Z) mid-run: the rig is not left suspended", 148,
                                      _run_args("run.mcap", *rt), w, _when_ticking(w / "run.mcap", _signal(signal.SIGTSTP))),
        "ctrl-z-terminal": lambda w: _run_case("ctrl-z-terminal", "Ctrl-Z typed at a terminal (SIGTSTP to the "
                                               "whole foreground group; progress bar drawn)", 148,
                                               _bench("run", "--log", "run.mcap", *rt), w,
                                               _when_ticking(w / "run.mcap", _key(b"\x1a")), terminal=True,
                                               max_shutdown_s=10.0),
        "ctrl-backslash-terminal": lambda w: _run_case("ctrl-backslash-terminal", "Ctrl-\\ typed at a terminal "
                                                       "(SIGQUIT to the whole foreground group)", 131,
                                                       _bench("run", "--log", "run.mcap", *rt), w,
                                                       _when_ticking(w / "run.mcap", _key(b"\x1c")), terminal=True,
                                                       max_shutdown_s=10.0),
        "ctrl-z-terminal-emulated": _terminal_emulated("ctrl-z-terminal-emulated", b"\x1a", 148,
                                                       "Ctrl-Z typed at a terminal, emulated rig: the drive is "
                                                       "stopped by the bench, not by its watchdog"),
        "sigint-twice": lambda w: _run_case("sigint-twice", "SIGINT, then SIGINT again 2 ms later", 130,
                                            _run_args("run.mcap", *rt), w,
                                            _when_ticking(w / "run.mcap", _signal(signal.SIGINT, (0.002, signal.SIGINT)))),
        "sigterm-then-sigint": lambda w: _run_case("sigterm-then-sigint", "SIGTERM, then SIGINT during shutdown",
                                                   143, _run_args("run.mcap", *rt), w,
                                                   _when_ticking(w / "run.mcap", _signal(signal.SIGTERM, (0.05, signal.SIGINT)))),
        "sigint-during-summary": lambda w: _run_case("sigint-during-summary", "SIGINT after the log is closed, "
                                                     "while the summary and plot are made (the outcome stands)", 0,
                                                     _run_args("run.mcap", "--scenario", "fig5.8"), w,
                                                     _when_log_closed(w / "run.mcap", _signal(signal.SIGINT))),
        "sigint-at-start": lambda w: _run_case("sigint-at-start", "SIGINT as soon as the log writer process exists",
                                               130, _run_args("run.mcap", *rt), w,
                                               lambda p: (p.writer_pid(), p.p.send_signal(signal.SIGINT))),
        "writer-killed": lambda w: _run_case("writer-killed", "SIGKILL of the log writer mid-run", 1,
                                             _run_args("run.mcap", *rt), w,
                                             _when_ticking(w / "run.mcap", _writer((signal.SIGKILL, 0)))),
        "writer-stalled": lambda w: _run_case("writer-stalled", "SIGSTOP of the log writer for 1.5 s, ring 0.3 s",
                                              1, _run_args("run.mcap", *rt, "--log-buffer", "0.3"), w,
                                              _when_ticking(w / "run.mcap", _writer((signal.SIGSTOP, 1.5),
                                                                                    (signal.SIGCONT, 0)))),
        "writer-paused": lambda w: _run_case("writer-paused", "SIGSTOP of the log writer for 1 s, ring 10 s", 0,
                                             _run_args("run.mcap", "--realtime", "--duration", "3", *GENTLE), w,
                                             _when_ticking(w / "run.mcap", _writer((signal.SIGSTOP, 1.0),
                                                                                   (signal.SIGCONT, 0)))),
        "driver-exception": lambda w: _run_case("driver-exception", "exception in rig.read (driver) at t = 0.5 s", 1,
                                                read_fails, w),
        "loop-stall": lambda w: _run_case("loop-stall", "one tick takes 80 ms (real time; mock rig max_stall 50 ms)", 1,
                                          stall_of(0.08), w),
        "stall-ridden-through": lambda w: _run_case("stall-ridden-through", "one tick takes 30 ms (real time; the "
                                                    "mock drive's ride-through 50 ms)", 0, stall_of(0.03), w),
        "stall-past-ride-through": lambda w: _run_case("stall-past-ride-through", "one tick takes 30 ms (real time; "
                                                       "a drive's 20 ms ride-through, max_stall 50 ms)", 1,
                                                       stall_of(0.03, 0.02), w),
        "emulator-killed": emulated("emulator-killed", "SIGKILL of the emulator (emulated rig, real drivers)", 1,
                                    lambda p, e: e.proc.kill()),
        "drive-stopped": emulated("drive-stopped", "third-party Modbus STOP of the drive (emulated rig)", 1,
                                  lambda p, e: e.stop_drive()),
        "host-killed": _host_killed,
        "disk-full": _disk_full("disk-full", 400_000, "the disk fills mid-run (2 MB tmpfs, 400 kB free)",
                                "log writer died (OSError: [Errno 28]"),
        "disk-full-at-start": _disk_full("disk-full-at-start", 0, "the disk is full before the run starts",
                                         "start-up failed: LogWriterError:"),
        "estop-under-flood": _operator_case("estop-under-flood", "estop", 1),
        "stop-under-flood": _operator_case("stop-under-flood", "stop", 0),
        "request-channel-broken": lambda w: _run_case("request-channel-broken", "the live request pipe breaks in "
                                                      "the loop process as a parameter change arrives", 1,
                                                      channel_breaks, w, _when_ticking(w / "run.mcap", set_once)),
        "real-rig-lockstep": lambda w: _run_case("real-rig-lockstep", "lockstep on a rig with real devices", 2,
                                                 _run_args("run.mcap", "--rig", str(RIGS / "lab-example.toml"),
                                                           "--lockstep"), w),
    }  # fmt: skip


def run(names: list[str] | None = None, out: Path | None = None, progress: bool = True) -> list[Outcome]:
    table = cases()
    chosen = names or list(table)
    unknown = [n for n in chosen if n not in table]
    if unknown:
        raise BadInput("case", f"unknown {unknown[0]!r}; allowed: {', '.join(table)}")
    results = []
    base = Path(tempfile.mkdtemp(prefix="fault-matrix-")) if out is None else out
    for i, name in enumerate(chosen):
        work = base / name
        work.mkdir(parents=True, exist_ok=True)
        if progress:
            print(f"[{i + 1}/{len(chosen)}] {name} ...", file=sys.stderr, flush=True)
        try:
            results.append(table[name](work))
        except Exception as exc:  # noqa: BLE001 - the harness itself failed: a failed row
            results.append(Outcome(name, "harness", -1, notes=[f"{type(exc).__name__}: {exc}"]))
    return results


def markdown(results: list[Outcome]) -> str:
    """The table of docs/RESULTS.md section 7."""

    def mark(v: bool | None) -> str:
        return "n/a" if v is None else ("yes" if v else "**NO**")

    rows = ["| fault | exit code (expected) | safe within one tick | log intact | summary written | cause | s |",
            "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in results:
        code = f"{r.exit_code} ({r.expected_exit})" if r.exit_code == r.expected_exit else f"**{r.exit_code}** ({r.expected_exit})"
        cause = (r.cause or "").replace("|", "\\|")
        rows.append(f"| {r.fault} | {code} | {mark(r.safe_within_one_tick)} | {mark(r.log_intact)} | "
                    f"{mark(r.summary_written)} | {cause} | {r.seconds:.1f} |")  # fmt: skip
    return "\n".join(rows)


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", help="case names (default: all)")
    ap.add_argument("--out", type=Path, default=None, help="folder for the cases' logs (default: a temp folder)")
    ap.add_argument("--markdown", action="store_true", help="print the RESULTS table instead of JSON")
    a = ap.parse_args()
    res = run(a.cases or None, a.out)
    print(markdown(res) if a.markdown else json.dumps([{**asdict(r), "ok": r.ok} for r in res], indent=2))
    sys.exit(0 if all(r.ok for r in res) else 1)


if __name__ == "__main__":
    main()
