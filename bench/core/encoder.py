"""Speed and angle from the quadrature encoder counter (App. A.5).

Shared by controllers (speed feedback), the supervisor (over-speed) and scenarios (speed-dependent
loads): it is measurement processing on HAL data, not control.
"""

from __future__ import annotations

import math


class EncoderSpeed:
    """Electrical speed and angle from the quadrature counter (App. A.5).

    The per-sample count difference (modulo the counter wrap) gives the mechanical speed with a
    resolution of 2*pi/counts_per_rev/T_s (about 4.6 rad/s at 4096 counts and 3 kHz); a first-order
    low-pass with time constant ``tau`` smooths it, as the thesis suggests.

    Given the loop time ``t`` of each sample, the difference is divided by the real elapsed time,
    so that ticks a real-time loop skipped (the count kept running) do not read as a speed jump;
    the low-pass then also advances by the elapsed time.
    """

    def __init__(self, counts_per_rev: int, modulus: int, Z_p: int, T_s: float, tau: float) -> None:
        self.modulus = modulus
        self.half = modulus // 2
        self.k_omega = Z_p * 2.0 * math.pi / (counts_per_rev * T_s)  # electrical rad/s per count/tick
        self.k_theta = Z_p * 2.0 * math.pi / counts_per_rev
        self.T_s = T_s
        self.set_tau(tau)
        self._late = 1.5 * T_s  # a gap longer than this is a skipped tick
        self.reset()

    def set_tau(self, tau: float) -> None:
        """A new low-pass time constant [s]; the filtered speed carries on from where it is."""
        self.tau = tau
        self.alpha = 1.0 - math.exp(-self.T_s / tau) if tau > 0 else 1.0

    def reset(self) -> None:
        self._prev: int | None = None
        self.d = 0  # count step of the last update (signed, modulo the wrap; 0 at the first)
        self._prev_t: float | None = None
        self.omega_r = 0.0  # filtered electrical speed [rad/s]
        self.omega_raw = 0.0  # last count difference as a speed [rad/s]: noisy, but integrates to theta_r exactly
        self.theta_r = 0.0  # electrical angle since reset [rad], unwrapped

    def update(self, count: int, t: float | None = None) -> float:
        """New counter value (at loop time ``t`` [s], if known) -> filtered electrical speed [rad/s]."""
        timed = t is not None
        self.d, self.theta_r, self.omega_raw, self.omega_r = encoder_speed_step(
            count, 0 if self._prev is None else self._prev, self._prev is not None, self.modulus, self.half,
            self.theta_r, self.omega_r, self.k_theta, self.k_omega, self.alpha, self.T_s, self._late, self.tau, timed,
            t if timed else 0.0, 0.0 if self._prev_t is None else self._prev_t, self._prev_t is not None)  # fmt: skip
        self._prev = count
        if timed:
            self._prev_t = t
        return self.omega_r


def encoder_speed_step(count: int, prev: int, has_prev: bool, modulus: int, half: int, theta_r: float, omega_r: float,
                       k_theta: float, k_omega: float, alpha: float, T_s: float, late: float, tau: float, timed: bool,
                       t: float, prev_t: float, has_prev_t: bool) -> tuple[int, float, float, float]:  # fmt: skip
    """`EncoderSpeed.update` from the previous count prev (has_prev: there is one) and, where ``timed``, the loop
    times t and prev_t [s]: (count step d, theta_r, omega_raw, omega_r). Plain Python that numba compiles: the compiled
    FOC tick (`bench.controllers.foc_compiled`) calls this one."""
    if not has_prev:
        d = 0
    else:
        d = (count - prev) % modulus  # Python's int %, numba's too
        if d >= half:
            d -= modulus
    theta_r += d * k_theta
    if timed:
        dt = t - prev_t if has_prev_t else T_s
        if dt > late:  # skipped ticks: the count change spans dt, not one period
            omega_raw = d * k_omega * T_s / dt
            a = 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0
            return d, theta_r, omega_raw, omega_r + a * (omega_raw - omega_r)
    omega_raw = d * k_omega
    return d, theta_r, omega_raw, omega_r + alpha * (omega_raw - omega_r)
