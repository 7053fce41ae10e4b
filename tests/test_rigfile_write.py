"""The rig file that `bench identify --write` and `bench commission` replace, under signals, symbolic links and a
second writer: real subprocesses and real signals on the mock rig (rigs/mock-real.toml, as the README's
``cp rigs/mock-real.toml runs/lab.toml``, without its saturation).

After every signal the exit code says what happened to the file: 128 + the signal - byte for byte as it was, and
no temporary file or backup beside it; 0 - the new file complete (it loads as a rig file) and the backup equal to
the original. The default tests signal at chosen moments (`bench.core.shutdown.pause_for_test` holds the process
there): in a session's shutdown, with the file locked before the commit section, inside the commit section,
after it. The sweeps at ~20 random moments per command are ``slow``."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from bench.core import rigfile_write
from bench.workflows.commission import rigfile
from bench.core.config import load as load_rig
from bench.errors import BadInput
from bench.params import MotorParams

ROOT = Path(__file__).resolve().parents[1]
# the README's rig without its saturation: a standstill `--write` on a saturating motor is refused by design
# (tests/test_identify_saturation.py); these tests are about the write
MOCK_REAL = (ROOT / "rigs" / "mock-real.toml").read_text().replace("saturation = true", "saturation = false")
# tests/test_commission_cli.py's hidden motor behind a rig whose [motor] is (3.57): bench commission gives GO
HIDDEN = {"L_s": 0.30, "L_r": 0.30, "L_m": 0.285, "R_s": 3.8, "R_r": 4.4}
GO_RIG = MOCK_REAL + "".join(f"{k} = {v}\n" for k, v in HIDDEN.items())


def _lab(tmp: Path, text: str = MOCK_REAL, link: bool = False) -> tuple[Path, Path]:
    """(the path given to bench, the file behind it) in folders of their own: ``lab/real.toml``, and with
    ``link`` a relative symbolic link ``links/lab.toml`` to it."""
    target = tmp / "lab" / "real.toml"
    target.parent.mkdir(parents=True)
    target.write_text(text)
    if not link:
        return target, target
    given = tmp / "links" / "lab.toml"
    given.parent.mkdir()
    given.symlink_to(Path("..") / "lab" / "real.toml")
    return given, target


def _start(tmp: Path, args: list[str], pause: str | None = None) -> tuple[subprocess.Popen, Path, Path]:
    """`python -m bench ARGS` with its stdout and stderr in files (read while it runs); ``pause``: the
    ``BENCH_TEST_PAUSE`` it gets."""
    out, err = tmp / "stdout.txt", tmp / "stderr.txt"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("BENCH_TEST_PAUSE", None)
    if pause is not None:
        env["BENCH_TEST_PAUSE"] = pause
    with open(out, "wb") as o, open(err, "wb") as e:
        proc = subprocess.Popen([sys.executable, "-m", "bench", *args], cwd=ROOT, stdout=o, stderr=e, env=env)
    return proc, out, err


def _wait_for(path: Path, text: str, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and text in path.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            raise AssertionError(f"ended ({proc.returncode}) before {text!r}: {path.read_text()[-2000:]}")
        time.sleep(0.02)
    proc.kill()
    raise AssertionError(f"no {text!r} within {timeout} s")


def _check(code: int, sig: int, given: Path, target: Path, before: bytes, err: str) -> str:
    """The exit code against the file: "kept" (128 + sig) or "written" (0); anything else fails."""
    names = sorted(p.name for p in target.parent.iterdir())
    if code == -sig and err == "" and target.read_bytes() == before and names == [target.name]:
        return "kept"  # the signal came during the interpreter's own start-up, before bench ran: nothing read yet
    if given != target:  # written through the link: it stays a link to the same file, alone in its folder
        assert given.is_symlink() and given.resolve() == target.resolve()
        assert sorted(p.name for p in given.parent.iterdir()) == [given.name]
    if code == 128 + sig:
        assert target.read_bytes() == before, "exit 128 + signal, but the rig file changed"
        assert names == [target.name], f"exit 128 + signal, and beside the rig file: {names}"
        return "kept"
    assert code == 0, f"exit {code} after {signal.Signals(sig).name}: {err[-3000:]}"
    new = target.read_bytes()
    assert new != before
    load_rig(str(given))  # loads as a rig file
    tomllib.loads(new.decode())  # complete, valid TOML
    baks = [n for n in names if n.endswith(".bak")]
    assert len(baks) == 1 and (target.parent / baks[0]).read_bytes() == before
    assert names == sorted([target.name, baks[0]]), f"a stray file beside the rig file: {names}"
    return "written"


def _identify(given: Path, tmp: Path) -> list[str]:
    return ["identify", "--rig", str(given), "--out", str(tmp / "runs"), "--write"]


def _commission(given: Path, tmp: Path) -> list[str]:  # (the standstill test: the write is what these test)
    return ["commission", "--rig", str(given), "--out", str(tmp / "report"), "--standstill-only"]


# --- signals at chosen moments -----------------------------------------------------------------------------------
@pytest.mark.parametrize("point, sig, code", [
    ("session-shutdown", signal.SIGTERM, 143),  # the run ended; its shutdown absorbs the signal: no write
    ("rigfile-locked", signal.SIGHUP, 129),  # the last moment before the commit section
    ("rigfile-commit", signal.SIGINT, 0),  # inside it, before the rename: deferred, the commit goes through
    ("rigfile-committed", signal.SIGTERM, 0),  # after it
])  # fmt: skip
def test_identify_signal_around_the_commit_point(tmp_path: Path, point: str, sig: int, code: int) -> None:
    given, target = _lab(tmp_path, link=True)
    before = target.read_bytes()
    proc, out, err = _start(tmp_path, _identify(given, tmp_path), pause=f"{point}:2")
    _wait_for(err, f"bench: test pause: {point}", proc)
    proc.send_signal(sig)
    rc = proc.wait(timeout=120)
    text = err.read_text()
    assert rc == code, text[-3000:]
    assert _check(rc, sig, given, target, before, text) == ("written" if code == 0 else "kept")
    assert "Traceback" not in text and "race condition" not in text
    name = signal.Signals(sig).name
    if code == 0:
        assert f"bench: {name} arrived after {given} was replaced (the commit point)" in text.splitlines()[-1]
        w = json.loads(out.read_text())["written"]
        assert w["rig_file"] == str(given) and w["target"] == str(target.resolve())
        assert Path(w["backup"]).parent == target.parent.resolve()
    else:
        assert text.splitlines()[-1].startswith("bench: interrupted")


def test_commission_signal_inside_the_commit_section(tmp_path: Path) -> None:
    """GO, and SIGTERM while the rig file is being replaced: the commit goes through, exit 0, the report says
    where the backup is, and the last line that the signal came after the commit."""
    given, target = _lab(tmp_path, GO_RIG)
    before = target.read_bytes()
    proc, out, err = _start(tmp_path, _commission(given, tmp_path), pause="rigfile-commit:2")
    _wait_for(err, "bench: test pause: rigfile-commit", proc, timeout=300)
    proc.send_signal(signal.SIGTERM)
    rc = proc.wait(timeout=120)
    text = err.read_text()
    assert _check(rc, signal.SIGTERM, given, target, before, text) == "written"
    res = json.loads(out.read_text())
    assert res["go"] and res["written"]["backup"] in (tmp_path / "report" / "report.md").read_text()
    assert "SIGTERM arrived after" in text.splitlines()[-1] and "Traceback" not in text


@pytest.mark.slow  # 25 s; the shutdown case of bench identify is in the default suite
def test_commission_signal_in_the_closed_loops_shutdown(tmp_path: Path) -> None:
    """SIGINT while the closed-loop check's session shuts down (its run complete): NO-GO, exit 130, the
    report says so, the rig file as it was."""
    given, target = _lab(tmp_path, GO_RIG)
    before = target.read_bytes()
    proc, out, err = _start(tmp_path, _commission(given, tmp_path), pause="session-shutdown:2:2")
    _wait_for(err, "bench: test pause: session-shutdown", proc, timeout=300)
    proc.send_signal(signal.SIGINT)
    rc = proc.wait(timeout=120)
    assert _check(rc, signal.SIGINT, given, target, before, err.read_text()) == "kept"
    rep = json.loads((tmp_path / "report" / "commission.json").read_text())
    assert rep["verdict"].startswith("NO-GO: interrupted") and "shutdown" in rep["verdict"]
    assert not rep.get("written")


# --- signals at random moments -----------------------------------------------------------------------------------
def _sweep(tmp: Path, args: list[str], text: str, n: int, seed: int) -> dict[str, int]:
    """One undisturbed run (when its backup appeared: the commit moment Tc), then ``n`` runs each signalled once,
    SIGINT and SIGTERM in turn, every other pair through a symbolic link: half at a moment drawn over
    (0.2 s, Tc), half over (Tc - 2 s, Tc + 0.5 s) around the commit point (the runs' speed varies with the
    machine's load: some land before it, some after). Every outcome checked by `_check`."""
    rng = random.Random(seed)
    first = tmp / "undisturbed"
    given, target = _lab(first, text)
    before = target.read_bytes()
    t0 = time.monotonic()
    proc, _, err = _start(first, [a.replace("{rig}", str(given)).replace("{tmp}", str(first)) for a in args])
    t_commit = None
    while proc.poll() is None:
        if t_commit is None and any(target.parent.glob("*.bak")):
            t_commit = time.monotonic() - t0
        time.sleep(0.01)
    assert _check(proc.returncode, signal.SIGINT, given, target, before, err.read_text()) == "written"
    assert t_commit is not None
    seen = {"kept": 0, "written": 0}
    for k in range(n):
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        case = tmp / f"case{k}"
        given, target = _lab(case, text, link=k % 4 >= 2)
        before = target.read_bytes()
        at = rng.uniform(0.2, t_commit) if k < n // 2 else rng.uniform(max(0.2, t_commit - 2.0), t_commit + 0.5)
        proc, _, err = _start(case, [a.replace("{rig}", str(given)).replace("{tmp}", str(case)) for a in args])
        time.sleep(at)
        if proc.poll() is None:
            proc.send_signal(sig)
        rc = proc.wait(timeout=600)
        seen[_check(rc, sig, given, target, before, err.read_text())] += 1
        print(f"case {k}: {signal.Signals(sig).name} at {at:.2f} s (commit at {t_commit:.2f} s undisturbed): exit {rc}")
    return seen


@pytest.mark.slow  # 20 runs of bench identify --write, ~3 min
def test_identify_signals_at_random_moments(tmp_path: Path) -> None:
    seen = _sweep(tmp_path, ["identify", "--rig", "{rig}", "--out", "{tmp}/runs", "--write"], MOCK_REAL, 20, 1)
    assert seen["kept"] >= 5  # (which moments write depends on the machine's speed; each is checked)


@pytest.mark.slow  # 20 runs of bench commission, ~6 min
def test_commission_signals_at_random_moments(tmp_path: Path) -> None:
    seen = _sweep(tmp_path, ["commission", "--rig", "{rig}", "--out", "{tmp}/report", "--standstill-only"], GO_RIG,
                  20, 2)  # fmt: skip
    assert seen["kept"] >= 5


# --- links, a file changed meanwhile, two writers ---------------------------------------------------------------
def _thesis(scale: float) -> dict[str, dict[str, float | list[float]]]:
    m = MotorParams().as_dict()
    return {n: {"value": m[n] * scale, "ci95": [0.999 * m[n] * scale, 1.001 * m[n] * scale]} for n in rigfile.NAMES}


def test_a_symbolic_link_stays_a_link(tmp_path: Path) -> None:
    """The link's target is replaced in the target's folder (its backup beside it); the link stays a link."""
    given, target = _lab(tmp_path, link=True)
    before = target.read_bytes()
    w = rigfile.write_motor(given, _thesis(1.01))
    assert given.is_symlink() and os.readlink(given) == str(Path("..") / "lab" / "real.toml")
    assert w["target"] == str(target.resolve()) and Path(w["backup"]).read_bytes() == before
    assert _check(0, signal.SIGINT, given, target, before, "") == "written"
    assert load_rig(str(given)).motor.R_s == pytest.approx(5.0 * 1.01)


def test_a_file_changed_since_the_run_read_it_is_not_written(tmp_path: Path) -> None:
    given, target = _lab(tmp_path)
    snap = rigfile_write.Snapshot.read(given)
    target.write_text(MOCK_REAL + "# edited by hand while the test ran\n")
    edited = target.read_bytes()
    with pytest.raises(BadInput, match="rig file changed since this run read it"):
        rigfile.write_motor(given, _thesis(1.01), read=snap)
    assert target.read_bytes() == edited and sorted(p.name for p in target.parent.iterdir()) == [target.name]


WRITER = """
import sys, time
from pathlib import Path
from bench.core import rigfile_write
from bench.workflows.commission import rigfile
from bench.errors import BadInput
from bench.params import MotorParams
rig, scale, go = sys.argv[1], float(sys.argv[2]), Path(sys.argv[4])
rigfile_write.LOCK_WAIT = float(sys.argv[3])
snap = rigfile_write.Snapshot.read(rig)
print("read", flush=True)
while not go.exists():
    time.sleep(0.01)
m = MotorParams().as_dict()
th = {n: {"value": m[n] * scale, "ci95": [0.999 * m[n] * scale, 1.001 * m[n] * scale]} for n in rigfile.NAMES}
try:
    rigfile.write_motor(rig, th, read=snap)
except BadInput as exc:
    print(f"bench: error: {exc}", file=sys.stderr)
    sys.exit(1)
"""


def _writer(tmp: Path, name: str, rig: Path, scale: float, wait: float, go: Path,
            pause: str | None = None) -> tuple[subprocess.Popen, Path, Path]:  # fmt: skip
    """A process that reads ``rig``, then (once ``go`` exists) writes [motor] x ``scale`` into it."""
    out, err = tmp / f"{name}.out", tmp / f"{name}.err"
    env = {**os.environ}
    env.pop("BENCH_TEST_PAUSE", None)
    if pause:
        env["BENCH_TEST_PAUSE"] = pause
    with open(out, "wb") as o, open(err, "wb") as e:
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(rig), str(scale), str(wait), str(go)], cwd=ROOT,
                                stdout=o, stderr=e, env=env)  # fmt: skip
    return proc, out, err


def test_two_writers_are_serialised_and_the_later_one_is_refused(tmp_path: Path) -> None:
    """Both read the file; A locks it and holds it 2 s before its commit; B waits for the lock, then finds the
    file changed since it read it: refused in one line, exit 1. A's file stands, one backup (the original)."""
    given, target = _lab(tmp_path, link=True)
    before = target.read_bytes()
    go_a, go_b = tmp_path / "go_a", tmp_path / "go_b"
    go_a.touch()
    b, b_out, b_err = _writer(tmp_path, "b", given, 1.02, 10.0, go_b)
    _wait_for(b_out, "read", b)
    a, _, a_err = _writer(tmp_path, "a", given, 1.01, 10.0, go_a, pause="rigfile-locked:2")
    _wait_for(a_err, "bench: test pause: rigfile-locked", a)
    go_b.touch()
    assert a.wait(timeout=60) == 0, a_err.read_text()
    assert b.wait(timeout=60) == 1
    line = b_err.read_text().strip()
    assert len(line.splitlines()) == 1 and "rig file changed since this run read it" in line, line
    assert _check(0, signal.SIGINT, given, target, before, "") == "written"
    assert load_rig(str(given)).motor.R_s == pytest.approx(5.0 * 1.01)


def test_a_writer_held_up_too_long_names_the_holder(tmp_path: Path) -> None:
    """A holds the lock for 4 s; B, waiting at most 0.5 s, is refused naming A's PID; then A writes."""
    given, target = _lab(tmp_path)
    before = target.read_bytes()
    go = tmp_path / "go"
    go.touch()
    a, _, a_err = _writer(tmp_path, "a", given, 1.01, 10.0, go, pause="rigfile-locked:4")
    _wait_for(a_err, "bench: test pause: rigfile-locked", a)
    b, _, b_err = _writer(tmp_path, "b", given, 1.02, 0.5, go)
    assert b.wait(timeout=60) == 1
    line = b_err.read_text().strip()
    assert len(line.splitlines()) == 1 and f"is being written by PID {a.pid} (" in line, line
    assert a.wait(timeout=60) == 0, a_err.read_text()
    assert _check(0, signal.SIGINT, given, target, before, "") == "written"
    assert load_rig(str(given)).motor.R_s == pytest.approx(5.0 * 1.01)


@pytest.mark.slow  # two bench identify --write at once, ~15 s on 2 cores
def test_two_identify_writes_at_once(tmp_path: Path) -> None:
    """Two `bench identify --write` of one rig file started together (seeds 0 and 1): one writes (exit 0),
    the other is refused (exit 1, "changed since this run read it"); never a lost update without a message."""
    given, target = _lab(tmp_path)
    before = target.read_bytes()
    procs = []
    for seed in (0, 1):
        d = tmp_path / f"w{seed}"
        d.mkdir()
        procs.append(_start(d, [*_identify(given, d), "--seed", str(seed)]))
    codes = sorted(p.wait(timeout=300) for p, _, _ in procs)
    assert codes == [0, 1]
    loser = next(err for p, _, err in procs if p.returncode == 1).read_text()
    assert "rig file changed since this run read it" in loser
    assert _check(0, signal.SIGINT, given, target, before, "") == "written"
