"""Whether numba's cache holds the compiled engines of these sources, and filling it in the background.

The compiled engines (the plant `mock_hw.compiled`, the FOC tick `bench.controllers.foc_compiled` with its parts,
the batch loop `bench.batch.kernel`) compile into numba's on-disk cache the first time they are imported after an
install or an update: about a minute on a 2-core machine, during which a run would sit silent before its first
tick. So a run takes them by default only when the cache is known to be warm (`is_warm`: a marker in numba's cache
directory, written after every one of them compiled, keyed to the sources' hash `bench.core.jit_cache.family_stamp`
and numba's version); otherwise it runs on the Python engines, which give the same results to the last bit, and
`warm_in_background` compiles them in a process of its own (`bench.batch.warmup`, nice 19, one at a time) for the
next run. ``python3 -m bench.batch.warmup`` does the same in the foreground, with a message.

Hand-written because numba's cache answers "is this compiled?" only by loading it, which is the slow part.
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib
import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path

from bench.core.jit_cache import family_stamp

def _cache_dir() -> Path:
    """Where the marker lives: numba's cache directory if one is set, else beside the sources as numba's own
    in-tree cache (``__pycache__``), else the user's cache directory."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent / "__pycache__"
    if os.access(here if here.exists() else here.parent, os.W_OK):
        return here
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "imbench"


def marker() -> Path:
    """The marker file for this version of the sources and this numba, in the cache directory it speaks of (a copy
    of the directory is as warm as the original)."""
    try:
        numba = importlib.metadata.version("numba")
    except importlib.metadata.PackageNotFoundError:
        numba = "none"
    key = hashlib.sha256(f"{family_stamp()}|{numba}".encode()).hexdigest()  # (its folder says which cache)
    return _cache_dir() / f"imbench-jit-warm-{key[:20]}"


def is_warm() -> bool:
    """True when every compiled engine of these sources has been compiled into the cache (loads in ~1 s)."""
    try:
        return marker().exists()
    except OSError:
        return False


def warming() -> bool:
    """True while a warm-up process holds the lock."""
    try:
        with open(marker().with_suffix(".lock"), "a") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            fcntl.flock(lock, fcntl.LOCK_UN)
    except OSError:
        return False
    return False


def warm_in_background() -> bool:
    """Start ``python3 -m bench.batch.warmup --quiet`` detached at nice 19 (its own session: a Ctrl-C of the run does
    not reach it), unless one is already at work. Returns True if one was started."""
    if warming():
        return False
    try:
        subprocess.Popen([sys.executable, "-m", "bench.batch.warmup", "--quiet"], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                         preexec_fn=lambda: os.nice(19))  # fmt: skip
    except OSError:
        return False
    return True
