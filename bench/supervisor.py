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

import cmath
import math
from collections import deque
from dataclasses import asdict, dataclass

from bench.encoder import EncoderSpeed
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
        self.reset()

    def reset(self) -> None:
        self.tripped = False
        self.cause: str | None = None
        self.trip_t: float | None = None
        self.speed.reset()
        self._stale = 0
        self._crc_times: deque[float] = deque()
        self._loss_times: deque[float] = deque()
        self._have_count = False  # the encoder has given its first count
        self._m_prev: Measurement | None = None  # the last measurement (its voltage, for the stuck check)
        self._prev_t: float | None = None
        self._stall: tuple[float, float] | None = None  # (time it ended, length) of the last stall >= STALL_NOTE
        self._still = 0  # ticks the encoder count has not moved
        self._u_angle = 0.0  # voltage-vector rotation accumulated while the count is still [rad]
        self._u_sum = 0.0  # sum of |u_s| while the count is still [V]
        self._requested: str | None = None
        self.enable_cmd = False  # what the loop last wrote (set by the loop after each write)
        self._enable_mismatch = 0  # ticks the drive's reported state has differed from enable_cmd

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

    def _encoder(self, m: Measurement, n: int) -> str | None:
        """Jump and stuck checks on the count step the speed estimate has just taken (``self.speed.d``)."""
        if not self._have_count:  # the first sample: no step yet
            self._have_count = True  # (the voltage before the first step counts as 0, as it always did)
            return None
        d = self.speed.d
        if abs(d) > self.enc_jump_max * n:
            return f"encoder jump: {d:+d} counts in {n} tick{'s' if n > 1 else ''} > {self.enc_jump_max * n}"
        prev, self._m_prev = self._m_prev, m
        if d:  # the shaft moved: the common case costs no voltage vector
            if self._still:
                self._still, self._u_angle, self._u_sum = 0, 0.0, 0.0
            return None
        u = m.u_s
        u_prev = prev.u_s if prev is not None else 0j
        self._still += 1
        au = abs(u)
        self._u_sum += au
        if au > 5.0 and abs(u_prev) > 5.0:
            step = cmath.phase(u / u_prev)
            if abs(step) <= self._rot_step_max * n:  # larger steps are no field the drive can turn (see reset)
                self._u_angle += step
        if self._still >= self._stuck_ticks:
            lim = self.limits
            w = abs(self._u_angle) / (self._still * self.T_s)
            u_mean = self._u_sum / self._still
            if w > lim.enc_stuck_omega or u_mean > lim.enc_stuck_u:
                return (f"encoder stuck: no count for {self._still * self.T_s:.3f} s while the stator voltage "
                        f"rotates at {w:.0f} rad/s, mean |u_s| = {u_mean:.0f} V")  # fmt: skip
        return None

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
        enc = self._encoder(m, n)
        if m.inv_enabled != self.enable_cmd:
            self._enable_mismatch += 1
        else:
            self._enable_mismatch = 0
        if self.tripped:
            return True
        ip = lim.I_trip_phase
        i_a, i_b, i_c = m.i_a, m.i_b, m.i_c
        if self._requested is not None:
            self.trip(self._requested, t)
        elif (n - 1) * self.T_s > lim.max_stall:
            self.trip(f"loop stall: {(n - 1) * self.T_s * 1e3:.1f} ms without a tick (> {lim.max_stall * 1e3:g} ms); "
                      f"the drive coasts after its {lim.ride_through * 1e3:g} ms ride-through", t)  # fmt: skip
        elif abs(i_a) > ip or abs(i_b) > ip or abs(i_c) > ip:
            worst = max(abs(i_a), abs(i_b), abs(i_c))
            self.trip(f"over-current: phase |i| = {worst:.2f} A > {ip:g} A", t)
        elif abs(m.i_s) > lim.I_trip:
            self.trip(f"over-current: |i_s| = {abs(m.i_s):.2f} A > {lim.I_trip:g} A", t)
        elif enc is not None:  # before over-speed: a jump also fakes a huge speed
            self.trip(enc, t)
        elif abs(omega) > lim.omega_max:
            self.trip(f"over-speed: |omega_r| = {abs(omega):.1f} rad/s > {lim.omega_max:g} rad/s", t)
        elif m.inv_fault:
            self.trip(f"inverter fault reported: {m.inv_fault_name or 'the drive did not say which'}", t)
        elif st and (cause := self._status_cause(st, crc_burst, loss_burst)) is not None:
            self.trip(cause, t)
        elif not (lim.u_dc_min <= m.u_dc <= lim.u_dc_max):
            self.trip(f"DC link {m.u_dc:.1f} V outside [{lim.u_dc_min:g}, {lim.u_dc_max:g}] V", t)
        elif math.isnan(i_a + i_b + i_c + m.u_a + m.u_b + m.u_c):
            self.trip("measurement is NaN", t)
        elif self._enable_mismatch > self._enable_ticks:
            said, told = ("disabled", "enabled") if self.enable_cmd else ("enabled", "disabled")
            self.trip(f"inverter state: commanded {told} but the drive reports {said} for "
                      f"{self._enable_mismatch * self.T_s * 1e3:.1f} ms (> {lim.enable_timeout * 1e3:g} ms)", t)  # fmt: skip
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
