"""Safety supervisor: trips, independent of the controller, and a latched safe state.

The loop asks the supervisor twice per tick: after reading the rig (`check_measurement`) and after
the controller (`check_command`: exception, NaN/inf). Causes from outside the tick (a signal, a
dead or stalled log writer, later an operator's e-stop) arrive through `request_trip` and trip at
the next `check_measurement`, so the safe command goes out at a tick boundary. A trip is latched until `reset`; while
tripped the loop writes the safe command (inverter disabled = coast, load torque 0) in the same
tick the trip was detected. The cause is kept as one line (``cause``, ``trip_t``) and goes into the
run summary and onto stderr; the MCAP log records ``tripped`` per tick and every tick up to it.

Trip causes, checked in this order on every measurement (cause prefix in brackets):

* a requested trip (``interrupted (...)``, ``log writer: ...``);
* a loop stall: more than ``max_stall`` seconds between two ticks, i.e. skipped ticks in a
  real-time run (``loop stall``). A shorter stall does not trip: the drive rides through it, turning
  the last reference at the field's frequency, for up to ``ride_through`` seconds, and then coasts with
  a set-point watchdog fault (bench.hal.InverterPort). Any other trip within ``STALL_BLAME`` after a
  stall of at least ``STALL_NOTE`` says so in its cause (``inverter fault reported: set-point watchdog;
  0.0 ms after a 25.0 ms loop stall``), so the log names the PC, not the motor;
* per-phase and space-vector over-current (``over-current``);
* over-speed from the supervisor's own encoder speed estimate (``over-speed``);
* encoder jump: a count step no real shaft below 2x omega_max can make in one tick
  (``encoder jump``); encoder stuck: the counter has not moved for ``enc_stuck_time`` while the
  measured stator-voltage vector rotates faster than ``enc_stuck_omega`` on average (steps larger than
  2 omega_max T_s per tick are not counted: no field the drive turns, but a vector that flips), or its mean
  amplitude exceeds ``enc_stuck_u`` (standstill needs only about R_s I; a stalled shaft at full
  current trips too, which is wanted) (``encoder stuck``);
* inverter fault bit, with the fault the drive names (``inverter fault reported: set-point
  watchdog``, bench.hal.InverterStatus.fault_name) and lost inverter heartbeat (``inverter heartbeat lost``,
  status bit ST_INV_STALE set by the driver after its timeout); parameter-channel failure
  (``inverter comm``);
* DC-link voltage outside [u_dc_min, u_dc_max] (``DC link``);
* missing or stale measurement frames: more than ``stale_ticks`` consecutive ticks without a fresh
  frame (``measurement stale``); a link that is down (``link down``);
* bursts of CRC errors, or of lost, late or duplicated frames (``CRC error burst``, ``frame loss
  burst``): ``burst_count`` ticks with the bit set within ``burst_window`` seconds (an exact
  sliding window per class) trip; fewer are tolerated and only logged;
* NaN in the measurement (``measurement is NaN``);
* the drive's reported state disagrees with the command for longer than ``enable_timeout``:
  commanded enabled but reported disabled (stopped by someone else, a drive-side timeout) or the
  reverse (``inverter state``).

Status bits come from the drivers (bench.hal ST_*); the in-process mock rig reports none.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass

from bench.core import supervisor_checks as sc
from bench.core.encoder import EncoderSpeed
from bench.hal import (
    ST_INV_COMM, ST_INV_STALE, ST_LINK_DOWN, ST_MEAS_CRC, ST_MEAS_DUP, ST_MEAS_LATE, ST_MEAS_LOST,
    ST_MEAS_STALE, Measurement,
)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Limits:
    I_max: float = 10.0  # stator-current amplitude controllers may request [A]
    I_trip: float = 15.0  # space-vector over-current trip [A]
    I_trip_phase: float = 15.0  # per-phase over-current trip [A]
    U_max: float = 400.0  # stator-voltage reference amplitude the drivers pass on (clipped above) [V]
    omega_max: float = 400.0  # over-speed trip, electrical [rad/s]
    u_dc_min: float = 400.0  # DC-link under-voltage trip [V]
    u_dc_max: float = 750.0  # DC-link over-voltage trip [V]
    stale_ticks: int = 3  # consecutive ticks without a fresh measurement frame before a trip
    burst_count: int = 5  # CRC / frame-loss errors that trip when they come within burst_window
    burst_window: float = 0.1  # [s]
    enc_stuck_time: float = 0.2  # [s] counter frozen this long while the voltage rotates -> trip
    enc_stuck_omega: float = 60.0  # [rad/s electrical] voltage-vector rotation that counts as "rotating"
    enc_stuck_u: float = 60.0  # [V] mean |u_s| while frozen that a machine at standstill does not need
    # [s] longest loop stall the drive bridges by turning the last reference at the field's frequency
    # (bench.hal.InverterPort); beyond it the drive coasts with a set-point watchdog fault. 0: none
    ride_through: float = 0.02
    max_stall: float = 0.03  # [s] longest gap between two ticks (>= ride_through: the drive bridged it)
    enable_timeout: float = 0.05  # [s] drive state may lag the enable command this long (CAN/Modbus status)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


# Physical ranges (both ends inclusive) of the limits a rig file may set: wide enough for any
# 1.5 kW-class rig, narrow enough that a typo (1e308) is caught before it disarms a trip, and with a
# sane lower end rather than 0, so that a denormal (5e-324, i.e. zero) is caught too: 10 mA, 1 V,
# 1 rad/s, 1 ms (max_stall at 1 ms already trips on any scheduling hiccup), one tick or frame.
LIMIT_RANGES: dict[str, tuple[float, float]] = {
    "I_max": (0.01, 200), "I_trip": (0.01, 500), "I_trip_phase": (0.01, 500), "U_max": (1, 1500),
    "omega_max": (1, 5000), "u_dc_min": (1, 1500), "u_dc_max": (1, 1500), "stale_ticks": (1, 1000),
    "burst_count": (1, 1000), "burst_window": (1e-3, 60), "enc_stuck_time": (1e-3, 60),
    "enc_stuck_omega": (0.1, 1e4), "enc_stuck_u": (0.1, 1500), "max_stall": (1e-3, 10), "ride_through": (0, 1), "enable_timeout": (1e-3, 10),
}  # fmt: skip


STALL_NOTE = 1e-3  # [s] a stall this long or longer is named in a trip that follows it ...
STALL_BLAME = 0.05  # [s] ... within this time (the current loop recovers from a stale voltage in a few ms)


class Supervisor:
    def __init__(self, limits: Limits, counts_per_rev: int, modulus: int, Z_p: int, T_s: float) -> None:
        self.limits = limits
        self.T_s = T_s
        self.speed = EncoderSpeed(counts_per_rev, modulus, Z_p, T_s, tau=0.002)
        self.modulus = modulus
        # largest plausible count step per tick: twice the over-speed limit, plus quantisation
        self.enc_jump_max = int(2.0 * limits.omega_max / Z_p * counts_per_rev / (2.0 * math.pi) * T_s) + 2
        self._stuck_ticks = max(1, int(round(limits.enc_stuck_time / T_s)))
        # the stuck check's rotation counts per-tick steps of the voltage vector up to twice the over-speed
        # limit's: a field the drive turns moves less; a vector that flips or jumps between phase patterns
        # (a dead time's error chattering at zero current, a pulsating single-axis test) does not rotate
        self._rot_step_max = 2.0 * limits.omega_max * T_s
        self._enable_ticks = max(1, int(round(limits.enable_timeout / T_s)))
        self._lim = sc.limits(self.enc_jump_max, self._rot_step_max, self._stuck_ticks, T_s, limits.enc_stuck_omega,
                              limits.enc_stuck_u, limits.I_trip_phase, limits.I_trip, limits.omega_max,
                              limits.u_dc_min, limits.u_dc_max, self._enable_ticks)  # fmt: skip
        self.reset()

    def reset(self) -> None:
        self.tripped = False
        self.cause: str | None = None
        self.trip_t: float | None = None
        self.speed.reset()
        self._stale = 0
        self._crc_times: deque[float] = deque()
        self._loss_times: deque[float] = deque()
        self._x, self._iv = sc.new_state()  # the per-tick checks' state (bench.core.supervisor_checks)
        self._prev_t: float | None = None
        self._stall: tuple[float, float] | None = None  # (time it ended, length) of the last stall >= STALL_NOTE
        self._requested: str | None = None
        self.enable_cmd = False  # what the loop last wrote (set by the loop after each write)

    @property
    def omega_r(self) -> float:
        """The supervisor's own encoder speed estimate (electrical, rad/s)."""
        return self.speed.omega_r

    def trip(self, cause: str, t: float) -> None:
        if not self.tripped:
            self.tripped, self.cause, self.trip_t = True, cause + self._after_stall(cause, t), t

    def _after_stall(self, cause: str, t: float) -> str:
        """``"; X ms after a Y ms loop stall"`` when a stall just preceded the trip, else ``""`` (not for a
        requested trip, which comes from outside the tick, nor for the stall trip itself)."""
        if self._stall is None or cause == self._requested or cause.startswith("loop stall"):
            return ""
        t_end, length = self._stall
        if t - t_end > STALL_BLAME:
            return ""
        rt = self.limits.ride_through
        how = (f"within the drive's {rt * 1e3:g} ms ride-through" if length <= rt * (1.0 + 1e-9) else
               f"longer than the drive's {rt * 1e3:g} ms ride-through")  # fmt: skip
        return f"; {(t - t_end) * 1e3:.1f} ms after a {length * 1e3:.1f} ms loop stall ({how})"

    def request_trip(self, cause: str) -> None:
        """Trip at the next measurement (safe to call from a signal handler or a callback)."""
        if self._requested is None:
            self._requested = cause

    def _burst(self, times: deque[float], t: float) -> bool:
        """Record an error at t; True if ``burst_count`` errors fall within ``burst_window``."""
        times.append(t)
        w = self.limits.burst_window + 0.5 * self.T_s
        while times and t - times[0] > w:
            times.popleft()
        return len(times) >= self.limits.burst_count

    def check_measurement(self, m: Measurement) -> bool:
        """Update and check; returns True if (now or already) tripped."""
        lim = self.limits
        t = m.t
        # ticks since the last check: > 1 when the real-time loop skipped ticks
        prev_t, self._prev_t = self._prev_t, t
        n = 1 if prev_t is None else max(1, int(round((t - prev_t) / self.T_s)))
        if (n - 1) * self.T_s >= STALL_NOTE:
            self._stall = (t, (n - 1) * self.T_s)
        omega = self.speed.update(m.enc_count, t)  # divides by the real elapsed time
        st = m.status
        if st:  # a driver reported something: count stale ticks and error bursts
            self._stale = self._stale + 1 if st & ST_MEAS_STALE else 0
            crc_burst = bool(st & ST_MEAS_CRC) and self._burst(self._crc_times, t)
            loss_burst = bool(st & (ST_MEAS_LOST | ST_MEAS_LATE | ST_MEAS_DUP)) and self._burst(self._loss_times, t)
        else:
            self._stale = 0
            crc_burst = loss_burst = False
        if self.tripped:
            return True
        x, iv = self._x, self._iv
        if self._requested is not None:
            self.trip(self._requested, t)
        elif (n - 1) * self.T_s > lim.max_stall:
            self.trip(f"loop stall: {(n - 1) * self.T_s * 1e3:.1f} ms without a tick (> {lim.max_stall * 1e3:g} ms); "
                      f"the drive coasts after its {lim.ride_through * 1e3:g} ms ride-through", t)  # fmt: skip
        else:
            status = self._status_cause(st, crc_burst, loss_burst) if st else None
            code = sc.measurement_checks(x, iv, self._lim, self.speed.d, n, m.i_a, m.i_b, m.i_c, m.u_a, m.u_b, m.u_c,
                                         omega, m.inv_fault or status is not None, m.u_dc, m.inv_enabled,
                                         self.enable_cmd)  # fmt: skip
            if code == sc.TRIP_OUTSIDE:
                self.trip(f"inverter fault reported: {m.inv_fault_name or 'the drive did not say which'}"
                          if m.inv_fault else status, t)  # fmt: skip
            elif code != sc.TRIP_NONE:
                self.trip(sc.cause(code, lim, x[sc.V1], x[sc.V2], x[sc.V3], iv[sc.JUMP_D], iv[sc.JUMP_N],
                                   self.enc_jump_max, iv[sc.ENABLE_CMD] == 1), t)  # fmt: skip
        return self.tripped

    def _status_cause(self, st: int, crc_burst: bool, loss_burst: bool) -> str | None:
        """The trip causes that come from the drivers' status bits, in their order of precedence."""
        lim = self.limits
        if st & ST_INV_STALE:
            return "inverter heartbeat lost: no status frame within its timeout"
        if st & ST_INV_COMM:
            return "inverter comm: parameter channel (Modbus) failed"
        if self._stale > lim.stale_ticks:
            return f"measurement stale: no fresh frame for {self._stale} ticks (> {lim.stale_ticks})"
        if st & ST_LINK_DOWN and self._stale:
            return "link down: measurement link disconnected"
        if crc_burst:
            return f"CRC error burst: {lim.burst_count} bad frames within {lim.burst_window:g} s"
        if loss_burst:
            return f"frame loss burst: {lim.burst_count} lost/late/duplicated frames within {lim.burst_window:g} s"
        return None

    def check_command(self, u_s_ref: complex, t: float) -> bool:
        """NaN/inf from the controller trips."""
        if not (math.isfinite(u_s_ref.real) and math.isfinite(u_s_ref.imag)):
            self.trip(f"controller output not finite: {u_s_ref!r}", t)
        return self.tripped
