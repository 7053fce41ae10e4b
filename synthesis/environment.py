"""What a number was computed with: Python, the numerical packages' versions and the BLAS kernel in use.

Designs and benchmarks record it next to their results: the same code can give another verdict under another
BLAS kernel (OpenBLAS picks one per CPU; OPENBLAS_CORETYPE overrides it) or another release of the stack.
"""

from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version
from typing import Any

__all__ = ["PACKAGES", "blas_info", "environment"]

#: the packages whose release can change a number
PACKAGES: tuple[str, ...] = ("numpy", "scipy", "cvxpy", "clarabel", "numba", "torch")


def blas_info() -> list[dict[str, Any]]:
    """The BLAS libraries numpy and scipy loaded and the kernel each chose (threadpoolctl, where installed)."""
    try:
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS)
        from threadpoolctl import threadpool_info
    except ImportError:
        return []
    return [{"api": i.get("internal_api"), "kernel": i.get("architecture"), "version": i.get("version")}
            for i in threadpool_info()]  # fmt: skip


def environment() -> dict[str, Any]:
    """{"python": ..., "packages": {name: version or None}, "blas": `blas_info()`, "machine": ...}."""
    pk: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            pk[name] = version(name)
        except PackageNotFoundError:
            pk[name] = None
    return {"python": platform.python_version(), "machine": platform.machine(), "packages": pk,
            "blas": blas_info()}  # fmt: skip
