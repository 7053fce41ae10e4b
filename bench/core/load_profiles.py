"""Load-torque profiles for the DC load: m_L_ref = profile(t, omega_r).

The PC computes the load command from time and the *measured* speed (App. A.6: "this can for
instance be a position or speed dependent load"), so profiles live on the bench side and work the
same against the mock plant and a real rig. Positive m_L brakes positive rotation (3.37).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence

LoadProfile = Callable[[float, float], float]


def constant(m: float) -> LoadProfile:
    return lambda t, omega: m


def steps(times: Sequence[float], values: Sequence[float], before: float = 0.0) -> LoadProfile:
    """Piecewise constant: ``values[i]`` from ``times[i]`` on (times ascending)."""
    ts, vs = list(times), list(values)

    def f(t: float, omega: float = 0.0) -> float:  # (omega unused: also a speed reference f(t))
        i = bisect.bisect_right(ts, t) - 1
        return before if i < 0 else vs[i]

    return f


def square(t0: float, half_period: float, low: float, high: float) -> LoadProfile:
    """``low`` for half a period from t0, then ``high``, alternating; 0 before t0."""

    def f(t: float, omega: float) -> float:
        if t < t0:
            return 0.0
        return high if int((t - t0) / half_period) % 2 else low

    return f


def sign_dependent(base: LoadProfile) -> LoadProfile:
    """``base * sign(omega)``: a load that always brakes (Figs 5.8, 5.11)."""
    return lambda t, omega: base(t, omega) * (1.0 if omega > 0 else -1.0 if omega < 0 else 0.0)


def speed_dependent_641(m_max: float = 8.0, k: float = 0.01) -> LoadProfile:
    """m_L = 8 (1 - 2/(1 + e^{0.01 omega_r})) of Sec. 6.4.1 (equal to 8 tanh(0.005 omega_r))."""
    return lambda t, omega: m_max * (1.0 - 2.0 / (1.0 + math.exp(max(min(k * omega, 700.0), -700.0))))


def gated(profile: LoadProfile, t_on: float, t_off: float = math.inf) -> LoadProfile:
    """``profile`` inside [t_on, t_off), zero elsewhere."""
    return lambda t, omega: profile(t, omega) if t_on <= t < t_off else 0.0
