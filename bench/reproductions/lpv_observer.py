"""`bench reproduce fig5.5 | fig5.6`: the LPV flux observer design figures (thesis 5.6.2).

The synthesis library stays independent of the bench; this module only registers its figure
functions with the `bench reproduce` registry.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench.reproduce import register


@register("fig5.5", "gamma_a of the LPV flux observer versus omega_r,max (10..400 rad/s), 3 kHz")
def fig5_5(out_dir: Path) -> dict[str, Any]:
    from synthesis.reproductions import fig5_5 as run

    return run(out_dir)


@register("fig5.6", "Bode plots at omega_r = 10 rad/s: LPV observer vs JL vs current model")
def fig5_6(out_dir: Path) -> dict[str, Any]:
    from synthesis.reproductions import fig5_6 as run

    return run(out_dir)
