"""Code version stamp for run metadata: package version plus ``git describe`` when available."""

from __future__ import annotations

import functools
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["code_version"]

_REPO = Path(__file__).resolve().parents[2]


def _package_version() -> str:
    try:
        return version("imbench")
    except PackageNotFoundError:
        pass
    try:  # running from a source tree that is not installed
        import tomllib

        with open(_REPO / "pyproject.toml", "rb") as f:
            return str(tomllib.load(f)["project"]["version"])
    except (OSError, KeyError, ValueError):
        return "0+unknown"


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """``"0.1.0"`` or ``"0.1.0+git.<describe>"``, e.g. ``0.1.0+git.3f2a9c1-dirty``.

    Never fails: without git, outside a work tree or in a repository without commits the
    git part is simply left off.
    """
    v = _package_version()
    try:
        out = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=_REPO,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return v
    describe = out.stdout.strip()
    if out.returncode != 0 or not describe:
        return v
    return f"{v}+git.{describe}"
