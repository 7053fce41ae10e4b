"""Synthesised controllers as versioned plain files: NAME.npz (matrices) + NAME.json (metadata). No pickle.

The npz holds the LFT controller matrix (5.57) and the scheduling data of (5.36) (P, U and the
eigenvalues of N on U); complex arrays are stored as complex128, which `np.load(..., allow_pickle=False)`
reads. The JSON holds the format version, channel sizes, sampling period, γ (and γ_a), model
parameters, solver and settings, the verification report, the creation date and the SHA-256 of the npz.
`load_controller` refuses unknown major versions and a mismatching checksum.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.construct import ScheduledController, Scheduling
from synthesis.lft import LFTController

__all__ = ["FORMAT", "FORMAT_VERSION", "save_controller", "load_controller", "ArtifactError"]

FORMAT = "imbench.lpv_controller"
FORMAT_VERSION = "1.0"


class ArtifactError(ValueError):
    """An artifact is missing, of an unknown version, or corrupt."""


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, complex):
        return {"re": x.real, "im": x.imag}
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


def save_controller(path: str | Path, ctrl: ScheduledController, meta: dict | None = None) -> tuple[Path, Path]:
    """Write PATH.npz and PATH.json (PATH without suffix); returns both paths.

    `meta` is merged into the JSON (e.g. model parameters, γ_a, solver settings, verification).
    """
    base = Path(path)
    if base.suffix in (".npz", ".json"):
        base = base.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    npz, js = base.with_suffix(".npz"), base.with_suffix(".json")
    K, S = ctrl.K, ctrl.scheduling
    np.savez(npz, K_M=K.M, sched_P=S.P, sched_U=S.U, sched_lam=S.lam)
    digest = hashlib.sha256(npz.read_bytes()).hexdigest()
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "npz": npz.name,
        "npz_sha256": digest,
        "sizes": dict(n_c=K.n_c, n_u=K.n_u, n_zc=K.n_zc, n_y=K.n_y, n_wc=K.n_wc, n_wu=S.n_wu, n_zu=S.n_zu),
        "dt": K.dt,
        "complex": bool(np.iscomplexobj(K.M)),
        "gamma": ctrl.gamma,
        "construction": _jsonable(ctrl.info),
        "meta": _jsonable(meta or {}),
    }
    js.write_text(json.dumps(doc, indent=2, sort_keys=True))
    return npz, js


def load_controller(path: str | Path) -> tuple[ScheduledController, dict]:
    """Read an artifact written by `save_controller`; returns (controller, JSON document)."""
    base = Path(path)
    if base.suffix in (".npz", ".json"):
        base = base.with_suffix("")
    js = base.with_suffix(".json")
    if not js.exists():
        raise ArtifactError(f"{js} not found")
    doc = json.loads(js.read_text())
    if doc.get("format") != FORMAT:
        raise ArtifactError(f"{js}: not an {FORMAT} file")
    major = str(doc.get("format_version", "")).split(".")[0]
    if major != FORMAT_VERSION.split(".")[0]:
        raise ArtifactError(f"{js}: format version {doc.get('format_version')} not supported ({FORMAT_VERSION})")
    npz = js.with_name(doc["npz"])
    if hashlib.sha256(npz.read_bytes()).hexdigest() != doc["npz_sha256"]:
        raise ArtifactError(f"{npz}: checksum mismatch")
    with np.load(npz, allow_pickle=False) as z:
        arrs = {k: np.array(z[k]) for k in z.files}
    s = doc["sizes"]
    K = LFTController(arrs["K_M"], s["n_c"], s["n_u"], s["n_zc"], s["n_y"], s["n_wc"], doc["dt"])
    sched = Scheduling(arrs["sched_P"], arrs["sched_U"], arrs["sched_lam"], s["n_wu"], s["n_zu"])
    return ScheduledController(K, sched, float(doc["gamma"]), dict(doc.get("construction", {}))), doc
