"""ADS1115 driver over an smbus2-like bus: config codec, single-shot and continuous reads.

The register map and the data-rate and PGA tables live in ``whiskerid.io._ads1115_spec`` (shared
with the signal-level ADC model); this module adds the bit layout of the config register, a
pure encoder/decoder for it, and a driver that retries I2C errors and times out every wait.
"""

from __future__ import annotations

import dataclasses
import struct
import time
from collections.abc import Callable, Sequence
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np

from whiskerid.io._ads1115_spec import (
    CODE_MAX,
    CODE_MIN,
    CONFIG_POWER_ON,
    DATA_RATE_SPS,
    OSCILLATOR_TOLERANCE,
    PGA_FSR_V,
    REG_CONFIG,
    REG_CONVERSION,
    REG_HI_THRESH,
    REG_LO_THRESH,
    check_data_rate,
    check_fsr,
    lsb_volts,
)

# --- Config register bit layout (datasheet table 8) -------------------------------------------
# Each field is (shift, width); mask = ((1 << width) - 1) << shift.
OS_SHIFT = 15
MUX_SHIFT = 12
PGA_SHIFT = 9
MODE_SHIFT = 8
DR_SHIFT = 5
COMP_MODE_SHIFT = 4
COMP_POL_SHIFT = 3
COMP_LAT_SHIFT = 2
COMP_QUE_SHIFT = 0

OS_MASK = 0b1 << OS_SHIFT
MUX_MASK = 0b111 << MUX_SHIFT
PGA_MASK = 0b111 << PGA_SHIFT
MODE_MASK = 0b1 << MODE_SHIFT
DR_MASK = 0b111 << DR_SHIFT
COMP_MODE_MASK = 0b1 << COMP_MODE_SHIFT
COMP_POL_MASK = 0b1 << COMP_POL_SHIFT
COMP_LAT_MASK = 0b1 << COMP_LAT_SHIFT
COMP_QUE_MASK = 0b11 << COMP_QUE_SHIFT

#: MUX field (bits 14:12): input pair name -> bits. "AINp_AINn" is differential, "AINx_GND"
#: single-ended.
MUX_CODES = MappingProxyType(
    {
        "AIN0_AIN1": 0b000,
        "AIN0_AIN3": 0b001,
        "AIN1_AIN3": 0b010,
        "AIN2_AIN3": 0b011,
        "AIN0_GND": 0b100,
        "AIN1_GND": 0b101,
        "AIN2_GND": 0b110,
        "AIN3_GND": 0b111,
    }
)
_MUX_NAMES = {bits: name for name, bits in MUX_CODES.items()}

#: Full-scale range (V) -> canonical PGA bits. 110 and 111 are aliases of 101 (+-0.256 V) and
#: decode to 0.256 V; encoding always writes 101.
PGA_CODES = MappingProxyType({fsr: bits for bits, fsr in sorted(PGA_FSR_V.items(), reverse=True)})
#: Data rate (SPS) -> DR bits.
DR_CODES = MappingProxyType({sps: bits for bits, sps in DATA_RATE_SPS.items()})
#: COMP_MODE bit 4.
COMP_MODE_CODES = MappingProxyType({"traditional": 0, "window": 1})
#: COMP_POL bit 3 (polarity of ALERT/RDY when asserted).
COMP_POL_CODES = MappingProxyType({"active_low": 0, "active_high": 1})
#: COMP_QUE bits 1:0: conversions beyond threshold before ALERT asserts; None disables (11).
COMP_QUE_CODES = MappingProxyType({1: 0b00, 2: 0b01, 4: 0b10, None: 0b11})
_COMP_QUE_VALUES = {bits: n for n, bits in COMP_QUE_CODES.items()}

#: Thresholds that turn ALERT/RDY into a conversion-ready pin (datasheet 9.3.8).
RDY_HI_THRESH = 0x8000
RDY_LO_THRESH = 0x0000


def _choices(table: Any) -> str:
    return ", ".join(repr(k) for k in table)


@dataclasses.dataclass(frozen=True)
class Config:
    """ADS1115 config register in human units. ``Config()`` is the power-on state 0x8583.

    Attributes:
        os: Bit 15. Written as 1 in single-shot mode it starts a conversion; read back it is 1
            when no conversion is in progress.
        mux: Input pair, a key of ``MUX_CODES`` (e.g. ``"AIN0_GND"``).
        fsr_v: PGA full-scale range in volts (6.144, 4.096, 2.048, 1.024, 0.512 or 0.256).
        single_shot: Bit 8: True for single-shot / power-down, False for continuous conversion.
        data_rate_sps: Conversions per second (8, 16, 32, 64, 128, 250, 475 or 860).
        comp_mode: ``"traditional"`` or ``"window"`` comparator.
        comp_polarity: ``"active_low"`` or ``"active_high"`` ALERT/RDY polarity.
        comp_latching: True latches ALERT until the conversion register is read.
        comp_queue: Conversions beyond threshold before ALERT asserts (1, 2 or 4); None
            disables the comparator and puts ALERT/RDY in high impedance.
    """

    os: bool = True
    mux: str = "AIN0_AIN1"
    fsr_v: float = 2.048
    single_shot: bool = True
    data_rate_sps: int = 128
    comp_mode: str = "traditional"
    comp_polarity: str = "active_low"
    comp_latching: bool = False
    comp_queue: int | None = None

    def __post_init__(self) -> None:
        # Validate eagerly so a bad value fails where it was typed, not at the first I2C write.
        _check_choice("mux", self.mux, MUX_CODES)
        _check_choice("comp_mode", self.comp_mode, COMP_MODE_CODES)
        _check_choice("comp_polarity", self.comp_polarity, COMP_POL_CODES)
        _check_choice("comp_queue", self.comp_queue, COMP_QUE_CODES)
        for name in ("os", "single_shot", "comp_latching"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(
                    f"Config.{name} must be True or False, got {getattr(self, name)!r}"
                )
        try:
            fsr = check_fsr(self.fsr_v)
        except (ValueError, TypeError) as e:
            raise ValueError(f"Config.fsr_v: {e}") from None
        try:
            dr = check_data_rate(self.data_rate_sps)
        except (ValueError, TypeError) as e:
            raise ValueError(f"Config.data_rate_sps: {e}") from None
        # Normalise to the table's exact values so equality and hashing behave.
        object.__setattr__(self, "fsr_v", min(PGA_CODES, key=lambda r: abs(r - fsr)))
        object.__setattr__(self, "data_rate_sps", dr)

    def replace(self, **changes: Any) -> Config:
        """Return a copy with some fields changed (validated like the constructor)."""
        return dataclasses.replace(self, **changes)

    @property
    def lsb_v(self) -> float:
        """Size of one output code in volts (FSR / 32768)."""
        return lsb_volts(self.fsr_v)

    @property
    def conversion_time_s(self) -> float:
        """Nominal conversion time in seconds (1 / data rate); the oscillator adds +-10%."""
        return 1.0 / self.data_rate_sps


def _check_choice(field: str, value: Any, table: Any) -> None:
    try:
        ok = value in table
    except TypeError:  # unhashable value
        ok = False
    if not ok or (isinstance(value, bool) and field == "comp_queue"):
        raise ValueError(f"Config.{field} {value!r} is not valid; choose one of {_choices(table)}")


def encode_config(cfg: Config) -> int:
    """Pack a :class:`Config` into the 16-bit config register word.

    Args:
        cfg: The configuration.

    Returns:
        The register value, 0..0xFFFF.
    """
    return (
        int(cfg.os) << OS_SHIFT
        | MUX_CODES[cfg.mux] << MUX_SHIFT
        | PGA_CODES[cfg.fsr_v] << PGA_SHIFT
        | int(cfg.single_shot) << MODE_SHIFT
        | DR_CODES[cfg.data_rate_sps] << DR_SHIFT
        | COMP_MODE_CODES[cfg.comp_mode] << COMP_MODE_SHIFT
        | COMP_POL_CODES[cfg.comp_polarity] << COMP_POL_SHIFT
        | int(cfg.comp_latching) << COMP_LAT_SHIFT
        | COMP_QUE_CODES[cfg.comp_queue] << COMP_QUE_SHIFT
    )


def decode_config(word: int) -> Config:
    """Unpack a 16-bit config register word into a :class:`Config`.

    PGA bits 110 and 111 decode to 0.256 V like 101, so they re-encode as 101; every other
    word round-trips exactly through :func:`encode_config`.

    Args:
        word: The register value, 0..0xFFFF.

    Returns:
        The decoded configuration.

    Raises:
        ValueError: If ``word`` is not a 16-bit unsigned integer.
    """
    if isinstance(word, bool) or not isinstance(word, int | np.integer) or not 0 <= word <= 0xFFFF:
        raise ValueError(f"config word must be an int in 0..0xFFFF, got {word!r}")
    word = int(word)
    comp_modes = {v: k for k, v in COMP_MODE_CODES.items()}
    comp_pols = {v: k for k, v in COMP_POL_CODES.items()}
    return Config(
        os=bool(word & OS_MASK),
        mux=_MUX_NAMES[(word & MUX_MASK) >> MUX_SHIFT],
        fsr_v=PGA_FSR_V[(word & PGA_MASK) >> PGA_SHIFT],
        single_shot=bool(word & MODE_MASK),
        data_rate_sps=DATA_RATE_SPS[(word & DR_MASK) >> DR_SHIFT],
        comp_mode=comp_modes[(word & COMP_MODE_MASK) >> COMP_MODE_SHIFT],
        comp_polarity=comp_pols[(word & COMP_POL_MASK) >> COMP_POL_SHIFT],
        comp_latching=bool(word & COMP_LAT_MASK),
        comp_queue=_COMP_QUE_VALUES[(word & COMP_QUE_MASK) >> COMP_QUE_SHIFT],
    )


#: Power-on configuration (0x8583): AIN0_AIN1, +-2.048 V, single-shot, 128 SPS, comparator off.
POWER_ON_CONFIG = decode_config(CONFIG_POWER_ON)

#: Driver default for a whisker on A0: single-ended, +-4.096 V (covers a 0..3.3 V signal on a
#: 3.3 V supply), single-shot at 475 SPS so a conversion (2.1 ms, 2.3 ms with a slow oscillator)
#: plus I2C traffic fits well inside a 5 ms period at 200 Hz; 250 SPS (4.4 ms worst case) does not
#: leave enough margin.
DEFAULT_CONFIG = Config(mux="AIN0_GND", fsr_v=4.096, single_shot=True, data_rate_sps=475)


# --- Conversion register -----------------------------------------------------------------------


def decode_conversion(data: Sequence[int]) -> int:
    """Decode the two conversion-register bytes (MSB first) as a signed 16-bit code.

    Args:
        data: ``[msb, lsb]`` as returned by ``read_i2c_block_data(addr, 0, 2)``.

    Returns:
        The code, -32768..32767.
    """
    return struct.unpack(">h", bytes(data[:2]))[0]


def decode_register(data: Sequence[int]) -> int:
    """Decode two register bytes (MSB first) as an unsigned 16-bit value."""
    return struct.unpack(">H", bytes(data[:2]))[0]


def code_to_volts(code: Any, fsr_v: float) -> Any:
    """Convert output codes to volts: ``code * FSR / 32768`` (exact: 32768 is a power of 2).

    Args:
        code: An int or an integer array.
        fsr_v: PGA full-scale range in volts.

    Returns:
        Volts, a float or a float array.
    """
    fsr = check_fsr(fsr_v)
    if isinstance(code, int | np.integer):
        return int(code) * fsr / 32768.0
    return np.asarray(code, dtype=np.float64) * fsr / 32768.0


def volts_to_code(volts: Any, fsr_v: float) -> Any:
    """Convert volts to the nearest output code, clipped to -0x8000..0x7FFF.

    Args:
        volts: A float or an array of floats.
        fsr_v: PGA full-scale range in volts.

    Returns:
        The code: an int for a scalar input, an int64 array otherwise.
    """
    fsr = check_fsr(fsr_v)
    codes = np.clip(
        np.rint(np.asarray(volts, dtype=np.float64) * (32768.0 / fsr)), CODE_MIN, CODE_MAX
    )
    return int(codes) if codes.ndim == 0 else codes.astype(np.int64)


# --- Errors and statistics ---------------------------------------------------------------------


class I2CError(OSError):
    """An I2C transfer failed on every attempt (the last OSError is the ``__cause__``)."""


class ConversionTimeout(TimeoutError):
    """The ADS1115 did not report a finished conversion within the timeout."""


@dataclasses.dataclass
class DriverStats:
    """Counters kept by :class:`ADS1115`.

    Attributes:
        reads: Conversion results read successfully.
        i2c_errors: Failed I2C transfers (each attempt counts).
        retries: Transfers re-attempted after an error.
        timeouts: Waits for conversion-ready that timed out.
    """

    reads: int = 0
    i2c_errors: int = 0
    retries: int = 0
    timeouts: int = 0


class SMBusLike(Protocol):
    """The subset of ``smbus2.SMBus`` the driver uses."""

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None: ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]: ...


def open_bus(bus_number: int = 1) -> Any:
    """Open ``/dev/i2c-<bus_number>`` with smbus2 (imported here so the rest works without it).

    Args:
        bus_number: I2C bus number; 1 is the Raspberry Pi header (GPIO2 SDA, GPIO3 SCL).

    Returns:
        An open ``smbus2.SMBus``; the caller owns it and must close it.

    Raises:
        ImportError: If smbus2 is not installed.
    """
    try:
        import smbus2
    except ImportError as e:
        raise ImportError(
            "smbus2 is needed to talk to a real ADS1115; install it with "
            'pip install "whiskerid[pi]"'
        ) from e
    return smbus2.SMBus(bus_number)


# --- Driver ------------------------------------------------------------------------------------


class ADS1115:
    """Driver for one ADS1115 on an I2C bus.

    The bus is passed in (an ``smbus2.SMBus``, an :class:`~whiskerid.hw.EmulatedADS1115`, ...)
    and never opened or closed here, so tests and several chips can share one. Every transfer
    is retried on any error of the bus; every wait for a conversion has a timeout.

    Args:
        bus: smbus2-like object with ``write_i2c_block_data`` and ``read_i2c_block_data``.
        address: 7-bit I2C address (0x48 ADDR=GND, 0x49 VDD, 0x4A SDA, 0x4B SCL).
        config: Configuration; defaults to :data:`DEFAULT_CONFIG`. Its ``os`` bit is ignored.
        timeout_s: Longest wait for one conversion in seconds; default twice the nominal
            conversion time plus 5 ms (covers the +-10% oscillator and scheduling delays).
        retries: Extra attempts per I2C transfer after a failure.
        retry_delay_s: Pause before each retry in seconds (lets a glitching bus settle).
        poll_interval_s: Pause between conversion-ready polls in seconds.
        ready_pin: Optional callable returning True while ALERT/RDY is asserted (for the
            default active-low polarity: while the GPIO reads low). When given, the driver
            programs the thresholds for conversion-ready mode and polls the pin instead of the
            config register, which saves two I2C transfers per poll.
        clock: Monotonic clock in integer nanoseconds.
        sleep: Sleep function taking seconds.
    """

    def __init__(
        self,
        bus: SMBusLike,
        address: int = 0x48,
        *,
        config: Config | None = None,
        timeout_s: float | None = None,
        retries: int = 3,
        retry_delay_s: float = 1e-3,
        poll_interval_s: float = 1e-4,
        ready_pin: Callable[[], bool] | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not 0x03 <= address <= 0x77:
            raise ValueError(f"I2C address {address:#x} is outside 0x03..0x77")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.bus = bus
        self.address = address
        self.retries = int(retries)
        self.retry_delay_s = float(retry_delay_s)
        self.poll_interval_s = float(poll_interval_s)
        self.ready_pin = ready_pin
        self.stats = DriverStats()
        self._clock = clock
        self._sleep = sleep
        self._timeout_s = timeout_s
        self._rdy_programmed = False
        self._continuous_started = False
        self.config = DEFAULT_CONFIG if config is None else config

    # -- configuration --

    @property
    def config(self) -> Config:
        """The configuration written on the next conversion (OS bit cleared)."""
        return self._config

    @config.setter
    def config(self, cfg: Config) -> None:
        if self.ready_pin is not None and cfg.comp_queue is None:
            # COMP_QUE = 11 would put ALERT/RDY in high impedance: the pin would never assert.
            cfg = cfg.replace(comp_queue=1)
        self._config = cfg.replace(os=False)
        self._continuous_started = False

    @property
    def timeout_s(self) -> float:
        """Timeout of one conversion wait in seconds."""
        if self._timeout_s is not None:
            return self._timeout_s
        return 2.0 * self._config.conversion_time_s + 5e-3

    def to_volts(self, code: int) -> float:
        """Convert a code read with the current configuration to volts."""
        return code_to_volts(code, self._config.fsr_v)

    # -- register access --

    def _transfer(self, what: str, fn: Callable[[], Any]) -> Any:
        """Run one I2C transfer, retrying a failure up to ``retries`` times.

        Any exception of the bus counts as a failed transfer, not only ``OSError``: bus
        libraries and their wrappers raise other types on a glitch, and a service that runs
        for months must treat those alike (retried, then an :class:`I2CError`).
        """
        for attempt in range(self.retries + 1):
            try:
                return fn()
            except Exception as e:
                self.stats.i2c_errors += 1
                if attempt == self.retries:
                    kind = "" if isinstance(e, OSError) else f"{type(e).__name__}: "
                    raise I2CError(
                        f"ADS1115 at {self.address:#04x}: {what} failed after "
                        f"{attempt + 1} attempt(s): {kind}{e}"
                    ) from e
                self.stats.retries += 1
                self._sleep(self.retry_delay_s)
        raise AssertionError("unreachable")  # pragma: no cover

    def write_register(self, register: int, value: int) -> None:
        """Write a 16-bit register, MSB first.

        Raises:
            I2CError: If every attempt failed.
        """
        if not 0 <= value <= 0xFFFF:
            raise ValueError(f"register value must be in 0..0xFFFF, got {value!r}")
        data = [(value >> 8) & 0xFF, value & 0xFF]
        self._transfer(
            f"write {value:#06x} to register {register}",
            lambda: self.bus.write_i2c_block_data(self.address, register, data),
        )

    def _read_bytes(self, register: int) -> list[int]:
        # A block read sets the pointer and reads MSB then LSB; smbus2's read_word_data would
        # return the bytes swapped (SMBus words are little-endian).
        return self._transfer(
            f"read register {register}",
            lambda: self.bus.read_i2c_block_data(self.address, register, 2),
        )

    def read_register(self, register: int) -> int:
        """Read a 16-bit register as an unsigned value.

        Raises:
            I2CError: If every attempt failed.
        """
        return decode_register(self._read_bytes(register))

    def read_config(self) -> Config:
        """Read back and decode the config register (``os`` True = no conversion running)."""
        return decode_config(self.read_register(REG_CONFIG))

    def read_conversion(self) -> int:
        """Read the conversion register as a signed code (the latest finished conversion)."""
        code = decode_conversion(self._read_bytes(REG_CONVERSION))
        self.stats.reads += 1
        return code

    def _program_ready_pin(self) -> None:
        # Hi_thresh MSB = 1 and Lo_thresh MSB = 0 turn ALERT/RDY into conversion-ready.
        self.write_register(REG_HI_THRESH, RDY_HI_THRESH)
        self.write_register(REG_LO_THRESH, RDY_LO_THRESH)
        self._rdy_programmed = True

    # -- conversions --

    def _wait_until_ready(self) -> None:
        """Wait for the single-shot conversion started last, by RDY pin or OS bit polling.

        Raises:
            ConversionTimeout: If the conversion is not done within ``timeout_s``.
        """
        deadline = self._clock() + round(self.timeout_s * 1e9)
        # The earliest a conversion can finish is with the oscillator 10% fast: sleep that long
        # first instead of hammering the bus.
        self._sleep(self._config.conversion_time_s / (1.0 + OSCILLATOR_TOLERANCE))
        while True:
            if self.ready_pin is not None:
                done = bool(self.ready_pin())
            else:
                done = bool(self.read_register(REG_CONFIG) & OS_MASK)
            if done:
                return
            now = self._clock()
            if now >= deadline:
                self.stats.timeouts += 1
                raise ConversionTimeout(
                    f"ADS1115 at {self.address:#04x}: no conversion-ready within "
                    f"{self.timeout_s * 1e3:.3g} ms "
                    f"({'ALERT/RDY pin' if self.ready_pin else 'OS bit'} polling)"
                )
            self._sleep(min(self.poll_interval_s, (deadline - now) * 1e-9))

    def read_single(self, mux: str | None = None) -> int:
        """Start one single-shot conversion, wait for it and return the code.

        Args:
            mux: Optional input pair for this conversion only (default: ``config.mux``).

        Returns:
            The signed code, -32768..32767.

        Raises:
            I2CError: If a transfer failed on every attempt.
            ConversionTimeout: If the conversion did not finish in time.
        """
        if self.ready_pin is not None and not self._rdy_programmed:
            self._program_ready_pin()
        cfg = self._config.replace(os=True, single_shot=True)
        if mux is not None:
            cfg = cfg.replace(mux=mux)
        self._continuous_started = False
        self.write_register(REG_CONFIG, encode_config(cfg))
        self._wait_until_ready()
        return self.read_conversion()

    def start_continuous(self) -> None:
        """Switch to continuous conversion and wait out the first conversion.

        In continuous mode the OS bit reads 0 all the time, so there is nothing to poll: the
        wait is the slowest possible conversion time.
        """
        if self.ready_pin is not None and not self._rdy_programmed:
            self._program_ready_pin()
        self.write_register(REG_CONFIG, encode_config(self._config.replace(single_shot=False)))
        self._continuous_started = True
        self._sleep(self._config.conversion_time_s * (1.0 + OSCILLATOR_TOLERANCE))

    def read_latest(self) -> int:
        """Return the latest finished conversion in continuous mode (no waiting)."""
        return self.read_conversion()

    def stop(self) -> None:
        """Return to single-shot mode: the chip powers down after the current conversion."""
        self.write_register(REG_CONFIG, encode_config(self._config.replace(single_shot=True)))
        self._continuous_started = False

    def read(self) -> int:
        """Read one code in the configured mode (single-shot, or latest continuous result)."""
        if self._config.single_shot:
            return self.read_single()
        if not self._continuous_started:
            self.start_continuous()
        return self.read_latest()

    def read_volts(self) -> float:
        """Read one conversion in volts (see :meth:`read`)."""
        return self.to_volts(self.read())
