"""Safety supervisor: trips, independent of the controller, and a latched safe state.

The loop asks the supervisor twice per tick: after reading the rig (over-current, over-speed,
DC-link window, inverter fault) and after the controller (exception, NaN/inf). A trip is latched
until `reset`; while tripped the loop writes the safe command (inverter disabled, load torque 0)
in the same tick the trip was detected.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from bench.encoder import EncoderSpeed
from bench.hal import Measurement


@dataclass(frozen=True, slots=True)
class Limits:
    I_max: float = 10.0  # stator-current amplitude controllers may request [A]
    I_trip: float = 15.0  # space-vector over-current trip [A]
    I_trip_phase: float = 15.0  # per-phase over-current trip [A]
    omega_max: float = 400.0  # over-speed trip, electrical [rad/s]
    u_dc_min: float = 400.0  # DC-link under-voltage trip [V]
    u_dc_max: float = 750.0  # DC-link over-voltage trip [V]

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


class Supervisor:
    def __init__(self, limits: Limits, counts_per_rev: int, modulus: int, Z_p: int, T_s: float) -> None:
        self.limits = limits
        self.speed = EncoderSpeed(counts_per_rev, modulus, Z_p, T_s, tau=0.002)
        self.reset()

    def reset(self) -> None:
        self.tripped = False
        self.cause: str | None = None
        self.trip_t: float | None = None
        self.speed.reset()

    @property
    def omega_r(self) -> float:
        """The supervisor's own encoder speed estimate (electrical, rad/s)."""
        return self.speed.omega_r

    def trip(self, cause: str, t: float) -> None:
        if not self.tripped:
            self.tripped, self.cause, self.trip_t = True, cause, t

    def check_measurement(self, m: Measurement) -> bool:
        """Update and check; returns True if (now or already) tripped."""
        lim = self.limits
        omega = self.speed.update(m.enc_count)
        if self.tripped:
            return True
        ip = lim.I_trip_phase
        if abs(m.i_a) > ip or abs(m.i_b) > ip or abs(m.i_c) > ip:
            worst = max(abs(m.i_a), abs(m.i_b), abs(m.i_c))
            self.trip(f"over-current: phase |i| = {worst:.2f} A > {ip:g} A", m.t)
        elif abs(m.i_s) > lim.I_trip:
            self.trip(f"over-current: |i_s| = {abs(m.i_s):.2f} A > {lim.I_trip:g} A", m.t)
        elif abs(omega) > lim.omega_max:
            self.trip(f"over-speed: |omega_r| = {abs(omega):.1f} rad/s > {lim.omega_max:g} rad/s", m.t)
        elif m.inv_fault:
            self.trip("inverter fault reported", m.t)
        elif not (lim.u_dc_min <= m.u_dc <= lim.u_dc_max):
            self.trip(f"DC link {m.u_dc:.1f} V outside [{lim.u_dc_min:g}, {lim.u_dc_max:g}] V", m.t)
        elif math.isnan(m.i_a + m.i_b + m.i_c):
            self.trip("measurement is NaN", m.t)
        return self.tripped

    def check_command(self, u_s_ref: complex, t: float) -> bool:
        """NaN/inf from the controller trips."""
        if not (math.isfinite(u_s_ref.real) and math.isfinite(u_s_ref.imag)):
            self.trip(f"controller output not finite: {u_s_ref!r}", t)
        return self.tripped
