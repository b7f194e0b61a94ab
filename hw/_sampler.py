"""Fixed-rate sampling on a drift-free schedule, with gap and overrun accounting."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from fractions import Fraction
from typing import NamedTuple, Protocol


class ADC(Protocol):
    """What :class:`Sampler` needs from a converter (e.g. :class:`~whiskerid.hw.ADS1115`)."""

    def read(self) -> int:
        """Return one output code; raise ``OSError`` on a bus error or timeout."""
        ...

    def to_volts(self, code: int) -> float:
        """Convert a code to volts."""
        ...


class Sample(NamedTuple):
    """One sample.

    Attributes:
        t_s: Seconds since the sampler started (midpoint of the read, from the monotonic clock).
        code: Raw ADC output code.
        volts: The code in volts.
    """

    t_s: float
    code: int
    volts: float


@dataclasses.dataclass
class SamplerStats:
    """Counters kept by :class:`Sampler`.

    Attributes:
        samples: Samples delivered.
        gaps: Slots lost to a failed read (I2C error or conversion timeout); no sample for them.
        timeouts: Of the gaps, those caused by a conversion timeout.
        overruns: Times a deadline had already passed when the sampler got to it.
        skipped_slots: Slots dropped by those overruns (the schedule jumps, never bursts).
        last_error: Message of the latest failed read, or None.
    """

    samples: int = 0
    gaps: int = 0
    timeouts: int = 0
    overruns: int = 0
    skipped_slots: int = 0
    last_error: str | None = None


class Sampler:
    """Read an ADC at a fixed rate on the schedule ``deadline_k = t0 + k / rate``.

    Deadlines are computed from the start time and the slot index with exact rational
    arithmetic, never by accumulating sleeps, so the mean rate does not drift however long it
    runs. When a deadline has already passed (a read or the OS took too long) the overrun is
    counted and the sampler moves on to the next deadline still in the future: no burst of
    catch-up reads. A read that fails (``OSError``: an exhausted I2C retry, a conversion
    timeout) counts as a gap and the stream continues.

    Args:
        adc: Object with ``read() -> code`` and ``to_volts(code) -> volts``.
        rate_hz: Sampling rate in Hz.
        clock: Monotonic clock in integer nanoseconds.
        sleep: Sleep function taking seconds.
        spin_s: Busy-wait the last ``spin_s`` seconds before a deadline instead of sleeping
            (lower jitter, more CPU); 0 sleeps all the way.
    """

    def __init__(
        self,
        adc: ADC,
        rate_hz: float = 200.0,
        *,
        clock: Callable[[], int] = time.monotonic_ns,
        sleep: Callable[[float], None] = time.sleep,
        spin_s: float = 0.0,
    ) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
        self.adc = adc
        self.rate_hz = float(rate_hz)
        # Period in ns as an exact fraction: deadline_k = t0 + floor(k * num / den).
        period = Fraction(10**9) / Fraction(rate_hz)
        self._num, self._den = period.numerator, period.denominator
        self.spin_s = float(spin_s)
        self._clock = clock
        self._sleep = sleep
        self._stop = False
        self.stats = SamplerStats()
        self.t0_ns: int | None = None

    @property
    def period_s(self) -> float:
        """Nominal sampling period in seconds."""
        return self._num / self._den * 1e-9

    def deadline_ns(self, k: int) -> int:
        """Clock reading (ns) at which slot ``k`` is due."""
        if self.t0_ns is None:
            raise RuntimeError("the sampler has not started")
        return self.t0_ns + k * self._num // self._den

    def _first_slot_from(self, now_ns: int) -> int:
        """Smallest slot index whose deadline is at or after ``now_ns``."""
        assert self.t0_ns is not None
        return -((-(now_ns - self.t0_ns) * self._den) // self._num)

    def stop(self) -> None:
        """Ask a running :meth:`samples` / :meth:`run` loop to return before its next slot."""
        self._stop = True

    def _wait_until(self, deadline_ns: int) -> None:
        spin_ns = round(self.spin_s * 1e9)
        while (remaining := deadline_ns - self._clock()) > spin_ns:
            # Sleep until the spin window; a loop because sleeps may end early on a signal.
            self._sleep((remaining - spin_ns) * 1e-9)
        while self._clock() < deadline_ns:
            pass

    def samples(self, n: int | None = None, duration_s: float | None = None) -> Iterator[Sample]:
        """Yield samples until ``n`` have been delivered, ``duration_s`` has passed, or stop().

        Args:
            n: Number of samples to deliver (gaps do not count); None for no limit.
            duration_s: Run until the schedule reaches this many seconds; None for no limit.

        Yields:
            :class:`Sample` tuples ``(t_s, code, volts)``.
        """
        self._stop = False
        self.t0_ns = self._clock()
        end_ns = None if duration_s is None else self.t0_ns + round(duration_s * 1e9)
        k = 0
        while not self._stop and (n is None or self.stats.samples < n):
            deadline = self.deadline_ns(k)
            if end_ns is not None and deadline >= end_ns:
                return
            now = self._clock()
            if k > 0 and now > deadline:
                # Late: skip to the next future deadline instead of reading back to back.
                k_next = self._first_slot_from(now)
                self.stats.overruns += 1
                self.stats.skipped_slots += k_next - k
                k = k_next
                deadline = self.deadline_ns(k)
                if end_ns is not None and deadline >= end_ns:
                    return
            self._wait_until(deadline)
            k += 1
            sample = self._read_one()
            if sample is not None:
                yield sample

    def _read_one(self) -> Sample | None:
        assert self.t0_ns is not None
        t_before = self._clock()
        try:
            code = self.adc.read()
        except OSError as e:  # I2CError and ConversionTimeout are both OSErrors
            self.stats.gaps += 1
            if isinstance(e, TimeoutError):
                self.stats.timeouts += 1
            self.stats.last_error = f"{type(e).__name__}: {e}"
            return None
        t_after = self._clock()
        self.stats.samples += 1
        # The read's midpoint: for a single-shot conversion, close to the centre of the window
        # the ADS1115 averaged over.
        t_s = ((t_before + t_after) // 2 - self.t0_ns) * 1e-9
        return Sample(t_s, code, self.adc.to_volts(code))

    def __iter__(self) -> Iterator[Sample]:
        return self.samples()

    def run(
        self,
        callback: Callable[[Sample], object],
        n: int | None = None,
        duration_s: float | None = None,
    ) -> SamplerStats:
        """Call ``callback(sample)`` for every sample (see :meth:`samples`); return the stats."""
        for sample in self.samples(n=n, duration_s=duration_s):
            callback(sample)
        return self.stats
