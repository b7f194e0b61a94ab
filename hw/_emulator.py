"""A register-level ADS1115 emulator with smbus2's method names, and a fake clock for tests.

The emulator is lazy: it has no thread. Every bus access first brings the chip's state up to
the current time of its clock (which may be the real ``time.monotonic_ns`` or a
:class:`FakeClock`), so conversion timing, continuous back-to-back conversions and the
ALERT/RDY pulse follow the clock exactly.
"""

from __future__ import annotations

import collections
import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from whiskerid.io import Recording, read_recording
from whiskerid.io._ads1115_spec import (
    CONFIG_POWER_ON,
    DATA_RATE_SPS,
    PGA_FSR_V,
    REG_CONFIG,
    REG_CONVERSION,
    REG_HI_THRESH,
    REG_LO_THRESH,
)

from ._ads1115 import (
    COMP_POL_MASK,
    COMP_QUE_MASK,
    DR_MASK,
    DR_SHIFT,
    MODE_MASK,
    MUX_MASK,
    MUX_SHIFT,
    OS_MASK,
    PGA_MASK,
    PGA_SHIFT,
    volts_to_code,
)

Source = Callable[[Any], Any]

#: Length of the ALERT/RDY pulse in continuous conversion-ready mode (datasheet: about 8 us).
RDY_PULSE_S = 8e-6

# MUX bits -> (positive input, negative input or None for GND).
_MUX_INPUTS = {0: (0, 1), 1: (0, 3), 2: (1, 3), 3: (2, 3), 4: (0, None), 5: (1, None),
               6: (2, None), 7: (3, None)}  # fmt: skip


class FakeClock:
    """A monotonic clock that only moves when told to; ``sleep`` advances it instantly.

    Pass ``clock=fake.now_ns, sleep=fake.sleep`` to the driver, emulator and sampler so a test
    runs a minute of schedule in milliseconds.

    Args:
        start_ns: Initial reading in nanoseconds.
    """

    def __init__(self, start_ns: int = 0) -> None:
        self._t_ns = int(start_ns)
        self.sleeps = 0

    def now_ns(self) -> int:
        """Current time in integer nanoseconds."""
        return self._t_ns

    def now_s(self) -> float:
        """Current time in seconds."""
        return self._t_ns * 1e-9

    def sleep(self, seconds: float) -> None:
        """Advance the clock by ``seconds`` (negative values are ignored, like a real sleep)."""
        self.sleeps += 1
        self.advance(max(0.0, seconds))

    def advance(self, seconds: float) -> None:
        """Advance the clock by ``seconds`` (rounded to the nearest nanosecond)."""
        if seconds < 0:
            raise ValueError("a monotonic clock cannot go back")
        # Nearest, not ceil: sleep(n * 1e-9) must advance exactly n ns for integer n.
        self._t_ns += round(seconds * 1e9)

    def advance_to_ns(self, t_ns: int) -> None:
        """Set the clock to ``t_ns`` if that is later than now."""
        self._t_ns = max(self._t_ns, int(t_ns))


def source_from_recording(
    t: Sequence[float] | np.ndarray | str | os.PathLike[str] | Recording,
    v: Sequence[float] | np.ndarray | None = None,
    *,
    column: str | None = None,
    periodic: bool = False,
) -> Source:
    """Make a signal source that linearly interpolates a recording.

    Args:
        t: Sample times in seconds, strictly increasing (need not be uniform); or a recording
            in volts (a :class:`whiskerid.io.Recording`, or a file that
            :func:`whiskerid.io.read_recording` reads), with ``v`` left out.
        v: Values in volts at those times.
        column: The recording's signal column (the first by default).
        periodic: If True, repeat the recording with period ``t[-1] - t[0]`` (to stream a short
            recording for a long time); otherwise hold the end values outside it.

    Returns:
        ``source(t_s) -> volts`` accepting a float or an array of times.

    Raises:
        ValueError: Bad times or values, or a recording whose units are ADC codes.
    """
    if v is None:
        t, v = _volts_of(t, column)
    # Contiguous copies, once: np.interp copies a strided array (a column of a table read
    # from CSV) on every call, which made each conversion cost the whole recording.
    t_arr = np.ascontiguousarray(t, dtype=np.float64)
    v_arr = np.ascontiguousarray(v, dtype=np.float64)
    if t_arr.ndim != 1 or t_arr.shape != v_arr.shape or t_arr.size < 2:
        raise ValueError("t and v must be 1-D arrays of the same length (at least 2 samples)")
    if not np.all(np.diff(t_arr) > 0):
        raise ValueError("recording times must be strictly increasing")
    t_start, span = t_arr[0], t_arr[-1] - t_arr[0]

    def source(t_s: Any) -> Any:
        q = np.asarray(t_s, dtype=np.float64)
        if periodic:
            q = t_start + np.mod(q - t_start, span)
        out = np.interp(q, t_arr, v_arr)
        return float(out) if out.ndim == 0 else out

    return source


def replay_sources(
    rec: str | os.PathLike[str] | Recording, names: Sequence[str], *, fsr_v: float | None = None
) -> list[Source]:
    """One source per input name, replaying a recording through the emulated chip.

    Each input plays the column of its own name (at its own times, ``t_<name>``), else the
    first column. A recording in ADC codes (``units: code``, what the stream and
    ``whiskerid record`` write by default) is turned back into volts with its ``fsr_v``
    metadata (or ``fsr_v``, default the driver's 4.096 V), so the chip reads the same codes.

    Raises:
        ValueError: Units other than volts or codes.
    """
    if not isinstance(rec, Recording):
        rec = read_recording(rec)
    units = rec.meta.get("units", "V")
    scale = 1.0
    if units == "code":
        scale = float(rec.meta.get("fsr_v", fsr_v or 4.096)) / 32768.0
    elif units != "V":
        raise ValueError(
            f"{rec.source or 'recording'}: units are {units!r}; a replay needs volts or ADC codes"
        )
    out = []
    for name in names:
        column = name if name in rec.columns else None
        t = rec.time_of(column)
        out.append(source_from_recording(t, np.asarray(rec.signal(column)) * scale))
    return out


def _volts_of(rec: str | os.PathLike[str] | Recording, column: str | None):
    if not isinstance(rec, Recording):
        rec = read_recording(rec)
    if rec.meta.get("units", "V") != "V":
        raise ValueError(
            f"{rec.source or 'recording'}: units are {rec.meta['units']!r}; the emulated chip "
            "is fed volts (convert the column, e.g. with code_to_volts)"
        )
    return rec.time_of(column), rec.signal(column)


def _zero(t_s: Any) -> Any:
    return np.zeros_like(np.asarray(t_s, dtype=np.float64))


class EmulatedADS1115:
    """An ADS1115 on an I2C bus, emulated at register level.

    Modelled: the pointer register; the config register (OS starts a single-shot conversion
    and reads 0 while converting; continuous mode converts back to back and OS reads 0); the
    conversion time ``1 / (DR (1 + clock_error))``; each result is the average of the selected
    input over its conversion window (``n_points`` midpoint samples, giving the first-order
    sinc response of the delta-sigma modulator), plus Gaussian noise, clipped by the PGA to
    +-FSR and to codes -0x8000..0x7FFF, stored as two's complement; Lo/Hi_thresh; ALERT/RDY in
    conversion-ready mode. Not modelled: the threshold comparator, power-up delay, and the
    input range limits of single-ended inputs.

    Args:
        source: Input signal(s): one callable ``source(t_s) -> volts`` (on AIN0), or a sequence
            of up to four callables or None (grounded) for AIN0..AIN3. Callables get float
            arrays of times in seconds since the emulator was created.
        address: 7-bit I2C address the chip answers on; other addresses NACK.
        clock_error: Oscillator error as a fraction; +0.05 makes conversions 5% faster.
        noise_v: Input-referred noise per conversion, volts RMS.
        seed: Seed of the noise generator.
        n_points: Samples of the source averaged per conversion.
        clock: Monotonic clock in integer nanoseconds.
        sleep: Sleep function in seconds (used for the injected read delay).
        log_limit: How many recent writes and reads to keep in :attr:`writes` and :attr:`reads`.

    Attributes:
        writes: Recent writes as ``(register, bytes)``, oldest first.
        reads: Recent reads as ``(register, bytes)``, oldest first.
        conversions: Number of conversions completed.
        read_delay_s: Extra time each read transfer takes (fault injection).
        never_ready: If True, started conversions never finish (fault injection).
        stuck_code: If not None, the conversion register always reads this code.
        error_rate: Fraction of transfers that fail at random (fault injection).
        error: What a random failure raises (default ``OSError(121)``, a NACK).
    """

    def __init__(
        self,
        source: Source | Sequence[Source | None] | None = None,
        *,
        address: int = 0x48,
        clock_error: float = 0.0,
        noise_v: float = 0.0,
        seed: int | None = 0,
        n_points: int = 16,
        clock: Callable[[], int] = time.monotonic_ns,
        sleep: Callable[[float], None] = time.sleep,
        log_limit: int = 10_000,
    ) -> None:
        if source is None:
            inputs: list[Source | None] = []
        elif callable(source):
            inputs = [source]
        else:
            inputs = list(source)
        if len(inputs) > 4:
            raise ValueError(f"the ADS1115 has 4 inputs, got {len(inputs)} sources")
        self.inputs: list[Source] = [s or _zero for s in inputs] + [_zero] * (4 - len(inputs))
        if not clock_error > -1.0:
            raise ValueError(f"clock_error must be > -1, got {clock_error}")
        if n_points < 1:
            raise ValueError(f"n_points must be >= 1, got {n_points}")
        self.address = address
        self.clock_error = float(clock_error)
        self.noise_v = float(noise_v)
        self.n_points = int(n_points)
        self._rng = np.random.default_rng(seed)
        self._clock = clock
        self._sleep = sleep
        self.origin_ns = clock()
        self.writes: collections.deque[tuple[int, bytes]] = collections.deque(maxlen=log_limit)
        self.reads: collections.deque[tuple[int, bytes]] = collections.deque(maxlen=log_limit)
        self.conversions = 0
        self.read_delay_s = 0.0
        self.never_ready = False
        self.stuck_code: int | None = None
        self.error_rate = 0.0
        self.error: BaseException | None = None
        self._fault_rng = np.random.default_rng(None if seed is None else [seed, 1])
        self.closed = False
        self._faults: collections.deque[BaseException | None] = collections.deque()
        self.reset()

    # -- chip state --

    def reset(self) -> None:
        """Return to the power-on state (config 0x8583, thresholds 0x8000 / 0x7FFF)."""
        self.pointer = REG_CONVERSION
        self._config = CONFIG_POWER_ON & ~OS_MASK  # bits 14:0; OS is derived from the state
        self._lo = 0x8000
        self._hi = 0x7FFF
        self._conversion = 0  # signed code
        self._busy = False  # a single-shot conversion is running
        self._ss_window: tuple[int, int, int] | None = None  # (start_ns, end_ns, config)
        self._rdy_latched = False  # single-shot: asserted from conversion end to next start
        self._cont: tuple[int, float, int] | None = None  # (t0_ns, period_ns, config)
        self._cont_done = -1  # index of the last continuous conversion stored
        self._last_end_ns: int | None = None

    def time_s(self) -> float:
        """The emulator's current time in seconds (the time axis its sources see)."""
        return (self._clock() - self.origin_ns) * 1e-9

    def conversion_time_s(self, data_rate_sps: float | None = None) -> float:
        """Actual conversion time in seconds, including the oscillator error.

        Args:
            data_rate_sps: Data rate; default the one currently configured.
        """
        if data_rate_sps is None:
            data_rate_sps = DATA_RATE_SPS[(self._config & DR_MASK) >> DR_SHIFT]
        return 1.0 / (data_rate_sps * (1.0 + self.clock_error))

    def _period_ns(self, config: int) -> float:
        return 1e9 * self.conversion_time_s(DATA_RATE_SPS[(config & DR_MASK) >> DR_SHIFT])

    def _convert(self, start_ns: float, end_ns: float, config: int) -> None:
        """Store the result of one conversion over the window [start_ns, end_ns]."""
        frac = (np.arange(self.n_points) + 0.5) / self.n_points
        t_s = (start_ns - self.origin_ns + frac * (end_ns - start_ns)) * 1e-9
        pos, neg = _MUX_INPUTS[(config & MUX_MASK) >> MUX_SHIFT]
        volts = self._mean(self.inputs[pos], t_s)
        if neg is not None:
            volts -= self._mean(self.inputs[neg], t_s)
        if self.noise_v > 0:
            volts += self.noise_v * self._rng.standard_normal()
        fsr = PGA_FSR_V[(config & PGA_MASK) >> PGA_SHIFT]
        self._conversion = volts_to_code(volts, fsr)  # clips to +-FSR and to the code range
        self.conversions += 1

    @staticmethod
    def _mean(src: Source, t_s: np.ndarray) -> float:
        v = np.broadcast_to(np.asarray(src(t_s), dtype=np.float64), t_s.shape)
        return float(v.mean())

    def _update(self) -> int:
        """Finish every conversion due by now; return now (ns)."""
        now = self._clock()
        if self.never_ready:
            return now
        if self._busy and self._ss_window is not None and now >= self._ss_window[1]:
            start, end, config = self._ss_window
            self._convert(start, end, config)
            self._busy = False
            self._rdy_latched = True
            self._last_end_ns = end
        if self._cont is not None:
            t0, period, config = self._cont
            latest = math.floor((now - t0) / period) - 1  # last conversion whose window ended
            if latest > self._cont_done:
                # Only the newest result is visible in the register; skipped ones still count.
                self._convert(t0 + latest * period, t0 + (latest + 1) * period, config)
                self.conversions += latest - self._cont_done - 1
                self._cont_done = latest
                self._last_end_ns = round(t0 + (latest + 1) * period)
        return now

    def _write_config(self, word: int, now: int) -> None:
        self._config = word & ~OS_MASK
        if not word & MODE_MASK:  # continuous: (re)start the back-to-back conversions now
            self._busy = False
            self._ss_window = None
            self._cont = (now, self._period_ns(word), self._config)
            self._cont_done = -1
            self._rdy_latched = False
            return
        self._cont = None  # back to single-shot / power-down
        if word & OS_MASK and not self._busy:  # OS=1 has no effect while converting
            self._busy = True
            self._rdy_latched = False
            self._ss_window = (now, now + round(self._period_ns(word)), self._config)

    def _register_value(self, register: int) -> int:
        if register == REG_CONVERSION:
            code = self._conversion if self.stuck_code is None else self.stuck_code
            return code & 0xFFFF  # two's complement storage
        if register == REG_CONFIG:
            idle = not self._busy and self._cont is None
            return self._config | (OS_MASK if idle else 0)
        if register == REG_LO_THRESH:
            return self._lo
        return self._hi

    def _rdy_mode(self) -> bool:
        return (
            bool(self._hi & 0x8000)
            and not self._lo & 0x8000
            and (self._config & COMP_QUE_MASK) != COMP_QUE_MASK
        )

    def rdy(self) -> bool:
        """True while ALERT/RDY is asserted as a conversion-ready signal.

        Needs conversion-ready mode (Hi_thresh MSB 1, Lo_thresh MSB 0, COMP_QUE not 11). In
        single-shot mode the pin stays asserted from the end of a conversion until the next one
        starts; in continuous mode it pulses for 8 us at the end of each conversion.
        """
        now = self._update()
        if not self._rdy_mode():
            return False
        if self._cont is not None:
            return (
                self._last_end_ns is not None and 0 <= now - self._last_end_ns < RDY_PULSE_S * 1e9
            )
        return self._rdy_latched

    def alert_level(self) -> bool:
        """Electrical level of the ALERT/RDY pin (True = high, the pull-up's idle level)."""
        asserted = self.rdy()
        active_high = bool(self._config & COMP_POL_MASK)
        return asserted if active_high else not asserted

    # -- fault injection --

    def fail_next(self, n: int = 1, exc: BaseException | None = None) -> None:
        """Make the next ``n`` transfers raise ``exc`` (default ``OSError(121)``, a NACK)."""
        self._faults.extend([exc] * n)

    def _begin(self, address: int) -> None:
        """Checks common to every transfer: open bus, matching address, injected faults."""
        if self.closed:
            raise OSError(9, "Bad file descriptor (bus closed)")
        if self._faults:
            exc = self._faults.popleft()
            raise exc if exc is not None else OSError(121, "Remote I/O error")
        if self.error_rate > 0 and self._fault_rng.random() < self.error_rate:
            raise self.error if self.error is not None else OSError(121, "Remote I/O error")
        if address != self.address:
            raise OSError(121, f"Remote I/O error (no device at {address:#04x})")

    # -- smbus2 interface --

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Sequence[int], force: bool | None = None
    ) -> None:
        """Set the pointer to ``register`` and write ``data`` (MSB first) into it."""
        self._begin(i2c_addr)
        payload = bytes(data)
        now = self._update()
        self.pointer = register & 0x03
        self.writes.append((register, payload))
        if len(payload) == 0:
            return
        if len(payload) != 2:
            raise OSError(5, f"Input/output error: ADS1115 registers take 2 bytes, got {payload!r}")
        value = payload[0] << 8 | payload[1]
        if self.pointer == REG_CONFIG:
            self._write_config(value, now)
        elif self.pointer == REG_LO_THRESH:
            self._lo = value
        elif self.pointer == REG_HI_THRESH:
            self._hi = value
        # The conversion register is read-only: the chip ignores the data.

    def read_i2c_block_data(
        self, i2c_addr: int, register: int, length: int, force: bool | None = None
    ) -> list[int]:
        """Set the pointer to ``register`` and read ``length`` bytes, MSB first."""
        self._begin(i2c_addr)
        self.pointer = register & 0x03
        return self._read(length)

    def _read(self, length: int) -> list[int]:
        if self.read_delay_s > 0:
            self._sleep(self.read_delay_s)
        self._update()
        value = self._register_value(self.pointer)
        two = [value >> 8, value & 0xFF]
        # Reading past the LSB repeats the register on the real chip.
        out = [two[i % 2] for i in range(length)]
        self.reads.append((self.pointer, bytes(out)))
        return out

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        """Write the pointer register only (a one-byte write)."""
        self._begin(i2c_addr)
        self._update()
        self.pointer = value & 0x03
        self.writes.append((self.pointer, b""))

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        """Read one byte (the MSB) of the register the pointer selects."""
        self._begin(i2c_addr)
        return self._read(1)[0]

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus word read, little-endian like the real smbus2: the ADS1115's bytes come back
        swapped. Present so that a driver using it fails its tests as it would on hardware."""
        self._begin(i2c_addr)
        self.pointer = register & 0x03
        msb, lsb = self._read(2)
        return lsb << 8 | msb

    def close(self) -> None:
        """Close the bus; later transfers raise ``OSError``."""
        self.closed = True

    def __enter__(self) -> EmulatedADS1115:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class EmulatedBus:
    """Several emulated chips on one I2C bus, each answering on its own address.

    Args:
        chips: The chips (:class:`EmulatedADS1115`), with distinct addresses.
    """

    def __init__(self, chips: Sequence[EmulatedADS1115]) -> None:
        self.chips = {c.address: c for c in chips}
        if len(self.chips) != len(chips):
            raise ValueError("two emulated chips share an address")

    def _chip(self, address: int) -> EmulatedADS1115:
        chip = self.chips.get(address)
        if chip is None:
            raise OSError(121, f"Remote I/O error (no device at {address:#04x})")
        return chip

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int],
                             force: bool | None = None) -> None:  # fmt: skip
        """Write to the chip at ``i2c_addr``."""
        self._chip(i2c_addr).write_i2c_block_data(i2c_addr, register, data)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int,
                            force: bool | None = None) -> list[int]:  # fmt: skip
        """Read from the chip at ``i2c_addr``."""
        return self._chip(i2c_addr).read_i2c_block_data(i2c_addr, register, length)

    def close(self) -> None:
        """Close every chip's bus."""
        for chip in self.chips.values():
            chip.close()

    def __enter__(self) -> EmulatedBus:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
