"""Synthesised controllers (and other designs) as versioned plain files: NAME.npz + NAME.json. No pickle.

`write_artifact`/`read_artifact` are the generic pair (format name, version, SHA-256 of the npz); the
NARX model artifact of `synthesis.narx` uses them too.

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
from typing import TYPE_CHECKING, Any

import numpy as np

from synthesis.construct import ScheduledController, Scheduling
from synthesis.lft import LFTController

if TYPE_CHECKING:  # construct pulls in cvxpy; model artifacts (synthesis.narx) do not need it
    from synthesis.construct import ScheduledController

__all__ = ["FORMAT", "FORMAT_VERSION", "save_controller", "load_controller", "ArtifactError", "write_artifact",
           "read_artifact"]

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


def _base(path: str | Path) -> Path:
    base = Path(path)
    return base.with_suffix("") if base.suffix in (".npz", ".json") else base


def write_artifact(path: str | Path, fmt: str, version: str, arrays: dict[str, np.ndarray],
                   doc: dict[str, Any]) -> tuple[Path, Path]:  # fmt: skip
    """Write PATH.npz (``arrays``) and PATH.json (``doc`` plus format, version, date, npz name and SHA-256)."""
    base = _base(path)
    base.parent.mkdir(parents=True, exist_ok=True)
    npz, js = base.with_suffix(".npz"), base.with_suffix(".json")
    np.savez(npz, **arrays)
    head = {
        "format": fmt,
        "format_version": version,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "npz": npz.name,
        "npz_sha256": hashlib.sha256(npz.read_bytes()).hexdigest(),
    }
    js.write_text(json.dumps(_jsonable({**head, **doc}), indent=2, sort_keys=True))
    return npz, js


def read_artifact(path: str | Path, fmt: str, version: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read PATH.json + PATH.npz written by `write_artifact`; refuses another format, another major
    version and a checksum mismatch (`ArtifactError`). Never unpickles."""
    js = _base(path).with_suffix(".json")
    if not js.exists():
        raise ArtifactError(f"{js} not found")
    doc = json.loads(js.read_text())
    if doc.get("format") != fmt:
        raise ArtifactError(f"{js}: not an {fmt} file")
    major = str(doc.get("format_version", "")).split(".")[0]
    if major != version.split(".")[0]:
        raise ArtifactError(f"{js}: format version {doc.get('format_version')} not supported ({version})")
    npz = js.with_name(doc["npz"])
    if not npz.exists() or hashlib.sha256(npz.read_bytes()).hexdigest() != doc["npz_sha256"]:
        raise ArtifactError(f"{npz}: missing or checksum mismatch")
    with np.load(npz, allow_pickle=False) as z:
        arrs = {k: np.array(z[k]) for k in z.files}
    return arrs, doc


def save_controller(path: str | Path, ctrl: ScheduledController, meta: dict | None = None) -> tuple[Path, Path]:
    """Write PATH.npz and PATH.json (PATH without suffix); returns both paths.

    `meta` is merged into the JSON (e.g. model parameters, γ_a, solver settings, verification).
    """
    K, S = ctrl.K, ctrl.scheduling
    doc = {
        "sizes": dict(n_c=K.n_c, n_u=K.n_u, n_zc=K.n_zc, n_y=K.n_y, n_wc=K.n_wc, n_wu=S.n_wu, n_zu=S.n_zu),
        "dt": K.dt,
        "complex": bool(np.iscomplexobj(K.M)),
        "gamma": ctrl.gamma,
        "construction": _jsonable(ctrl.info),
        "meta": _jsonable(meta or {}),
    }
    arrays = {"K_M": K.M, "sched_P": S.P, "sched_U": S.U, "sched_lam": S.lam}
    return write_artifact(path, FORMAT, FORMAT_VERSION, arrays, doc)


def load_controller(path: str | Path) -> tuple[ScheduledController, dict]:
    """Read an artifact written by `save_controller`; returns (controller, JSON document)."""

    arrs, doc = read_artifact(path, FORMAT, FORMAT_VERSION)
    s = doc["sizes"]
    K = LFTController(arrs["K_M"], s["n_c"], s["n_u"], s["n_zc"], s["n_y"], s["n_wc"], doc["dt"])
    sched = Scheduling(arrs["sched_P"], arrs["sched_U"], arrs["sched_lam"], s["n_wu"], s["n_zu"])
    return ScheduledController(K, sched, float(doc["gamma"]), dict(doc.get("construction", {}))), doc


MOTOR_KEYS = ("L_s", "L_r", "L_m", "R_s", "R_r")


def motor_mismatch(meta: dict, motor: Any, rel_tol: float = 1e-9) -> list[str]:
    """Names of the electrical motor parameters in which ``meta["motor"]`` (an artifact's design data)
    differs from ``motor`` (any object with attributes L_s, L_r, L_m, R_s, R_r); missing ones count."""
    import math

    design = meta.get("motor", {})
    return [k for k in MOTOR_KEYS
            if not math.isclose(float(design.get(k, math.nan)), float(getattr(motor, k)), rel_tol=rel_tol)]  # fmt: skip

