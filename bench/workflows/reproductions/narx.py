"""`bench reproduce narx`: the identification chain of thesis 6.4.2-6.4.3 on the mock rig.

Collects the training (seed 1) and validation (seed 2) sets of 22000 samples with `bench collect narx`'s
experiment, trains the ARX and MLP models, transforms the MLP to the quasi-LPV LFT and writes the
validation figures (Figs 6.6-6.11 and the sector plot) into the output folder. The logs and the model
artifact stay in ``runs/narx-reproduce/`` (model: ``runs/narx-reproduce/model.npz/.json``).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from bench.workflows.reproduce import register
from bench.workflows.narx import collect_and_train

WORK_DIR = Path("runs") / "narx-reproduce"


@register("narx", "Figs 6.6-6.11 + sector table: collect train/val sets, ARX + LM-trained MLP, MLP -> LFT (6.3-6.4)")
def narx(out_dir: Path) -> dict[str, Any]:
    import click


    def say(msg: str) -> None:
        click.echo(f"reproduce narx: {msg}", err=True)

    s = collect_and_train(WORK_DIR, progress=say)
    figs = {}
    for name, src in s["figures"].items():
        dst = out_dir / (f"narx-{name}.png" if name in ("sectors", "lm") else f"{name}.png")
        shutil.copyfile(src, dst)
        figs[name] = str(dst)
    doc = json.loads(Path(s["report"]).read_text())
    doc["figures"] = figs
    doc["collect"] = s["collect"]
    doc["training"] = s["training"]
    doc["model"] = s["model"]
    return doc
