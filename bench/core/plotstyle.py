"""One look for every figure the bench writes (run plots, thesis reproductions, reports).

Speeds are electrical angular speeds everywhere in imbench (DESIGN: omega_r is electrical); every
axis says so the same way. Figure sizes are capped so that a wide grid of panels stays readable.
"""

from __future__ import annotations

SPEED_UNIT = "rad/s, electrical"
DPI = 110
MAX_WIDTH_IN = 14.0  # [in] 1540 px at DPI
MIN_HEIGHT_IN = 4.0


def speed_label(what: str = "speed") -> str:
    """``speed [rad/s, electrical]``: the one way an axis of omega_r says its unit."""
    return f"{what} [{SPEED_UNIT}]"


def grid_figsize(rows: int, cols: int, col_w: float = 6.5, row_h: float = 2.9) -> tuple[float, float]:
    """A figure size for rows x cols panels, no wider than MAX_WIDTH_IN and not a thin strip."""
    return min(col_w * cols, MAX_WIDTH_IN), max(row_h * rows + 0.6, MIN_HEIGHT_IN)


def pyplot():  # noqa: ANN201
    """matplotlib.pyplot on the file-only Agg backend (no display at the rig or in CI)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, png):  # noqa: ANN001, ANN201
    """Tight layout, ``png`` at `DPI`, the figure closed; returns ``png``."""
    fig.tight_layout()
    fig.savefig(png, dpi=DPI)
    pyplot().close(fig)
    return png
