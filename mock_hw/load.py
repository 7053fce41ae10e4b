"""DC load motor with its torque-controlled drive (thesis 3.7, App. A.6) (`LoadPort`).

The torque reference (from the PC's DAC) is clipped to +-torque_limit and followed by the drive's
current loop, modelled as a first-order lag tau (default 2 ms, an assumption: the thesis gives no
data). The output m_L acts in the motor's mechanics (3.37): positive m_L brakes positive rotation
(and drives the shaft backwards at standstill: the DC drive is active, not a brake).

The lag is discretised exactly for a reference held over each period; the plant passes the *mean*
torque over the period to the motor, so the speed's response to the lag is exact too. A new
reference acts from the start of the period in which it was written (the DAC path has no sample
delay; the 2 ms lag dominates).
"""

from __future__ import annotations

import math


class DcLoadDrive:
    """Torque-controlled DC load drive: limit + first-order lag."""

    def __init__(self, *, tau: float = 2e-3, torque_limit: float = 15.0) -> None:
        if not tau > 0 or not torque_limit > 0:
            raise ValueError("tau and torque_limit must be > 0")
        self.tau = float(tau)
        self.torque_limit = float(torque_limit)
        self._h = -1.0
        self.reset()

    def reset(self) -> None:
        self.m_L_ref = 0.0  # clipped reference [N m]
        self.m_L = 0.0  # output torque [N m]

    def set_torque(self, m_L_ref: float) -> None:
        lim = self.torque_limit
        self.m_L_ref = lim if m_L_ref > lim else (-lim if m_L_ref < -lim else float(m_L_ref))

    def advance(self, h: float) -> float:
        """Advance the lag by h [s]; return the mean torque over the step [N m]."""
        if h != self._h:
            self._h = h
            self._e, self._mean = lag_coefficients(self.tau, h)
        self.m_L, mean = lag_step(self.m_L_ref, self.m_L, self._e, self._mean)
        return mean


# The lag's kernels, plain Python that numba compiles: the compiled plant (mock_hw.compiled) calls the same two.
def lag_coefficients(tau: float, h: float) -> tuple[float, float]:
    """(e, mean) of the exact discretisation of tau dm/dt = ref - m over h [s] with the reference held:
    e = e^{-h/tau}, mean = (1/h) int_0^h e^{-t/tau} dt."""
    e = math.exp(-h / tau)
    return e, tau / h * (1.0 - e)


def lag_step(ref: float, m0: float, e: float, mean: float) -> tuple[float, float]:
    """One step of the lag from m0 towards ref [N m]: (m at the step's end, its mean over the step)."""
    d = m0 - ref
    return ref + d * e, ref + d * mean
