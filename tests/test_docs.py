"""The docs' examples run as written."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


# a ```python block runs unless the line before it says <!-- not run: WHY --> (sparingly: a block that needs
# hardware or a cluster); <!-- run after: COMMAND --> runs a `bench` command first in the same folder
_BLOCK = re.compile(r"(?:<!--\s*(not run|run after:)([^>]*?)\s*-->\n)?```python\n(.*?)```", flags=re.S)
_DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("**/*.md"))]
_LINKED = ("rigs", "sweeps", "examples")  # the docs run from the repository's top folder


def python_blocks() -> list:
    blocks = []
    for page in _DOCS:
        text = page.read_text()
        for m in _BLOCK.finditer(text):
            line = text.count("\n", 0, m.start(3))
            name = f"{page.relative_to(ROOT)}:{line}"
            marks = [pytest.mark.skip(reason=f"marked not run{m.group(2)}")] if m.group(1) == "not run" else []
            after = m.group(2).strip() if m.group(1) == "run after:" else None
            blocks.append(pytest.param(m.group(3), after, id=name, marks=marks))
    return blocks


def test_the_docs_have_python_blocks_and_few_are_skipped():
    blocks = python_blocks()
    skipped = [b for b in blocks if b.marks]
    assert len(blocks) >= 8 and len(skipped) <= 1, [b.id for b in skipped]


@pytest.mark.parametrize(("code", "after"), python_blocks())
def test_every_python_block_of_the_docs_runs_as_a_script(code, after, tmp_path):
    """Saved as a file and run in a fresh process from a new folder (the repository's rig and sweep files
    beside it), as a reader would: no `__main__` guard is added."""
    for name in _LINKED:
        (tmp_path / name).symlink_to(ROOT / name)
    if after:
        cmd = after.split()
        assert cmd[0] == "bench", after
        p = subprocess.run([sys.executable, "-m", "bench", *cmd[1:]], cwd=tmp_path, capture_output=True, text=True,
                           timeout=600)  # fmt: skip
        assert p.returncode == 0, p.stderr[-3000:]
    script = tmp_path / "snippet.py"
    script.write_text(code)
    p = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]


def test_the_first_pages_example_prints_fig_5_7s_numbers(tmp_path):
    text = (ROOT / "docs" / "index.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    (tmp_path / "example.py").write_text(code)
    p = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    rms, omega_end = (float(v) for v in p.stdout.split())
    assert 0 < rms < 3.0 and abs(omega_end - 10.0) < 2.0  # Fig. 5.7: 10 rad/s, settled error ~1.3 rad/s rms


def test_every_docs_page_is_in_the_site_navigation():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = {str(p.relative_to(ROOT / "docs")) for p in (ROOT / "docs").glob("*.md")}
    pages |= {str(p.relative_to(ROOT / "docs")) for p in (ROOT / "docs" / "results").glob("*.md")}
    assert pages and all(name in nav for name in pages), pages


def test_measured_results_are_numbered_in_order_in_the_navigation():
    """The numbered result pages (``# 1. ...``) follow one another in the nav without a gap."""
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = re.findall(r"^\s+- (results/[\w-]+\.md)$", nav, flags=re.M)
    numbers = []
    for page in pages:
        m = re.match(r"# (\d+)\. ", (ROOT / "docs" / page).read_text())
        if m:
            numbers.append(int(m.group(1)))
    assert numbers == list(range(1, len(numbers) + 1)), numbers


def test_code_blocks_are_coloured_and_the_plugin_path_is_the_repositorys():
    import tomllib

    conf = (ROOT / "mkdocs.yml").read_text()
    assert "pymdownx.highlight" in conf and "pymdownx.superfences" in conf
    docs_extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["docs"]
    assert any(d.startswith("pymdown-extensions") for d in docs_extra)
    text = (ROOT / "docs" / "plugins.md").read_text()
    for path in re.findall(r"pip install -e \./(\S+)", text):
        assert (ROOT / path / "pyproject.toml").is_file(), path
    index = (ROOT / "docs" / "index.md").read_text()
    for page in ("commissioning.md", "rr-adaptation.md", "switching.md"):
        assert f"]({page})" in index, page



def test_the_controllers_page_is_what_the_schema_says():
    """docs/controllers.md is generated; regenerate it with `bench controllers --markdown > docs/controllers.md`."""
    from bench.controllers import available
    from bench.controllers.schema import markdown

    assert (ROOT / "docs" / "controllers.md").read_text() == markdown(dict(sorted(available().items())))


def test_the_switching_page_states_the_voltage_jump_window_in_ticks():
    from bench.runtime.metrics import SWITCH_WINDOW_U

    text = " ".join((ROOT / "docs" / "switching.md").read_text().split())
    ms, ticks = SWITCH_WINDOW_U * 1e3, round(SWITCH_WINDOW_U * 3000)
    assert f"in the {ms:g} ms after the switch (the reference is logged every 3 kHz tick: {ticks} ticks" in text
