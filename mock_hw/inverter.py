"""Voltage-sourced inverter of the mock rig (thesis 3.5, App. A.2: VLT5003, PWM at 15 kHz).

What it models, per sample period T_s (the PWM ripple itself is averaged away, 3.5):

- zero-order hold of the stator-voltage reference;
- a one-sample computation/transport delay: a reference written during tick k, i.e. after the
  sample at t_k, is latched at the boundary t_{k+1} and applied over [t_{k+1}, t_{k+2}). The
  plant calls `latch` once per period, at the start of the period it is about to integrate.
  ``delay=0`` applies it over [t_k, t_{k+1}) instead (idealised: zero computation time);
- the SVPWM linear range: the vector amplitude is limited to u_dc/sqrt(3), keeping its angle
  (overmodulation is not modelled). The default u_dc = 560 V is a 400 V grid rectified
  (sqrt(2)*400 V less diode and load drop), giving 323 V. The thesis' 6.2.3 simulation clipped
  the voltage vector at 600 V, which no SVPWM on such a link can deliver; u_dc = 600 sqrt(3) V
  reproduces that clip;
- optional inverter voltage error, per phase, the sum of two effects that both oppose the phase
  current: the dead time t_d, which loses t_d f_pwm u_dc of the average phase voltage over a PWM
  period, and the switches' on-state drop v_on (an IGBT's V_CE,sat or a free-wheeling diode's V_F,
  taken equal; their slope resistance is left out: identification lumps it into R_s)::

      e_x = -(t_d f_pwm u_dc + v_on_x) sgn(i_x),   x = a, b, c

  ``sgn`` is the hard sign when ``i_knee = 0`` (the default) and otherwise the soft knee
  sgn(i) = i / sqrt(i^2 + i_knee^2): the error grows linearly through zero current (slope
  1/i_knee) instead of jumping, as the real error does while the current is too small to
  finish commutating within the dead time; it reaches 89 % of its full value at 2 i_knee and
  97 % at 4 i_knee. The currents are taken at the start of the period and held over it; the
  errors enter as a space vector (3.17), whose common-mode part drops out (isolated neutral).
  For a DC current along phase a (i_b = i_c = -i_a/2) and the hard sign, the error vector is
  -4/3 (t_d f_pwm u_dc + v_on) sign(i_a). Defaults t_d = 0, v_on = 0 (the VLT compensates its
  dead time internally), so the bridge is ideal unless a rig file asks otherwise;
- enable/disable: ``enable`` goes through the same one-sample pipeline as the reference (the
  bridge starts switching at t_{k+1}), while ``disable`` blocks the gates at once: the bridge is
  off over the whole period in which it was called (from the last sample instant on, the nearest
  point of the simulation grid). A disabled bridge coasts (i_s forced to 0, see mock_hw.motor);
- an injectable drive fault: latched, blocks the gates like ``disable`` and is reported by
  `status` until `reset_fault`; the drive then needs a new `enable`;
- stall ride-through (`bench.hal.InverterPort`): an enabled drive that gets no reference for a period
  substitutes one, the last turned by ``omega_u T_s`` (the field's stator frequency, sent with each
  reference), as drives with cyclic set-points extrapolate a missed set-point at constant speed. It
  counts the missed references (`missed`, `ride_throughs`, `longest`); after ``ride_through`` seconds
  without one it coasts with a latched ``set-point watchdog`` fault. ``ride_through = None`` (a bare
  plant in tests) holds the last reference for ever, as a zero-order hold;
- the drive's own over-current trip: a phase current above ``i_trip`` at the start of a period in which
  the bridge switches latches an ``over-current`` fault (the bridge is off from that period on). It
  acts while the PC is stalled; a session sets it above the PC's phase trip (`DRIVE_TRIP_MARGIN`), so the
  supervisor, which samples the same currents, trips first whenever the loop runs;
- the drive's own current limit while it rides through: a phase current heading above ``i_limit`` by the end of
  a period whose reference is a substitute (it rises as over the last period) makes that period's output the
  zero vectors (the voltage error stays), as a drive's current limiter does; the substitute reference goes on
  turning and is applied again once the current is back below the limit (`current_limited` counts those
  periods). At standstill (a stall while the FOC forces the
  magnetising current up) this holds the current instead of letting the forcing voltage run it into the trip;
  at speed the zero vectors short the back-EMF, so a ride-through that goes wrong there still ends in the
  over-current trip above. A session sets ``i_limit`` below the PC's phase trip (`DRIVE_LIMIT_MARGIN`).
"""

from __future__ import annotations

import cmath
import math

from bench.hal import InverterStatus

SQRT3 = math.sqrt(3.0)
_H = 0.5 * SQRT3
SETPOINT_WATCHDOG = "set-point watchdog"  # fault names as in the DBC's VLT_STATUS.FAULT value table
OVER_CURRENT = "over-current"
DRIVE_TRIP_MARGIN = 1.2  # the drive's own over-current trip, relative to the rig's phase trip (I_trip_phase)
DRIVE_LIMIT_MARGIN = 0.9  # the drive's current limit while it rides through, relative to the same


class Inverter:
    """Averaged VSI with ZOH, delay, voltage limit, voltage error (dead time, on-state drop), enable and
    fault (`InverterPort`)."""

    def __init__(
        self,
        u_dc: float = 560.0,
        *,
        delay: int = 1,
        dead_time: float = 0.0,
        f_pwm: float = 15e3,
        v_on: float | tuple[float, float, float] = 0.0,
        i_knee: float = 0.0,
        T_s: float = 1.0 / 3000.0,
        ride_through: float | None = None,
        i_trip: float = math.inf,
        i_limit: float = math.inf,
    ) -> None:
        if not u_dc > 0:
            raise ValueError(f"u_dc must be > 0, got {u_dc!r}")
        if delay not in (0, 1):
            raise ValueError(f"delay must be 0 or 1 samples, got {delay!r}")
        if not dead_time >= 0 or not f_pwm > 0:
            raise ValueError("dead_time must be >= 0 and f_pwm > 0")
        v3 = (v_on,) * 3 if isinstance(v_on, (int, float)) else tuple(v_on)
        if len(v3) != 3 or not all(v >= 0 for v in v3) or not i_knee >= 0:
            raise ValueError("v_on must be >= 0 (one value or one per phase) and i_knee >= 0")
        self.u_dc = float(u_dc)
        self.u_dc_nominal = float(u_dc)
        self.delay = delay
        self.dead_time = float(dead_time)
        self.f_pwm = float(f_pwm)
        self.v_on: tuple[float, float, float] = (float(v3[0]), float(v3[1]), float(v3[2]))
        self.i_knee = float(i_knee)
        self._verr = self.dead_time > 0.0 or any(self.v_on)  # any voltage error to add
        if not T_s > 0 or (ride_through is not None and not ride_through >= 0) or not i_trip > 0 or not i_limit > 0:
            raise ValueError("T_s, i_trip and i_limit must be > 0, ride_through >= 0 or None")
        self.T_s = float(T_s)
        self.ride_through = ride_through  # [s] budget of missed references; None: hold for ever
        self.i_trip = float(i_trip)  # [A] the drive's own phase over-current trip
        self.i_limit = float(i_limit)  # [A] the drive's current limit while it rides through (with i_trip set)
        self.reset()

    def reset(self) -> None:
        self._ref = 0j  # last reference received
        self._cmd_on = False  # last enable command received
        self._next_ref = 0j  # latched at the last boundary, applied from the next one (delay=1)
        self._next_on = False
        self.u_applied = 0j  # voltage applied over the current period [V]
        self.on = False  # bridge switching over the current period
        self._fault = False
        self.fault_reason = ""
        self._status = InverterStatus(False, False, self.u_dc)
        self._omega = 0.0  # [rad/s] frequency sent with the last reference
        self._fresh = False  # a reference came since the last period boundary
        self._run = 0  # references missed in a row
        self._next_sub = False  # _next_ref is a ride-through substitute (delay=1)
        self._i_last = 0.0  # the largest phase current at the last period start [A] (with i_trip set)
        self.missed = 0  # references missed in all (ride-through periods)
        self.ride_throughs = 0  # stalls ridden through (runs of missed references)
        self.longest = 0  # the longest run of missed references [periods]
        self.i_peak = 0.0  # the largest phase current at a period start with the bridge on [A] (with i_trip set)
        self.i_peak_ride = 0.0  # ... of those while riding through a stall [A]
        self.current_limited = 0  # ridden-through periods the current limit gave zero vectors

    # --- InverterPort ----------------------------------------------------------------------
    @property
    def u_max(self) -> float:
        """Largest vector amplitude in the SVPWM linear range, u_dc/sqrt(3) [V]."""
        return self.u_dc / SQRT3

    def set_voltage(self, u_s_ref: complex, omega_u: float = 0.0) -> None:
        self._ref = u_s_ref
        self._omega = omega_u
        self._fresh = True

    def enable(self) -> None:
        if not self._fault:
            self._cmd_on = True

    def disable(self) -> None:
        # Gate blocking is immediate (no computation delay): the bridge is off over the whole
        # period in which disable() was called, i.e. from the last sample instant on.
        self._cmd_on = False
        self._next_on = False

    def status(self) -> InverterStatus:
        """Bridge state from the last latched boundary on; fault flag; DC-link voltage."""
        on = (self._next_on if self.delay else self._cmd_on) and not self._fault
        st = self._status
        if st.enabled != on or st.fault != self._fault or st.u_dc != self.u_dc or st.fault_name != self.fault_reason:
            st = self._status = InverterStatus(on, self._fault, self.u_dc, self.fault_reason)
        return st

    # --- faults ----------------------------------------------------------------------------
    def inject_fault(self, reason: str = "injected") -> None:
        """Trip the drive: latched fault, bridge off from the next period."""
        self._fault = True
        self.fault_reason = reason
        self._cmd_on = False
        self._next_on = False

    def reset_fault(self) -> None:
        """Clear a latched fault; the bridge stays off until the next `enable`."""
        self._fault = False
        self.fault_reason = ""

    # --- called by the plant at each period boundary --------------------------------------
    def pipeline(self, i_s: complex = 0j) -> tuple[complex, bool]:
        """Start a period: the drive's own over-current check on ``i_s`` (the stator current at the
        boundary), the ride-through of a missed reference, the one-sample pipeline. Returns the
        reference and the bridge state for the period (before the voltage limit and error: `latch`;
        the compiled plant applies those itself)."""
        if self._fresh:
            self._fresh = False
            self._run = 0
        elif self._cmd_on and not self._fault:  # enabled, and no reference came for this period
            self._ride_through()
        limited = False
        if self.i_trip < math.inf and (self._next_on if self.delay else self._cmd_on) and not self._fault:
            re, h = i_s.real, _H * i_s.imag
            i_max = max(abs(re), abs(-0.5 * re + h), abs(-0.5 * re - h))
            if i_max > self.i_peak:
                self.i_peak = i_max
            if self._run and i_max > self.i_peak_ride:
                self.i_peak_ride = i_max
            if i_max > self.i_trip:
                self.inject_fault(OVER_CURRENT)
            # where the current will be at the period's end if it rises as over the last one: the limiter of a
            # real drive acts within the PWM period; sampled once a period, it has to look one period ahead
            limited = 2.0 * i_max - self._i_last > self.i_limit
            self._i_last = i_max
        if self.delay:
            ref, on, substitute = self._next_ref, self._next_on, self._next_sub
            self._next_ref, self._next_on, self._next_sub = self._ref, self._cmd_on, self._run > 0
        else:
            ref, on, substitute = self._ref, self._cmd_on, self._run > 0
        limited = limited and substitute
        on = on and not self._fault
        self.on = on
        if limited and on:  # the current limit while riding through (module docstring)
            self.current_limited += 1
            ref = 0j
        return ref, on

    def _ride_through(self) -> None:
        """A missed reference: substitute the last one turned by omega_u T_s, or coast after the budget."""
        self._run = run = self._run + 1
        self.missed += 1
        if run == 1:
            self.ride_throughs += 1
        if run > self.longest:
            self.longest = run
        if self.ride_through is not None and run * self.T_s > self.ride_through * (1.0 + 1e-9):
            self.inject_fault(SETPOINT_WATCHDOG)
        elif self._omega != 0.0:
            self._ref *= cmath.rect(1.0, self._omega * self.T_s)

    def latch(self, i_s: complex = 0j) -> complex:
        """Start a period: fix the voltage applied over it and return it [V].

        ``i_s`` is the stator current at the boundary (the drive's over-current check and the voltage
        error's sign).
        """
        ref, on = self.pipeline(i_s)
        if not on:
            self.u_applied = 0j
            return 0j
        # SVPWM linear range: |u| <= u_dc/sqrt(3), angle kept
        lim = self.u_dc / SQRT3
        mag = abs(ref)
        if mag > lim:
            ref = ref * (lim / mag)
        if self._verr:
            ref = ref + self.voltage_error(i_s)
        self.u_applied = ref
        return ref

    def voltage_error(self, i_s: complex) -> complex:
        """Space vector (3.17) of the per-phase errors -(t_d f_pwm u_dc + v_on_x) sgn(i_x) [V]
        (module docstring) for the stator current i_s [A]."""
        va, vb, vc = self.v_on
        return complex(*voltage_error(self.dead_time * self.f_pwm * self.u_dc, va, vb, vc, self.i_knee, i_s.real,
                                      i_s.imag))  # fmt: skip


def voltage_error(dt: float, va: float, vb: float, vc: float, k: float, i_re: float, i_im: float
                  ) -> tuple[float, float]:  # fmt: skip
    """(re, im) of the voltage error [V] for the stator current i_s = i_re + j i_im [A]: the dead time's share
    dt = t_d f_pwm u_dc, the on-state drops va, vb, vc, the soft knee k [A] (0: the sign), per phase, then the
    amplitude-invariant transform (3.17), whose common-mode part drops out (isolated neutral). Plain Python that
    numba compiles: the compiled plant (mock_hw.compiled) calls this one."""
    re, h = i_re, _H * i_im
    ia, ib, ic = re, -0.5 * re + h, -0.5 * re - h  # phase currents, inverse of (3.17)
    if k > 0.0:
        k2 = k * k
        sa, sb, sc = ia / math.sqrt(ia * ia + k2), ib / math.sqrt(ib * ib + k2), ic / math.sqrt(ic * ic + k2)
    else:  # sgn, 0 at 0
        sa = 1.0 if ia > 0.0 else (-1.0 if ia < 0.0 else 0.0)
        sb = 1.0 if ib > 0.0 else (-1.0 if ib < 0.0 else 0.0)
        sc = 1.0 if ic > 0.0 else (-1.0 if ic < 0.0 else 0.0)
    ea = -(dt + va) * sa
    eb = -(dt + vb) * sb
    ec = -(dt + vc) * sc
    return (2.0 * ea - eb - ec) / 3.0, (eb - ec) / SQRT3
