"""The README's command blocks run as written, in order, in a fresh folder: "Run and look" (each
command's output is the next one's input: the --log run, then `bench plot` of that log) and the
identification chain collect -> train -> synth -> run."""

from __future__ import annotations

import re
import json
import shlex
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def readme_block(title: str) -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    block = re.search(re.escape(title) + r".*?```sh\n(.*?)```", text, flags=re.S)
    assert block, title
    cmds = []
    for line in block.group(1).splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            cmds.append(shlex.split(line))
    return cmds


def test_the_chain_block_is_found_and_starts_with_collect():
    cmds = readme_block("**From data to an LPV speed controller**")
    assert [c[:3] for c in cmds[:3]] == [["bench", "collect", "narx"]] * 2 + [["bench", "train", "narx"]]


@pytest.mark.slow
def test_readme_identification_chain_runs_as_written(tmp_path):
    for cmd in readme_block("**From data to an LPV speed controller**"):
        assert cmd[0] == "bench"
        args = cmd[1:] + (["--no-progress"] if cmd[1] in ("run", "collect") else [])
        p = subprocess.run([sys.executable, "-m", "bench", *args], cwd=tmp_path, capture_output=True, text=True,
                           timeout=900)  # fmt: skip
        assert p.returncode == 0, (cmd, p.stderr[-2000:])
    assert (tmp_path / "runs" / "sc.npz").exists()


def test_the_run_and_look_block_is_found():
    cmds = readme_block("**Run and look**")
    assert ["bench", "plot", "runs/fig58.mcap"] in cmds and any("--live" in c for c in cmds)


@pytest.mark.slow
@pytest.mark.realtime  # its --live run is paced by the wall clock
def test_readme_run_and_look_runs_in_order(tmp_path):
    """Every command of "Run and look" in order. The --live run goes to the background (on a free port
    rather than 8765, which another test on this machine may hold), `bench set` tunes it, and `bench
    stop` (the README's "bench stop ends it") ends it normally, after `bench switch`."""
    port = str(free_port())
    live = None
    try:
        for cmd in readme_block("**Run and look**"):
            assert cmd[0] == "bench"
            args = cmd[1:] + (["--no-progress"] if cmd[1] == "run" else [])
            if "--live" in args:
                args += ["--live-port", port]
                live = subprocess.Popen([sys.executable, "-m", "bench", *args], cwd=tmp_path, text=True,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
                line = live.stderr.readline()
                assert "bench: live: ws://" in line, line
                continue
            if cmd[1] in ("set", "switch"):
                args += ["--port", port]
            p = subprocess.run([sys.executable, "-m", "bench", *args], cwd=tmp_path, capture_output=True, text=True,
                               timeout=300)  # fmt: skip
            assert p.returncode == 0, (cmd, p.stderr[-2000:])
            if cmd[1] == "set":
                assert "speed_Kp: 0.6 -> 0.8" in p.stdout, p.stdout
            if cmd[1] == "switch":  # the live run's last request: then the stop the README names ends it
                assert "speed_controller -> lpv at tick" in p.stdout, p.stdout
                stop = subprocess.run([sys.executable, "-m", "bench", "stop", "--port", port], cwd=tmp_path,
                                      capture_output=True, text=True, timeout=60)  # fmt: skip
                assert stop.returncode == 0, stop.stderr
                out, err = live.communicate(timeout=60)
                assert live.returncode == 0, err[-2000:]
                assert json.loads(out)["duration"] < 30  # ended by the stop, not by its 60 s
            if cmd[1] == "plot":  # the --log run wrote runs/fig58.png; the plot is a second one beside it
                assert p.stdout.strip() == str(Path("runs") / "fig58-2.png")
                assert (tmp_path / "runs" / "fig58.png").exists() and (tmp_path / "runs" / "fig58-2.png").exists()
    finally:
        if live is not None and live.poll() is None:
            live.kill()
            live.wait()
    folders = [f.name for f in (tmp_path / "runs").iterdir() if f.is_dir()]
    assert any("speed_Kp=0.3-current_wc=800" in f for f in folders), folders
    assert any("observer=lpv" in f for f in folders) and any("speed_controller=lpv" in f for f in folders), folders


@pytest.mark.slow
def test_readme_commission_block_runs_as_written(tmp_path):
    """"Commission a motor": the rig file copied, both identifications, `bench commission` (the rotating test too:
    the mock's shaft turns) GO and the rig file written (the accuracy benchmark over 20 motors is left out:
    minutes)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(re.escape("**Commission a motor**") + r".*?```sh\n(.*?)```", text, flags=re.S).group(1)
    (tmp_path / "rigs").mkdir()
    (tmp_path / "rigs" / "mock-real.toml").write_text((ROOT / "rigs" / "mock-real.toml").read_text())
    ran = 0
    for line in block.splitlines():
        cmd = line.split("#", 1)[0].strip()
        if not cmd or "perf identify" in cmd:
            continue
        cmd = cmd.replace("bench ", f"{shlex.quote(sys.executable)} -m bench ")
        p = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, (cmd, p.stderr[-2000:])
        ran += 1
    assert ran == 4
    assert json.loads((tmp_path / "runs" / "commission" / "commission.json").read_text())["go"]
    assert list((tmp_path / "runs").glob("lab.toml.*.bak"))
