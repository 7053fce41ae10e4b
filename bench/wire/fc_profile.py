"""The drive's Danfoss FC profile: its control and status words and its percent registers, as the Modbus
client (`bench.drivers.modbus`) and the emulated drive (`mock_hw.emulators.rig`) both read and write them.

Danfoss FC-profile registers (wire addresses, i.e. register number - 1; all configurable in the
rig file's ``[modbus]`` table):

=============  ======  =====================================================================
control word   49999   CTW, FC profile (bits below)
reference      50009   bus reference 1: u_alpha; 50010: u_beta (customised drive), 0x4000 = U_max
status word    50199   STW, FC profile (bits below)
actual value   50209   main actual value: applied |u_s|, 0x4000 = U_max
DC link        16299   parameter 16-30 DC-link voltage, 0.1 V
=============  ======  =====================================================================

References and actual values are signed 16-bit, two's complement, 0x4000 = 100 %.
"""

from __future__ import annotations

# control word (CTW) bits, FC profile
CTW_NO_DC_BRAKE = 1 << 2
CTW_NO_COAST = 1 << 3
CTW_NO_QSTOP = 1 << 4
CTW_NO_HOLD = 1 << 5
CTW_START = 1 << 6  # ramp start (0 = ramp stop)
CTW_RESET = 1 << 7  # fault reset on the rising edge
CTW_DATA_VALID = 1 << 10
CTW_STOP = CTW_NO_DC_BRAKE | CTW_NO_COAST | CTW_NO_QSTOP | CTW_NO_HOLD | CTW_DATA_VALID  # 0x043C
CTW_RUN = CTW_STOP | CTW_START  # 0x047C
CTW_COAST = CTW_STOP & ~CTW_NO_COAST  # 0x0434
# status word (STW) bits, FC profile
STW_CONTROL_READY = 1 << 0
STW_DRIVE_READY = 1 << 1
STW_TRIP = 1 << 3
STW_WARNING = 1 << 7
STW_BUS_CONTROL = 1 << 9
STW_RUNNING = 1 << 11

PERCENT_100 = 0x4000


def to_percent_word(x: float, full: float) -> int:
    """x/full as a 16-bit register, 0x4000 = 100 %, two's complement, saturating."""
    v = int(round(x / full * PERCENT_100))
    v = max(-0x8000, min(0x7FFF, v))
    return v & 0xFFFF


def from_percent_word(w: int, full: float) -> float:
    w &= 0xFFFF
    if w & 0x8000:
        w -= 0x10000
    return w * full / PERCENT_100
