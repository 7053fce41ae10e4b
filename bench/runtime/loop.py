"""The timed control loop: read -> supervise -> control -> supervise -> write -> log, every tick.

Two clocks:

* **lockstep** - simulated time. Ticks run back to back as fast as the CPU allows; with the mock
  rig the run is deterministic for a given seed.
* **real-time** - absolute deadlines t0 + k*T_s on the monotonic wall clock. The loop sleeps until
  `SPIN_MARGIN` before a deadline and then spins (plain `time.sleep` wakes ~60 us late at p50 on
  this VM, spinning ~0.2 us; DESIGN.md). Garbage collection is paused during the run, the loop
  process is pinned to one CPU with SCHED_FIFO priority where the OS allows (`realtime_setup`), and its
  memory is locked where it may be (`bench.runtime.rt_memory`; the run's page faults are in the summary).

Overrun policy (real-time): a tick that starts late but less than one period late runs at once and
keeps the grid (no drift). A tick whose write finishes after the next deadline is an *overrun*.
If the loop falls a whole period or more behind, the missed ticks are *skipped*: the loop jumps to
the next grid point, so it never bursts to catch up. The drive rides through the stall: it turns the
last reference at the field's frequency that came with it (`bench.hal.Command.omega_u`) for up to the
rig's ``limits.ride_through``, then coasts (the mock plant integrates the skipped periods with what the
drive applied); the controller resynchronises from the elapsed loop time. Every stall is in the result
(`LoopResult.stalls`) and so in the summary. ``deadline_misses = overruns + skipped``.

Per-tick records go to the log writer (a separate process); in real time a full ring is a fault
(`bench.daq.writer`), never a wait.

Failures inside a tick: a controller exception or a NaN command trips the supervisor and the loop
goes on with the safe command for `POST_TRIP_TIME` (the coast-down is logged); an exception from
``rig.read``/``rig.write`` (a driver or the plant) or anywhere else in the tick ends the loop at
once with ``rig.safe()`` and the cause as the trip. Requests from outside (a signal, the log
writer) trip at the next tick through `Supervisor.request_trip`. Operator requests (parameter
changes, part switches, stop, e-stop, notes: bench.operate.operator) are applied between ticks, before the read: in
real time first in the slack before the tick's deadline (a part switch's hand-over then costs the tick
nothing), and what arrives while the loop waits right after the wait (an e-stop still acts in that tick).
"""

from __future__ import annotations

import gc
import math
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from bench.runtime import rt_memory
from bench.controllers.base import Controller
from bench.hal import MEAS_FIELDS, SAFE_COMMAND, Command, Rig, meas_values
from bench.core.rt_host import realtime_setup, realtime_teardown, save_sched
from bench.core.scenarios import Scenario
from bench.core.supervisor import Supervisor

SPIN_MARGIN = 150e-6  # [s] wake this long before a deadline, then spin
# wall-clock fields: differ between identical runs (log_time: the reader's column, start epoch + t)
TIMING_FIELDS = ("compute_us", "latency_us", "overrun", "log_time")
POST_TRIP_TIME = 0.02  # [s] ticks logged after a trip, with the safe command, to show the coast-down

_MEAS_TYPES = {"enc_count": "int32", "enc_index": "int32", "inv_enabled": "bool", "inv_fault": "bool",
               "status": "uint32"}


class OperatorPort(Protocol):
    """What the loop needs of on-line operation (`bench.operate.operator.Operator`): between two ticks, whether anything
    is due and its service (True: the operator stop ends the run), the references in force and the controller running
    (a whole-controller switch hands over another); ``epoch_ns`` is set by the loop (log_time of t = 0)."""

    ctrl: Controller
    epoch_ns: int

    def due(self, k: int) -> bool: ...
    def service(self, k: int, t: float) -> bool: ...
    def refs(self, speed_ref: Callable[[float], float], load: Callable[[float, float], float],
             i_mR_ref: Any) -> tuple[Any, Any, Any]: ...  # fmt: skip


# the measurement columns of a tick whose read failed: NaN, integer fields 0
_NO_MEAS = tuple(0 if f in _MEAS_TYPES or f.startswith("raw_") else math.nan for f in MEAS_FIELDS)


def _safe(rig: Rig) -> None:
    """Best effort safe state (the driver that just failed may fail again; the others must not wait)."""
    try:
        rig.safe()
    except Exception:  # noqa: BLE001 - the shutdown path reports the cause; nothing else to do here
        pass


def log_topics(rig: Rig, controller: Controller) -> list[tuple[str, str, list[tuple[str, str]]]]:
    """(topic, message type, fields) of the per-tick record, in the order `TimedLoop` fills it.

    Field names are the thesis names lower-cased (ROS 2 field-name rule): i_mR -> i_mr, m_L -> m_l.
    """
    return [(topic, schema, [(f.lower(), ty) for f, ty in flds]) for topic, schema, flds in _topics(rig, controller)]


def _topics(rig: Rig, controller: Controller) -> list[tuple[str, str, list[tuple[str, str]]]]:
    # Three topics, one message each per tick: everything the rig saw and was told, with the
    # references and loop timing (/rig); the controller's internals (its `topic`: /ctrl, or /ident
    # for an identification's test signals and running estimates); the mock plant's
    # ground truth (/truth). Few, wide topics: the MCAP writer's cost is per message (~3 us), so
    # this layout logs about twice as fast as one topic per record kind (docs/RESULTS.md).
    rig_fields = [("t", "float64")] + [(f, _MEAS_TYPES.get(f, "int32" if f.startswith("raw_") else "float64"))
                                       for f in MEAS_FIELDS]  # fmt: skip
    rig_fields += [("u_s_ref_re", "float64"), ("u_s_ref_im", "float64"), ("enable", "bool"), ("m_L_ref", "float64"),
                   ("omega_r_ref", "float64"), ("i_mR_ref", "float64"), ("tick", "int64"),
                   ("compute_us", "float64"), ("latency_us", "float64"), ("overrun", "bool"), ("tripped", "bool")]  # fmt: skip
    topics = [
        ("/rig", "imbench_msgs/msg/RigTick", rig_fields),
        (controller.topic, f"imbench_msgs/msg/Ctrl{controller.name.title().replace('_', '')}",
         [(f, "float64") for f in controller.fields]),
    ]  # fmt: skip
    if rig.truth is not None:
        topics.append(("/truth", "imbench_msgs/msg/GroundTruth", [(f, "float64") for f in rig.truth.fields]))
    return topics


@dataclass
class LoopResult:
    ticks: int
    sim_time: float  # [s]
    wall_time: float  # [s]
    realtime: bool
    overruns: int
    skipped: int
    trip_cause: str | None
    trip_t: float | None
    interrupted: bool
    rt_setup: dict[str, Any]
    compute_us: np.ndarray = field(repr=False)
    latency_us: np.ndarray = field(repr=False)
    start_epoch_ns: int = 0  # log_time of t = 0 [ns since the Unix epoch]
    stalls: list[tuple[float, int]] = field(default_factory=list)  # (t after it [s], ticks skipped) per stall

    @property
    def deadline_misses(self) -> int:
        return self.overruns + self.skipped

    @property
    def realtime_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else math.inf

    def timing(self) -> dict[str, Any]:
        def pct(a: np.ndarray) -> dict[str, float]:
            if a.size == 0:
                return {}
            q = np.percentile(a, [50, 99, 99.9])
            return {"p50": float(q[0]), "p99": float(q[1]), "p99_9": float(q[2]), "max": float(a.max()),
                    "mean": float(a.mean())}  # fmt: skip

        return {"compute_us": pct(self.compute_us), "latency_us": pct(self.latency_us)}

    def stall_report(self, T_s: float, limit: int = 50) -> dict[str, Any]:
        """The loop stalls of the run (each one the drive rode through, or coasted after its budget):
        count, longest and total [ms], and the first ``limit`` as [t [s], length [ms]]."""
        ms = [n * T_s * 1e3 for _, n in self.stalls]
        return {"count": len(ms), "longest_ms": round(max(ms, default=0.0), 3), "total_ms": round(sum(ms), 3),
                "events": [[round(t, 6), round(n * T_s * 1e3, 3)] for t, n in self.stalls[:limit]]}  # fmt: skip


class TimedLoop:
    def __init__(
        self,
        rig: Rig,
        controller: Controller,
        scenario: Scenario,
        supervisor: Supervisor,
        *,
        T_s: float,
        duration: float,
        realtime: bool = False,
        log: Any | None = None,
        progress: Callable[[float], None] | None = None,
        operator: OperatorPort | None = None,
        inject_stalls: dict[int, int] | None = None,
    ) -> None:
        self.rig, self.ctrl, self.scn, self.sup = rig, controller, scenario, supervisor
        # lockstep only (bench perf stall, tests): {tick: ticks to skip before it}, as a stalled real-time loop does
        self.inject_stalls = inject_stalls if inject_stalls else None
        self.operator = operator
        self.T_s, self.realtime, self.log, self.progress = T_s, realtime, log, progress
        self.n_ticks = int(round(duration / T_s))
        self.epoch_ns = 0
        self._rt: tuple[Any, dict[str, Any], dict[str, Any], tuple[int, int], bool] | None = None  # take_realtime
        # per-tick timings, pre-sized and written now, before the rig is activated: no growth, copy or page fault
        # mid-run (a run is at most an hour: 86 MB each)
        self._compute_us = array("d", [0.0]) * (self.n_ticks + 1)
        self._latency_us = array("d", [0.0]) * (self.n_ticks + 1)

    def _put_fault_row(self, k: int, meas: Any, w_ref: float, i_mR_ref: Any) -> None:
        """The row of a tick that failed in read/write: what was measured (NaN if nothing), the safe command."""
        ctrl, truth = self.ctrl, self.rig.truth
        m = meas_values(meas) if meas is not None else _NO_MEAS
        try:
            internals = tuple(ctrl.internals())
        except Exception:  # noqa: BLE001
            internals = (math.nan,) * len(ctrl.fields)
        try:
            true = tuple(truth.sample()) if truth is not None else ()
        except Exception:  # noqa: BLE001
            true = (math.nan,) * len(truth.fields)
        t = k * self.T_s
        i_mR = i_mR_ref if not callable(i_mR_ref) else math.nan
        try:
            safe_and_tripped = (0.0, 0.0, False, 0.0, w_ref, i_mR, k, 0.0, 0.0, False, True)  # the /rig tail
            self.log.put(self.epoch_ns + int(t * 1e9), (t,) + m + safe_and_tripped + internals + true)
        except Exception:  # noqa: BLE001 - the cause is in the summary either way
            pass

    def take_realtime(self) -> None:
        """A real-time run's CPU, SCHED_FIFO priority, locked memory (no page fault, no memory handed back mid-run)
        and no garbage collector; a lockstep run takes none. The session takes them before it activates the rig:
        locking a few hundred MB takes 0.1-0.3 s on a busy machine, and between the drive's first set-point and the
        first tick nothing slow may lie (the emulated drive's control-word watchdog, 0.1 s, fired there)."""
        if not self.realtime or self._rt is not None:
            return
        saved = save_sched()
        rt = realtime_setup()
        rt["memory"] = rt_memory.lock_memory()
        gc_was = gc.isenabled()
        gc.disable()
        self._rt = (saved, rt, rt["memory"], rt_memory.faults(), gc_was)

    def give_back_realtime(self) -> None:
        """Undo `take_realtime` (the page faults in between go into its report); nothing if it was not taken."""
        if self._rt is None:
            return
        saved, rt, mem, faults0, gc_was = self._rt
        self._rt = None
        minor, major = rt_memory.faults()
        rt["page_faults"] = {"minor": minor - faults0[0], "major": major - faults0[1]}
        rt_memory.unlock_memory(mem)
        realtime_teardown(saved)
        if gc_was:
            gc.enable()

    def _operate(self, k: int, scn_refs: tuple) -> tuple | None:
        """Serve the operator's requests at tick k (`bench.operate.operator`): None once its stop is done, else the
        references (speed, load, i_mR and the i_mR function of time or None) and the controller, which a
        whole-controller switch may have replaced."""
        op = self.operator
        if op.service(k, k * self.T_s):
            return None
        speed_ref, load, i_mR_ref = op.refs(*scn_refs)
        self.ctrl = op.ctrl
        return speed_ref, load, i_mR_ref, i_mR_ref if callable(i_mR_ref) else None, op.ctrl

    def _fail(self, cause: str, k: int, done: int, now: float, latency: float, meas: Any, w_ref: float,
              i_mR_ref: Any) -> tuple[int, int]:  # fmt: skip
        """A read or write failure at tick k: the safe state in that tick, the trip, and a row that says so (its
        timings and what was measured, `_put_fault_row`). Returns the ticks done after it (k, done)."""
        _safe(self.rig)
        self.sup.trip(cause, k * self.T_s)
        if self.log is None or k >= self.n_ticks:
            return k, done
        self._compute_us[done] = (time.perf_counter() - now) * 1e6
        self._latency_us[done] = latency * 1e6
        self._put_fault_row(k, meas if meas is not None and meas.t == k * self.T_s else None, w_ref, i_mR_ref)
        return k + 1, done + 1

    def _wait(self, k: int, t0: float) -> tuple[int, float, float]:
        """Real time: wait for tick k's deadline t0 + k T_s (sleep, then spin the last SPIN_MARGIN). Late by a
        period or more (a stall), the tick is the one whose period it is now. Returns that tick, the time and the
        latency past its deadline."""
        T = self.T_s
        deadline = t0 + k * T
        now = time.perf_counter()
        if now < deadline:
            if deadline - now > SPIN_MARGIN:
                time.sleep(deadline - now - SPIN_MARGIN)
            while (now := time.perf_counter()) < deadline:
                pass
        elif now - deadline >= T:
            k = int((now - t0) / T)
            deadline = t0 + k * T
        return k, now, now - deadline

    def run(self) -> LoopResult:
        rig, ctrl, scn, sup, log = self.rig, self.ctrl, self.scn, self.sup, self.log
        T = self.T_s
        speed_ref, load, i_mR_ref = scn.speed_ref, scn.load, scn.i_mR_ref
        op = self.operator
        scn_refs = (speed_ref, load, i_mR_ref)  # an operator's overrides or stop wrap them while they last
        i_mR_of_t = i_mR_ref if callable(i_mR_ref) else None  # a time-varying reference (e.g. the NARX excitation)
        truth = rig.truth.sample if rig.truth is not None else (lambda: ())
        pc = time.perf_counter
        n = self.n_ticks
        compute_us, latency_us = self._compute_us, self._latency_us
        done = 0  # ticks computed (a stall skips some)
        post_trip = int(round(POST_TRIP_TIME / T))
        every = max(1, int(round(0.05 / T)))  # progress every 50 ms of loop time
        overruns = skipped = 0
        stalls: list[tuple[float, int]] = []  # (loop time of the tick after it, ticks skipped) of each stall
        inject = self.inject_stalls
        interrupted = False
        failed: str | None = None  # a read/write failure ends the loop at once
        meas, w_ref, now, latency = None, math.nan, pc(), 0.0
        stop_at = n
        k = 0
        realtime, progress = self.realtime, self.progress
        self.take_realtime()  # (done already where the session took it before activating the rig)
        rt = self._rt[1] if self._rt is not None else {}
        wall0 = pc()
        t0 = wall0 + 0.002
        # log_time = epoch + t: wall-clock time of each tick in real time (to within its latency),
        # the run's start + simulated time in lockstep
        self.epoch_ns = epoch = time.time_ns() + (int((t0 - pc()) * 1e9) if realtime else 0)
        if op is not None:
            op.epoch_ns = epoch
        try:
            while k < stop_at:
                # operator requests between ticks: first in the slack before this tick's deadline (a part switch's
                # hand-over then costs the tick nothing), then again below for what arrives while waiting (an e-stop
                # stays within the tick)
                if op is not None and op.due(k):
                    if (refs := self._operate(k, scn_refs)) is None:  # the operator stop is done
                        stop_at = k
                        break
                    speed_ref, load, i_mR_ref, i_mR_of_t, ctrl = refs
                if realtime:
                    k_was = k
                    k, now, latency = self._wait(k, t0)
                    m = k - k_was  # a stall: the ticks it missed are skipped
                else:
                    now, latency = pc(), 0.0
                    m = inject[k] if inject is not None and k in inject else None  # an injected stall, as above
                    k += m or 0
                if m:
                    skipped += m
                    stalls.append((k * T, m))
                    if k >= stop_at:
                        break
                t = k * T
                if op is not None and op.due(k):
                    if (refs := self._operate(k, scn_refs)) is None:
                        stop_at = k
                        break
                    speed_ref, load, i_mR_ref, i_mR_of_t, ctrl = refs
                if i_mR_of_t is not None:
                    i_mR_ref = i_mR_of_t(t)
                try:
                    meas = rig.read(t)
                except Exception as exc:  # a driver or the plant failed: no measurement this tick
                    failed = f"rig read failed: {type(exc).__name__}: {exc}"
                    break
                was_tripped = sup.tripped
                w_ref = speed_ref(t)
                if not sup.check_measurement(meas):
                    try:
                        u = ctrl.step(meas, w_ref, i_mR_ref)
                    except Exception as exc:  # any controller failure trips; the loop goes on safely
                        sup.trip(f"controller exception: {type(exc).__name__}: {exc}", t)
                        u = 0j
                    if not sup.check_command(u, t):
                        cmd = Command(u, True, load(t, sup.omega_r), ctrl.omega_u)
                    else:
                        cmd = SAFE_COMMAND
                else:
                    cmd = SAFE_COMMAND
                try:
                    rig.write(cmd)
                except Exception as exc:
                    failed = f"rig write failed: {type(exc).__name__}: {exc}"
                    break
                sup.enable_cmd = cmd.enable
                end = pc()
                if sup.tripped and not was_tripped:
                    stop_at = min(stop_at, k + 1 + post_trip)
                over = realtime and end > t0 + (k + 1) * T
                overruns += over
                c_us = (end - now) * 1e6
                lat_us = latency * 1e6
                compute_us[done] = c_us
                latency_us[done] = lat_us
                done += 1
                if log is not None:
                    u = cmd.u_s_ref
                    try:
                        log.put(epoch + int(t * 1e9), (t,) + meas_values(meas) + (u.real, u.imag, cmd.enable, cmd.m_L_ref,
                                w_ref, i_mR_ref, k, c_us, lat_us, over, sup.tripped) + ctrl.internals() + truth())  # fmt: skip
                    except Exception as exc:  # e.g. a value the log cannot take: trip at the next tick
                        sup.request_trip(f"log: {type(exc).__name__}: {exc}")
                k += 1
                if progress is not None and k % every == 0:
                    progress(k * T)
        except KeyboardInterrupt:  # Ctrl-C without a SignalGuard (library use; `bench run` has one)
            _safe(rig)  # first thing: the hardware goes safe
            interrupted = True
            sup.trip("interrupted (Ctrl-C)", k * T)
        except Exception as exc:  # a scenario function, the supervisor, ... : a bug, but the rig goes safe
            failed = f"exception in the loop: {type(exc).__name__}: {exc}"
        except BaseException:
            _safe(rig)
            raise
        finally:
            if failed is not None:
                k, done = self._fail(failed, k, done, now, latency, meas, w_ref, i_mR_ref)
            self.give_back_realtime()
        wall = pc() - wall0
        return LoopResult(
            ticks=done, sim_time=k * T, wall_time=wall, realtime=self.realtime,
            overruns=overruns, skipped=skipped, trip_cause=sup.cause, trip_t=sup.trip_t,
            interrupted=interrupted, rt_setup=rt, compute_us=np.frombuffer(compute_us, dtype=float)[:done],
            latency_us=np.frombuffer(latency_us, dtype=float)[:done], start_epoch_ns=self.epoch_ns, stalls=stalls,
        )  # fmt: skip
