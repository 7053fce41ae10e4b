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
  `status` until `reset_fault`; the drive then needs a new `enable`.
"""

from __future__ import annotations

import math

from bench.hal import InverterStatus

SQRT3 = math.sqrt(3.0)
_H = 0.5 * SQRT3


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

    # --- InverterPort ----------------------------------------------------------------------
    @property
    def u_max(self) -> float:
        """Largest vector amplitude in the SVPWM linear range, u_dc/sqrt(3) [V]."""
        return self.u_dc / SQRT3

    def set_voltage(self, u_s_ref: complex) -> None:
        self._ref = u_s_ref

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
    def latch(self, i_s: complex = 0j) -> complex:
        """Start a period: fix the voltage applied over it and return it [V].

        ``i_s`` is the stator current at the boundary (only used for the voltage error's sign).
        """
        if self.delay:
            ref, on = self._next_ref, self._next_on
            self._next_ref, self._next_on = self._ref, self._cmd_on
        else:
            ref, on = self._ref, self._cmd_on
        on = on and not self._fault
        self.on = on
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
        dt = self.dead_time * self.f_pwm * self.u_dc
        va, vb, vc = self.v_on
        re, h = i_s.real, _H * i_s.imag
        ia, ib, ic = re, -0.5 * re + h, -0.5 * re - h  # phase currents, inverse of (3.17)
        k = self.i_knee
        if k > 0.0:
            k2 = k * k
            sa, sb, sc = ia / math.sqrt(ia * ia + k2), ib / math.sqrt(ib * ib + k2), ic / math.sqrt(ic * ic + k2)
        else:
            sa, sb, sc = _sign(ia), _sign(ib), _sign(ic)
        ea = -(dt + va) * sa
        eb = -(dt + vb) * sb
        ec = -(dt + vc) * sc
        # amplitude-invariant transform; the common-mode part drops out (isolated neutral)
        return complex((2.0 * ea - eb - ec) / 3.0, (eb - ec) / SQRT3)


def _sign(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)
