"""A run's summary (`bench.runtime.session.run`): what ran and how it ended, the loop's timing and stalls, the log
closed with the summary in it, the numbers read back from the log (the speed and magnetising-current errors, the load
steps' dips and recoveries, the estimation errors, the R_r estimate, the voltage limit, part switches), then
summary.json and the plot written. The batch engine (`bench.batch.engine`) makes the same summary from its
reductions."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from bench.core.config import RigConfig
from bench.daq import LogReader, LogWriterError
from bench.daq.memory import MemoryLog
from bench.daq.reader import internals_topic
from bench.core.outputs import replacing, write_text
from bench.hal import Rig
from bench.runtime.loop import LoopResult
from bench.core.scenarios import T_MAGNETISE, Scenario
from bench.runtime.metrics import estimation_errors, voltage_limit, switch_transients


LOG_CLOSE_TIMEOUT = 30.0  # [s] the writer gets this long to finish the file at shutdown, then is killed


def summary_time(t: float | None) -> float | None:
    """A loop time for summary.json: rounded to 1 us (3.2, not 3.1999999999999997: the sum of 9600 ticks of
    1/3000 s); the log keeps every tick's time in full."""
    return None if t is None else round(float(t), 6)


def stats(x: np.ndarray) -> dict[str, float]:
    if x.size == 0:
        return {}
    return {"rms": float(np.sqrt(np.mean(x**2))), "max_abs": float(np.max(np.abs(x))), "mean": float(np.mean(x))}


def summarize(r: LogReader | MemoryLog, scn: Scenario, torque_constant: float | None = None,
              R_r_true: float | None = None) -> dict[str, Any]:
    """Speed-tracking and load-rejection numbers from the log (true speed where the rig has it); with the
    truth, the estimation errors (`bench.runtime.metrics.estimation_errors`: flux, torque with the nominal
    ``torque_constant``, the R_r estimate against the truth's r_r or the true machine's ``R_r_true``)."""
    tail = tuple(tp for tp in ("/truth", internals_topic(r.topics())) if tp in r.topics())
    meas, *rest = r.read_ticks("/rig", *tail)
    got = dict(zip(tail, rest))
    ctrl = next((v for k, v in got.items() if k != "/truth"), {})  # the controller's internals
    if "/truth" in got:
        truth = got["/truth"]
        omega, source = truth["omega_r"], "truth"
        i_m = np.hypot(truth["i_m_re"], truth["i_m_im"])
    else:
        omega, source, i_m = ctrl.get("omega_hat", np.zeros_like(meas["t"])), "measured", None
    ref = cmd = meas
    t = meas["t"]
    w_ref, m_L = ref["omega_r_ref"], cmd["m_l_ref"]
    e = w_ref - omega
    active = (t >= T_MAGNETISE) & ~meas["tripped"].astype(bool)
    out: dict[str, Any] = {"speed_source": source, "speed_error": stats(e[active])}

    # settled tracking: samples more than 0.2 s after the last reference change
    ref_change = np.flatnonzero(np.diff(w_ref) != 0) + 1
    last_change = np.full(t.shape, -np.inf)
    if ref_change.size:
        idx = np.searchsorted(t[ref_change], t, side="right") - 1
        ok = idx >= 0
        last_change[ok] = t[ref_change][idx[ok]]
    settled = active & (t - last_change > 0.2)
    out["speed_error_settled"] = stats(e[settled])

    # load steps: peak deviation and time to return within 1 rad/s, in the window from each load
    # step to the next one (at most 0.2 s); steps near a reference change are left out
    load_steps = np.flatnonzero(np.abs(np.diff(m_L)) > 0.5) + 1
    peaks, recov = [], []
    for n, i in enumerate(load_steps):
        t_s = t[i]
        t_end = min(t_s + 0.2, t[load_steps[n + 1]] if n + 1 < load_steps.size else np.inf)
        if t_s < T_MAGNETISE or np.any((t[ref_change] > t_s - 0.2) & (t[ref_change] < t_end)):
            continue
        win = (t >= t_s) & (t < t_end) & active
        if not win.any():
            continue
        dev = np.abs(e[win])
        peaks.append(float(dev.max()))
        above = np.flatnonzero(dev > 1.0)
        recov.append(float(t[win][above[-1]] - t_s) if above.size else 0.0)
    out["load_steps"] = {
        "count": len(peaks),
        "peak_deviation_max": max(peaks) if peaks else None,
        "peak_deviation_mean": float(np.mean(peaks)) if peaks else None,
        "recovery_time_1rad_s_mean": float(np.mean(recov)) if recov else None,
    }
    if i_m is not None:
        out["i_mR_error"] = stats((ref["i_mr_ref"] - i_m)[settled])
        if "i_m_hat_re" in ctrl and ("omega_hat" in ctrl or "omega_est" in ctrl):  # a flux observer's estimate

            tripped = meas["tripped"].astype(bool)
            trip_t = float(t[tripped][0]) if tripped.any() else None
            est = estimation_errors(t, ctrl, truth, w_ref, T_MAGNETISE + 0.1, trip_t, torque_constant, R_r_true)
            # null where no sample is left (a trip before the window): summary.json stays standard JSON
            out["estimation_errors"] = {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in est.items()}
    if "u_sat" in ctrl and ("fw" in ctrl or "rr_gate" in ctrl):  # field weakening or the R_r estimate: the limit's part

        tripped = meas["tripped"].astype(bool)
        out["voltage_limit"] = voltage_limit(t, ctrl, T_MAGNETISE, float(t[tripped][0]) if tripped.any() else None)
    events = r.events()
    if events and "omega_mr" in ctrl:  # parts switched while running: the jump each one made

        sw = switch_transients(t, meas["u_s_ref_re"] + 1j * meas["u_s_ref_im"], ctrl["omega_mr"], events,
                               got["/truth"]["m_e"] if "/truth" in got else None)  # fmt: skip
        if sw:  # null where the run ended before a window (summary.json stays standard JSON)
            out["switches"] = [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}
                               for row in sw]  # fmt: skip
    return out


def true_R_r(rig: Rig | None) -> float | None:
    """The simulated machine's R_r [Ohm] (the mock plant's; None on other rigs): what an R_r estimate is
    scored against where the truth has no ``r_r`` (thermal state off: R_r is constant)."""
    params = getattr(getattr(getattr(rig, "truth", None), "motor", None), "params", None)
    R_r = getattr(params, "R_r", None)
    return float(R_r) if isinstance(R_r, (int, float)) else None




def stall_report(res: LoopResult, rig: Rig | None, cfg: RigConfig) -> dict[str, Any]:
    """The run's loop stalls (`LoopResult.stall_report`), the drive's budget, and what the drive counted where
    it says (the mock drive: references missed, stalls ridden through, the longest run of misses)."""
    out = res.stall_report(cfg.T_s)
    out["ride_through_ms"] = cfg.limits.ride_through * 1e3
    inv = rig.inverter if rig is not None else None
    if inv is not None and hasattr(inv, "ride_throughs"):
        out["drive"] = {"missed": inv.missed, "ride_throughs": inv.ride_throughs,
                        "longest_ms": round(inv.longest * cfg.T_s * 1e3, 3), "i_peak": inv.i_peak,
                        "i_peak_ride_through": inv.i_peak_ride,
                        "current_limited": getattr(inv, "current_limited", 0)}  # fmt: skip
    return out


def log_kept(path: Path) -> bool:
    """Whether the log file is there; an empty one (the writer wrote nothing, e.g. a full disk) is removed."""
    try:
        if path.stat().st_size == 0:
            path.unlink()
            return False
        return True
    except OSError:
        return False


def write_summary_and_plot(summary: dict[str, Any], paths: tuple[Path, Path, Path], plot: bool) -> None:
    """summary.json first (into the room set aside at the start), then the plot, then summary.json again
    with the plot's path; each written whole or not at all (bench.core.outputs.replacing), so a full disk
    leaves no empty or torn file and the plot can never cost the summary its space. A summary that
    cannot be written is ``summary["summary"] = None``."""
    log_path, summary_path, plot_path = paths
    problems: list[str] = summary["warnings"]

    def save() -> str | None:
        try:
            write_text(summary_path, json.dumps({k: v for k, v in summary.items() if k != "record"}, indent=2,
                                                default=str) + "\n")  # fmt: skip
            return None
        except OSError as exc:
            return exc.strerror or str(exc)

    summary["summary"] = str(summary_path)
    first = save()
    if plot:
        try:
            from bench.daq.plots import plot_run

            with replacing(plot_path) as tmp:
                plot_run(log_path, tmp)  # title from the log's metadata
            summary["plot"] = str(plot_path)
        except Exception as exc:  # noqa: BLE001
            problems.append(f"plot not written: {type(exc).__name__}: {exc}")
        again = save()
        if again is not None and first is None:
            problems.append(f"{summary_path} holds the summary as it was before the plot (rewrite failed: {again})")
        first = None if again is None else first  # on disk if either write succeeded
    if first is not None:  # the caller has it (bench run prints it in full on stderr)
        summary["summary"] = None
        problems.append(f"summary not written: {first}")


def close_log(log: Any, summary: dict[str, Any], problems: list[str]) -> dict[str, Any] | None:
    """Record how the run ended (metadata ``shutdown``, attachment ``summary.json``: the summary as
    known before the log is read back), close the log (bounded), return its statistics; never raises."""
    if log is None:
        return None
    if isinstance(log, MemoryLog):
        return log.stats()
    if log.healthy:
        try:
            log.add_metadata("shutdown", {"cause": summary["trip_cause"] or "", "exit_code": summary["exit_code"],
                                          "start_epoch_ns": summary.get("start_epoch_ns", 0)})  # fmt: skip
            log.attach("summary.json", "application/json", json.dumps(summary, indent=2, default=str))
        except Exception as exc:  # noqa: BLE001
            problems.append(f"log metadata not written: {exc}")
    try:
        log.close()
    except LogWriterError as exc:
        if not log.fault:  # a dead writer is the cause already
            problems.append("log: " + one_line(str(exc)))
        log.abort()  # a stalled writer is killed; the file keeps every complete chunk
    except Exception as exc:  # noqa: BLE001
        problems.append(f"log close failed: {type(exc).__name__}: {exc}")
        log.abort()
    if log.fault and log.fault != summary["trip_cause"]:  # e.g. the writer died after the last tick
        problems.append(log.fault)
    return log.stats()


def one_line(text: str) -> str:
    """A message for the summary and stderr: its first and last lines (a writer's traceback: what, then why)."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return " ".join(dict.fromkeys([lines[0], lines[-1]])) if lines else text
