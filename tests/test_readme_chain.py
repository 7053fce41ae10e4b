"""The README's identification chain runs as written (issue 14): collect -> train -> synth -> run."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


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
