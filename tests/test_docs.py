"""The docs' examples run as written."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_python_example_on_the_first_page_runs(tmp_path):
    text = (ROOT / "docs" / "index.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    rms, omega_end = (float(v) for v in p.stdout.split())
    assert 0 < rms < 3.0 and abs(omega_end - 10.0) < 2.0  # Fig. 5.7: 10 rad/s, settled error ~1.3 rad/s rms


def test_every_docs_page_is_in_the_site_navigation():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = {str(p.relative_to(ROOT / "docs")) for p in (ROOT / "docs").glob("*.md")}
    pages |= {str(p.relative_to(ROOT / "docs")) for p in (ROOT / "docs" / "results").glob("*.md")}
    assert pages and all(name in nav for name in pages), pages



def test_the_controllers_page_is_what_the_schema_says():
    """docs/controllers.md is generated; regenerate it with `bench controllers --markdown > docs/controllers.md`."""
    from bench.controllers import available
    from bench.controllers.schema import markdown

    assert (ROOT / "docs" / "controllers.md").read_text() == markdown(dict(sorted(available().items())))
