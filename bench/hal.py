"""Hardware abstraction layer: the rig's ports, the per-tick records and the rig lifecycle.

The ports mirror the hardware functions of the thesis' lab (App. A): the inverter's stator-voltage
reference (A.2), the three LEM current channels (A.3), the three filtered voltage channels (A.4),
the quadrature encoder (A.5) and the DC-load torque command (A.6).

Everything that crosses this boundary is in SI units; raw ADC codes and encoder counts are also
passed up, unscaled, so they can be logged. Scaling lives in the devices below the HAL.

Lifecycle (as in ros2_control's hardware components): ``configure -> activate -> (read/write)* ->
deactivate``. ``deactivate`` and ``safe`` always leave the safe state: inverter disabled (coasting),
zero voltage reference, load torque 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from collections.abc import Callable
from typing import NamedTuple, Protocol, runtime_checkable

SQRT3_INV = 1.0 / math.sqrt(3.0)


def space_vector(a: float, b: float, c: float) -> complex:
    """Amplitude-invariant space vector (3.17): 2/3 (x_a + a x_b + a^2 x_c)."""
    return complex((2.0 * a - b - c) / 3.0, (b - c) * SQRT3_INV)


def phase_values(x: complex) -> tuple[float, float, float]:
    """Inverse of `space_vector` for a zero-sequence-free triple (isolated neutral, (3.1))."""
    re, im = x.real, x.imag
    h = 0.5 * math.sqrt(3.0) * im
    return re, -0.5 * re + h, -0.5 * re - h


class InverterStatus(NamedTuple):
    enabled: bool  # bridge is switching
    fault: bool  # drive reports a fault (latched in the drive)
    u_dc: float  # DC-link voltage [V]
    fault_name: str = ""  # which fault, when the drive says (set-point watchdog, over-current, ...)


class RigState(Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"  # configured, outputs safe
    ACTIVE = "active"


@dataclass(slots=True)
class Measurement:
    """One sample of all rig inputs, taken at loop time ``t`` [s]."""

    t: float
    i_a: float  # phase currents [A] (LEM, A.3)
    i_b: float
    i_c: float
    u_a: float  # phase-to-neutral voltages behind the 1 kHz filter [V] (A.4)
    u_b: float
    u_c: float
    enc_count: int  # x4-decoded quadrature counter, as read (wraps at the counter modulus)
    enc_index: int  # counter value latched at the last index pulse, -1 if none yet
    u_dc: float  # DC-link voltage [V]
    inv_enabled: bool
    inv_fault: bool
    raw_i: tuple[int, int, int]  # ADC codes of the current channels
    raw_u: tuple[int, int, int]  # ADC codes of the voltage channels
    status: int = 0  # link/driver status bits (ST_* below), OR-ed over the rig's devices
    inv_fault_name: str = ""  # which fault the drive reports (InverterStatus.fault_name); not logged per tick

    @property
    def i_s(self) -> complex:
        """Stator current space vector, stator-fixed (3.17) [A]."""
        return space_vector(self.i_a, self.i_b, self.i_c)

    @property
    def u_s(self) -> complex:
        """Measured (filtered) stator voltage space vector, stator-fixed [V]."""
        return space_vector(self.u_a, self.u_b, self.u_c)


# --- status bits (Measurement.status) ---------------------------------------------------------
# Drivers report the health of their links through a ``status_bits`` attribute; `Rig.read` ORs them
# into ``Measurement.status`` every tick. The in-process mock rig always reports 0. The supervisor
# (bench.core.supervisor) decides which bits, or which bursts of them, trip. A bit describes this tick.
ST_MEAS_STALE = 1 << 0  # no fresh measurement frame for this tick: the values are the last good ones
ST_MEAS_LOST = 1 << 1  # a gap in the frame sequence numbers was seen (frames lost)
ST_MEAS_DUP = 1 << 2  # a duplicated frame was seen (and discarded)
ST_MEAS_LATE = 1 << 3  # a frame arrived after its tick (and was discarded)
ST_MEAS_CRC = 1 << 4  # a frame failed its CRC (or framing) check
ST_LINK_DOWN = 1 << 5  # a transport is disconnected; the driver is reconnecting
ST_INV_STALE = 1 << 6  # inverter status frame (heartbeat) missing beyond its timeout
ST_INV_COMM = 1 << 7  # inverter parameter channel (Modbus) failed
ST_ENC_ERROR = 1 << 8  # the front-end flags an encoder error (its status bits)
ST_ADC_CLIP = 1 << 9  # an ADC channel is at the end of its range
ST_NAMES: dict[int, str] = {
    ST_MEAS_STALE: "meas_stale", ST_MEAS_LOST: "meas_lost", ST_MEAS_DUP: "meas_dup", ST_MEAS_LATE: "meas_late",
    ST_MEAS_CRC: "meas_crc", ST_LINK_DOWN: "link_down", ST_INV_STALE: "inv_stale", ST_INV_COMM: "inv_comm",
    ST_ENC_ERROR: "enc_error", ST_ADC_CLIP: "adc_clip",
}  # fmt: skip


def status_names(status: int) -> list[str]:
    """Names of the set ST_* bits, for messages."""
    return [name for bit, name in ST_NAMES.items() if status & bit]


MEAS_FIELDS: tuple[str, ...] = (
    "i_a", "i_b", "i_c", "u_a", "u_b", "u_c", "enc_count", "enc_index", "u_dc",
    "inv_enabled", "inv_fault", "raw_i_a", "raw_i_b", "raw_i_c", "raw_u_a", "raw_u_b", "raw_u_c", "status",
)  # fmt: skip


def meas_values(m: Measurement) -> tuple:
    """Flatten a measurement in MEAS_FIELDS order (for logging)."""
    ri, ru = m.raw_i, m.raw_u
    return (m.i_a, m.i_b, m.i_c, m.u_a, m.u_b, m.u_c, m.enc_count, m.enc_index, m.u_dc,
            m.inv_enabled, m.inv_fault, ri[0], ri[1], ri[2], ru[0], ru[1], ru[2], m.status)  # fmt: skip


@dataclass(slots=True)
class Command:
    """What the loop writes to the rig each tick."""

    u_s_ref: complex = 0j  # stator-voltage reference, stator-fixed [V]
    enable: bool = False  # inverter enable; False = coast
    m_L_ref: float = 0.0  # DC-load torque command [N m]; positive brakes positive rotation (3.37)
    # electrical frequency [rad/s] at which the drive keeps turning u_s_ref while no new reference comes (a
    # loop stall): the stator frequency of the field the reference belongs to; 0 holds it (`InverterPort`)
    omega_u: float = 0.0


SAFE_COMMAND = Command()


# --- ports ------------------------------------------------------------------------------------
@runtime_checkable
class Device(Protocol):
    """Something the rig owns and sequences: a driver, or the mock plant."""

    def configure(self) -> None: ...
    def activate(self) -> None: ...
    def deactivate(self) -> None: ...
    def acquire(self, t: float) -> None:
        """Latch one sample for loop time ``t`` (read a frame, advance a simulation, ...)."""
        ...


class InverterPort(Protocol):
    """The drive's reference channel.

    Stall ride-through (as drives with cyclic set-points extrapolate a missed one): each reference comes
    with the electrical frequency ``omega_u`` of the field it belongs to. A drive that misses the next
    reference keeps turning the last one at that frequency, counts the missed references, and after
    the rig's ``ride_through`` budget coasts with a latched set-point watchdog fault.
    """

    u_dc_nominal: float

    def set_voltage(self, u_s_ref: complex, omega_u: float = 0.0) -> None: ...
    def enable(self) -> None: ...
    def disable(self) -> None: ...
    def status(self) -> InverterStatus: ...


class PhaseSensorPort(Protocol):
    """Three phase channels (LEM currents or the voltage bridge)."""

    def read(self) -> tuple[float, float, float]: ...
    def read_raw(self) -> tuple[int, int, int]: ...


class EncoderPort(Protocol):
    counts_per_rev: int  # 4 x lines
    modulus: int  # counter wraps at this value

    def read(self) -> tuple[int, int]:
        """(count, index) - index is the count latched at the last index pulse, or -1."""
        ...


class LoadPort(Protocol):
    torque_limit: float  # [N m]

    def set_torque(self, m_L_ref: float) -> None: ...


class GroundTruth(Protocol):
    """Only the mock plant has one. Logged, and read by tests; never passed to controllers."""

    fields: tuple[str, ...]

    def sample(self) -> tuple[float, ...]: ...


class LifecycleError(RuntimeError):
    pass


class Rig:
    """A set of ports plus the devices behind them, with a lifecycle.

    ``read(t)`` latches a sample on every device and assembles a `Measurement`;
    ``write(cmd)`` sends the voltage reference/enable and the load torque command.
    """

    def __init__(
        self,
        *,
        name: str,
        inverter: InverterPort,
        currents: PhaseSensorPort,
        voltages: PhaseSensorPort,
        encoder: EncoderPort,
        load: LoadPort,
        devices: list[Device],
        truth: GroundTruth | None = None,
        measure: Callable[[float], Measurement] | None = None,
    ) -> None:
        self.name = name
        self.inverter = inverter
        self.currents = currents
        self.voltages = voltages
        self.encoder = encoder
        self.load = load
        self.devices = devices
        self.truth = truth
        self.state = RigState.UNCONFIGURED
        self._enabled = False
        # devices that report link health (drivers): their ``status_bits`` go into Measurement.status
        self._status_devices = [d for d in devices if hasattr(d, "status_bits")]
        # a single device behind every port may assemble the Measurement itself in one call (the mock
        # plant: the lockstep tick is the budget of every sweep); it must equal what `read` assembles
        self._measure = measure

    # lifecycle ------------------------------------------------------------------------------
    def configure(self) -> None:
        if self.state is not RigState.UNCONFIGURED:
            raise LifecycleError(f"configure() in state {self.state.value}")
        for d in self.devices:
            d.configure()
        self.state = RigState.INACTIVE

    def activate(self) -> None:
        if self.state is not RigState.INACTIVE:
            raise LifecycleError(f"activate() in state {self.state.value}")
        for d in self.devices:
            d.activate()
        self.safe()
        self.state = RigState.ACTIVE

    def deactivate(self) -> None:
        """Leave the safe state and release the devices. Safe to call more than once."""
        if self.state is RigState.UNCONFIGURED:
            return
        try:
            self.safe()
        finally:
            for d in reversed(self.devices):
                d.deactivate()
            self.state = RigState.INACTIVE

    def __enter__(self) -> "Rig":
        if self.state is RigState.UNCONFIGURED:
            self.configure()
        self.activate()
        return self

    def __exit__(self, *exc: object) -> None:
        self.deactivate()

    # per tick ------------------------------------------------------------------------------
    def read(self, t: float) -> Measurement:
        if self._measure is not None:
            return self._measure(t)
        for d in self.devices:
            d.acquire(t)
        i_a, i_b, i_c = self.currents.read()
        u_a, u_b, u_c = self.voltages.read()
        count, index = self.encoder.read()
        st = self.inverter.status()
        bits = 0
        for d in self._status_devices:
            bits |= d.status_bits
        return Measurement(t, i_a, i_b, i_c, u_a, u_b, u_c, count, index, st.u_dc, st.enabled,
                           st.fault, self.currents.read_raw(), self.voltages.read_raw(), bits,
                           st.fault_name)  # fmt: skip

    def write(self, cmd: Command) -> None:
        if cmd.enable:
            if not self._enabled:
                self.inverter.enable()
                self._enabled = True
            self.inverter.set_voltage(cmd.u_s_ref, cmd.omega_u)
        elif self._enabled:
            self.inverter.set_voltage(0j)
            self.inverter.disable()
            self._enabled = False
        self.load.set_torque(cmd.m_L_ref)

    def safe(self) -> None:
        """Safe state: zero reference, inverter disabled (coast), load torque 0."""
        self.inverter.set_voltage(0j)
        self.inverter.disable()
        self._enabled = False
        self.load.set_torque(0.0)
