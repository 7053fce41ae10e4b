"""Measurement front-end: LEM x3, voltage bridge x3 and the encoder counter as a framed serial stream.

The frames are `bench.wire.frontend`'s (wire format, CRC, the resynchronising `FrameParser`).

`FrontEnd` is the driver (a `Device`): it owns the serial link and the scaling and serves three
HAL ports: ``currents``, ``voltages`` (`PhaseSensorPort`) and ``encoder`` (`EncoderPort`).

Per tick (`acquire(t)`) it waits for the frame whose sequence number is the tick number (the
device samples on SYNC), at most ``timeout`` seconds. Frames older than that are discarded
(ST_MEAS_DUP if it repeats the last good one, else ST_MEAS_LATE); a newer one is taken and the
frames before it counted lost (ST_MEAS_LOST); bad CRCs set ST_MEAS_CRC; no frame in time keeps the
last values and sets ST_MEAS_STALE (a dropped frame shows up so, as the device never sends it).

Reconnection: a serial error or a closed socket sets ST_LINK_DOWN and closes the port; every
``reconnect_interval`` seconds one `acquire` tries to reopen it (a refused connection costs
microseconds on loopback). Measurements stay stale until frames flow again; the supervisor trips
after ``limits.stale_ticks`` stale ticks, so a reconnect never hides a gap.

Scaling (all in the rig file's ``[frontend]`` table): i = (code * lsb - offset_i) * turns_ratio /
burden; u = (code * lsb - offset_u) / divider_ratio; lsb = 2 adc_range / 2^adc_bits.
"""

from __future__ import annotations

import time
from typing import Any

import serial

from bench.errors import LinkError
from bench.hal import (
    ST_ADC_CLIP, ST_ENC_ERROR, ST_LINK_DOWN, ST_MEAS_CRC, ST_MEAS_DUP, ST_MEAS_LATE, ST_MEAS_LOST, ST_MEAS_STALE,
)  # fmt: skip
from bench.wire.frontend import FRAME_SIZE, FS_ADC_CLIP, FS_ENC_ERROR, Frame, FrameParser


class _Phases:
    """A `PhaseSensorPort` view on the front-end: three channels of one kind."""

    def __init__(self) -> None:
        self.value: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.raw: tuple[int, int, int] = (0, 0, 0)

    def read(self) -> tuple[float, float, float]:
        return self.value

    def read_raw(self) -> tuple[int, int, int]:
        return self.raw


class _Encoder:
    """An `EncoderPort` view on the front-end."""

    def __init__(self, lines: int, modulus: int) -> None:
        self.counts_per_rev = 4 * lines
        self.modulus = modulus
        self.value: tuple[int, int] = (0, -1)

    def read(self) -> tuple[int, int]:
        return self.value


class FrontEnd:
    """Driver of the measurement front-end (a `Device`), serving currents, voltages and encoder."""

    def __init__(self, serial_cfg: dict[str, Any], fe_cfg: dict[str, Any], T_s: float) -> None:
        self.url = serial_cfg["port"]
        self.baudrate = serial_cfg["baudrate"]
        self.timeout = serial_cfg["timeout"]
        self.reconnect_interval = serial_cfg["reconnect_interval"]
        self.T_s = T_s
        lsb_i = 2.0 * fe_cfg["adc_range"] / (1 << fe_cfg["adc_bits"])
        self.adc_bits = fe_cfg["adc_bits"]
        k_i = fe_cfg["turns_ratio"] / fe_cfg["burden"]  # A per V at the ADC
        k_u = 1.0 / fe_cfg["divider_ratio"]  # V per V at the ADC
        self._scale_i = (lsb_i * k_i, tuple(o * k_i for o in fe_cfg["offset_i"]))
        self._scale_u = (lsb_i * k_u, tuple(o * k_u for o in fe_cfg["offset_u"]))
        self.lsb = lsb_i
        self.modulus = fe_cfg["modulus"]
        self.currents = _Phases()
        self.voltages = _Phases()
        self.encoder = _Encoder(fe_cfg["lines"], self.modulus)
        self.parser = FrameParser()
        self.ser: serial.SerialBase | None = None
        self.status_bits = 0
        self.stats = {"frames": 0, "stale": 0, "lost": 0, "dup": 0, "late": 0, "crc": 0, "reconnects": 0,
                      "skipped": 0}
        self._last_seq: int | None = None
        self._prev_want: int | None = None  # the previous tick's sequence number
        self._next_try = 0.0

    # --- link ---------------------------------------------------------------------------------
    def _open(self) -> bool:
        try:
            self.ser = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=self.timeout)
        except (serial.SerialException, OSError, ValueError):
            self.ser = None
            self._next_try = time.monotonic() + self.reconnect_interval
            return False
        self.parser = FrameParser()
        return True

    def _close(self) -> None:
        if self.ser is not None:
            try:
                self.ser.close()
            except Exception:  # noqa: BLE001 - closing a broken link must not raise
                pass
        self.ser = None

    # --- Device ---------------------------------------------------------------------------------
    def configure(self) -> None:
        if self.ser is None and not self._open():
            raise LinkError("serial.port", f"cannot open {self.url!r} (is the front-end, or `bench emulate`, there?)")

    def activate(self) -> None:
        self._last_seq = self._prev_want = None

    def deactivate(self) -> None:
        pass

    def close(self) -> None:
        self._close()

    def acquire(self, t: float) -> None:
        want = int(round(t / self.T_s)) & 0xFFFF
        bits = 0
        ser = self.ser
        if ser is None:
            bits |= ST_LINK_DOWN
            if time.monotonic() >= self._next_try and self._open():
                self.stats["reconnects"] += 1
                ser = self.ser
        got = False
        if ser is not None:
            crc0 = self.parser.crc_errors
            deadline = time.perf_counter() + self.timeout
            try:
                while not got:
                    data = ser.read(FRAME_SIZE)
                    if data:
                        for fr in self.parser.feed(data):
                            b, ok = self._take(fr, want)
                            bits |= b
                            got = got or ok
                    if got or time.perf_counter() >= deadline:
                        break
            except (serial.SerialException, OSError):
                self._close()
                self._next_try = time.monotonic() + self.reconnect_interval
                bits |= ST_LINK_DOWN
            if self.parser.crc_errors != crc0:
                bits |= ST_MEAS_CRC
                self.stats["crc"] += self.parser.crc_errors - crc0
        if not got:
            bits |= ST_MEAS_STALE
            self.stats["stale"] += 1
        self._prev_want = want
        self.status_bits = bits

    def _take(self, fr: Frame, want: int) -> tuple[int, bool]:
        """Use frame ``fr`` if it is the wanted one (or newer); returns (status bits, used)."""
        seq = fr[0]
        d = (seq - want) & 0xFFFF
        if d >= 0x8000:  # older than wanted
            prev = self._prev_want
            if prev is not None and 0 < (seq - prev) & 0xFFFF < (want - prev) & 0xFFFF:
                self.stats["skipped"] += 1  # sampled for a tick the loop skipped: not late, just unused
                return 0, False
            if seq == self._last_seq:
                self.stats["dup"] += 1
                return ST_MEAS_DUP, False
            self.stats["late"] += 1
            return ST_MEAS_LATE, False
        bits = 0
        if d:  # newer than wanted: the wanted frame and any between were lost (ticks the loop
            bits |= ST_MEAS_LOST  # skipped have no frame, as the device samples on SYNC)
            self.stats["lost"] += d
        self._last_seq = seq
        self.stats["frames"] += 1
        _, st, raw_i, raw_u, cnt, idx = fr
        ki, (oia, oib, oic) = self._scale_i
        ku, (oua, oub, ouc) = self._scale_u
        c = self.currents
        c.raw = raw_i
        c.value = (raw_i[0] * ki - oia, raw_i[1] * ki - oib, raw_i[2] * ki - oic)
        v = self.voltages
        v.raw = raw_u
        v.value = (raw_u[0] * ku - oua, raw_u[1] * ku - oub, raw_u[2] * ku - ouc)
        self.encoder.value = (cnt % self.modulus, idx)
        if st & FS_ENC_ERROR:
            bits |= ST_ENC_ERROR
        if st & FS_ADC_CLIP:
            bits |= ST_ADC_CLIP
        return bits, True
