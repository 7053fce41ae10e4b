"""`bench calibrate` replaces its rig file as `bench identify --write` does (bench.core.rigfile_write): real
subprocesses and real signals on an emulated rig (in-process emulators whose front-end has ADC offsets), the checks of
tests/test_rigfile_write.py: 128 + the signal - the file byte for byte, nothing beside it; 0 - the new file
complete, its backup the original, a symbolic link still a link."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
import tomlkit

from bench.core.config import load as load_rig
from mock_hw.emulators.testing import emulated_data
from tests.test_rigfile_write import _check, _lab, _start, _sweep, _wait_for

OFFSETS_I, OFFSETS_U = [0.01, -0.02, 0.005], [-0.03, 0.0, 0.02]
CAL_RIG = tomlkit.dumps(emulated_data("virtual", mock={"currents": {"offset": OFFSETS_I},
                                                       "voltages": {"offset": OFFSETS_U}}))  # fmt: skip


def _calibrate(given: Path, samples: int = 600) -> list[str]:
    return ["calibrate", "--rig", str(given), "--samples", str(samples)]


@pytest.mark.parametrize("point, sig, code", [
    ("calibrate-measuring", signal.SIGTERM, 143),  # the rig made safe and closed, nothing written
    ("rigfile-locked", signal.SIGINT, 130),  # the last moment before the commit section
    ("rigfile-commit", signal.SIGHUP, 0),  # inside it, before the rename: deferred, the commit goes through
    ("rigfile-committed", signal.SIGINT, 0),  # after it
])  # fmt: skip
def test_calibrate_signal_around_the_commit_point(tmp_path: Path, point: str, sig: int, code: int) -> None:
    given, target = _lab(tmp_path, CAL_RIG, link=True)
    before = target.read_bytes()
    proc, out, err = _start(tmp_path, _calibrate(given), pause=f"{point}:2")
    _wait_for(err, f"bench: test pause: {point}", proc)
    proc.send_signal(sig)
    rc = proc.wait(timeout=120)
    text = err.read_text()
    assert rc == code, text[-3000:]
    assert _check(rc, sig, given, target, before, text) == ("written" if code == 0 else "kept")
    assert "Traceback" not in text and "race condition" not in text
    if code == 0:
        assert f"bench: {signal.Signals(sig).name} arrived after {given} was replaced" in text.splitlines()[-1]
        res = json.loads(out.read_text())
        w = res["written"]
        assert w["rig_file"] == str(given) and w["target"] == str(target.resolve())
        assert Path(w["backup"]).parent == target.parent.resolve()
        fe = load_rig(str(given)).hw["frontend"]  # what was measured is what the file holds (6 digits)
        assert fe["offset_i"] == pytest.approx(res["offset_i"], rel=1e-5)
        assert fe["offset_i"] == pytest.approx(OFFSETS_I, abs=2e-3)
    else:
        assert text.splitlines()[-1].startswith("bench: interrupted"), text[-2000:]
        assert out.read_text() == ""  # no result printed: nothing was written


def test_a_file_edited_during_calibration_is_not_overwritten(tmp_path: Path) -> None:
    """Edited by hand while the offsets are measured: the measurement is printed, the write refused in one line,
    exit 1, the edit kept and nothing beside it."""
    given, target = _lab(tmp_path, CAL_RIG)
    proc, out, err = _start(tmp_path, _calibrate(given), pause="calibrate-measuring:1")
    _wait_for(err, "bench: test pause: calibrate-measuring", proc)
    target.write_text(CAL_RIG + "# edited by hand during the calibration\n")
    edited = target.read_bytes()
    rc = proc.wait(timeout=120)
    lines = [ln for ln in err.read_text().splitlines() if not ln.startswith("bench: test pause")]
    assert rc == 1 and len(lines) == 1, lines
    assert lines[0].startswith("bench: --rig: not written: rig file changed since this run read it")
    res = json.loads(out.read_text())
    assert res["written"] is None and res["offset_i"] == pytest.approx(OFFSETS_I, abs=2e-3)
    assert target.read_bytes() == edited and sorted(p.name for p in target.parent.iterdir()) == [target.name]


def test_a_shipped_or_unwritable_rig_file_is_refused_before_measuring(tmp_path: Path) -> None:
    from tests.test_emulators import bench

    p = bench("calibrate", "--rig", "emulated")
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.strip() == ("bench: error: --rig: rigs/emulated.toml is a rig file shipped with imbench; copy it "
                                "and give the copy (cp rigs/emulated.toml runs/lab.toml)")  # fmt: skip
    if os.geteuid() != 0:  # (root writes anyway)
        given, target = _lab(tmp_path, CAL_RIG)
        target.parent.chmod(0o500)
        try:
            p = bench("calibrate", "--rig", str(given))
        finally:
            target.parent.chmod(0o700)
        assert p.returncode == 2 and "cannot write" in p.stderr and p.stdout == ""


@pytest.mark.slow  # 12 runs of bench calibrate, ~1 min on 2 busy cores
def test_calibrate_signals_at_random_moments(tmp_path: Path) -> None:
    seen = _sweep(tmp_path, ["calibrate", "--rig", "{rig}", "--samples", "3000"], CAL_RIG, 12, 3)
    assert seen["kept"] >= 3  # (which moments write depends on the machine's speed; each is checked)


def test_only_the_shipped_rig_files_are_refused_in_the_rigs_folder(tmp_path: Path, monkeypatch) -> None:
    """`SHIPPED` is the source tree's rigs/*.toml; a user's own file beside them (docs/at-the-rig.md's
    rigs/mylab.toml) is theirs to write."""
    import shutil
    import subprocess

    from bench.core import config

    from bench.core import rigfile_write
    from bench.errors import BadInput
    from bench.core.rigfile_write import SHIPPED, check_writable

    if shutil.which("git") is None or not (config.RIGS_DIR.parent / ".git").exists():
        pytest.skip("not a git checkout")
    tracked = subprocess.run(["git", "ls-files", "rigs/*.toml"], capture_output=True, text=True,
                             cwd=config.RIGS_DIR.parent, check=True).stdout.split()  # fmt: skip
    assert sorted(Path(t).stem for t in tracked) == sorted(SHIPPED)
    rigs = tmp_path / "rigs"  # a copy of the folder, with a user's own file in it
    shutil.copytree(config.RIGS_DIR, rigs)
    (rigs / "mylab.toml").write_text(CAL_RIG)
    monkeypatch.setattr(rigfile_write, "RIGS_DIR", rigs)  # the shipped rigs' folder, where check_writable reads it
    for name in SHIPPED:
        with pytest.raises(BadInput, match="shipped with imbench"):
            check_writable(rigs / f"{name}.toml", "--rig")
    check_writable(rigs / "mylab.toml", "--rig")  # no refusal
