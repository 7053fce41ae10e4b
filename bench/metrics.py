"""Estimation errors against the mock rig's ground truth: flux magnitude and angle, estimated speed.

One definition, used by the session summary (``estimation_errors`` in summary.json and every sweep
row) and by the observer reproductions (`bench.reproductions.common.errors`). Ground truth exists
only on rigs that log ``/truth`` (the mock plant and the emulators).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

__all__ = ["estimation_errors"]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _max_abs(x: np.ndarray) -> float:
    return float(np.max(np.abs(x))) if x.size else math.nan


def estimation_errors(t: np.ndarray, ctrl: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray],
                      omega_ref: np.ndarray, t_from: float, trip_t: float | None = None) -> dict[str, float | bool]:  # fmt: skip
    """Errors over loop times ``t >= t_from`` and before ``trip_t`` (if any).

    Flux magnitude: |i_m_hat| - |i_m| [A], also relative to the mean true |i_m|; flux angle:
    angle(i_m_hat) - angle(i_m) [deg], wrapped to (-180, 180]; speed: the estimator's output
    (``omega_est`` where a speed estimator runs, else the controller's ``omega_hat``) minus the true
    omega_r [rad/s]; tracking: omega_r_ref - omega_r [rad/s]. NaN where no sample is left.
    """
    ok = t >= t_from
    if trip_t is not None:
        ok &= t < trip_t
    im_true = truth["i_m_re"] + 1j * truth["i_m_im"]
    im_hat = ctrl["i_m_hat_re"] + 1j * ctrl["i_m_hat_im"]
    e_mag = (np.abs(im_hat) - np.abs(im_true))[ok]
    e_ang = np.degrees(np.angle(np.exp(1j * (np.angle(im_hat) - np.angle(im_true)))))[ok]
    w_est = ctrl["omega_est"] if "omega_est" in ctrl else ctrl["omega_hat"]
    e_w = (w_est - truth["omega_r"])[ok]
    e_track = (omega_ref - truth["omega_r"])[ok]
    mean_im = float(np.mean(np.abs(im_true)[ok])) if ok.any() else math.nan
    return {
        "flux_mag_rms_A": _rms(e_mag), "flux_mag_max_A": _max_abs(e_mag),
        "flux_mag_rms_rel": _rms(e_mag) / mean_im if mean_im > 0 else math.nan,
        "flux_angle_rms_deg": _rms(e_ang), "flux_angle_max_deg": _max_abs(e_ang),
        "speed_rms": _rms(e_w), "speed_max": _max_abs(e_w),
        "tracking_rms": _rms(e_track), "tripped": trip_t is not None,
    }  # fmt: skip
