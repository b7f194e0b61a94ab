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
        channel: Index of the input it was read from (0 for a single-input ADC).
        round: Index of the schedule's round (period) it belongs to.
    """

    t_s: float
    code: int
    volts: float
    channel: int = 0
    round: int = 0


class Gap(NamedTuple):
    """A slot whose read failed (yielded by :meth:`Sampler.samples` with ``gaps=True``).

    Attributes:
        t_s: Seconds since the sampler started, when the read failed.
        channel: Index of the input the slot was for.
        error: What failed (``"I2CError: ..."``).
    """

    t_s: float
    channel: int
    error: str


@dataclasses.dataclass
class SamplerStats:
    """Counters kept by :class:`Sampler`.

    Attributes:
        samples: Samples delivered.
        gaps: Slots lost to a failed read (I2C error or conversion timeout); no sample for them.
        timeouts: Of the gaps, those caused by a conversion timeout.
        other_errors: Of the gaps, those caused by an error that is not an ``OSError``.
        overruns: Times a deadline had already passed when the sampler got to it.
        skipped_slots: Slots dropped by those overruns (the schedule jumps, never bursts).
        last_error: Message of the latest failed read, or None.
    """

    samples: int = 0
    gaps: int = 0
    timeouts: int = 0
    other_errors: int = 0
    overruns: int = 0
    skipped_slots: int = 0
    last_error: str | None = None


class Sampler:
    """Read an ADC at a fixed rate on the schedule ``deadline_k = t0 + k / rate``.

    An ADC with several inputs (``n_inputs`` and ``read_input(j)``, e.g.
    :class:`~whiskerid.hw.InputScan`) is read round-robin: the schedule has ``n_inputs``
    slots per period, ``t0 + k / (n_inputs rate)``, and slot ``k`` reads input
    ``k mod n_inputs``, so each input is sampled at ``rate_hz`` and input ``j`` lags input 0
    by ``j / (n_inputs rate_hz)``. A lost slot loses that input's sample only.

    Deadlines are computed from the start time and the slot index with exact rational
    arithmetic, never by accumulating sleeps, so the mean rate does not drift however long it
    runs. When a deadline has already passed (a read or the OS took too long) the overrun is
    counted; the latest slot already due is read at once if it is less than half a slot
    late (its timestamp is the real one), else the sampler moves on to the next deadline
    still in the future: the slots in between are skipped, never read in a burst. A read
    that fails (an exhausted I2C retry, a conversion timeout, or any other exception the bus
    raises) counts as a gap and the stream continues.

    Args:
        adc: Object with ``read() -> code`` and ``to_volts(code) -> volts``.
        rate_hz: Sampling rate of each input in Hz.
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
        self.n_inputs = int(getattr(adc, "n_inputs", 1))
        # Slot period in ns as an exact fraction: deadline_k = t0 + floor(k * num / den).
        period = Fraction(10**9) / (Fraction(rate_hz) * self.n_inputs)
        self._num, self._den = period.numerator, period.denominator
        self.spin_s = float(spin_s)
        self._clock = clock
        self._sleep = sleep
        self._stop = False
        self.stats = SamplerStats()
        self.t0_ns: int | None = None

    @property
    def period_s(self) -> float:
        """Nominal time between two slots in seconds (``1 / (n_inputs rate_hz)``)."""
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

    def _catch_up(self, now_ns: int) -> int:
        """The slot to read after an overrun: the latest one already due, at once, if it
        is less than half a slot late (a short stall costs no sample, only a late
        timestamp), else the next one still to come (never reads back to back)."""
        latest = self._first_slot_from(now_ns) - 1
        if 2 * (now_ns - self.deadline_ns(latest)) * self._den < self._num:
            return latest
        return latest + 1

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

    def samples(
        self, n: int | None = None, duration_s: float | None = None, *, gaps: bool = False
    ) -> Iterator[Sample | Gap]:
        """Yield samples until ``n`` have been delivered, ``duration_s`` has passed, or stop().

        Args:
            n: Number of samples to deliver (gaps do not count); None for no limit.
            duration_s: Run until the schedule reaches this many seconds; None for no limit.
            gaps: Also yield a :class:`Gap` for every failed read, so that a consumer keeps
                running (syncing files, reporting a dead bus) while no sample arrives.

        Yields:
            :class:`Sample` tuples ``(t_s, code, volts, channel)``, and :class:`Gap` tuples
            when ``gaps`` is True.
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
                k_next = self._catch_up(now)
                self.stats.overruns += 1
                self.stats.skipped_slots += k_next - k
                k = k_next
                deadline = self.deadline_ns(k)
                if end_ns is not None and deadline >= end_ns:
                    return
            self._wait_until(deadline)
            sample = self._read_one(k)
            k += 1
            if sample is None:
                if gaps:
                    t_s = (self._clock() - self.t0_ns) * 1e-9
                    yield Gap(t_s, (k - 1) % self.n_inputs, self.stats.last_error or "")
                continue
            yield sample

    def _read_one(self, k: int) -> Sample | None:
        assert self.t0_ns is not None
        channel = k % self.n_inputs
        t_before = self._clock()
        try:
            code = self.adc.read_input(channel) if self.n_inputs > 1 else self.adc.read()
        except Exception as e:
            # I2CError and ConversionTimeout are OSErrors; a bus object may raise anything
            # else on a glitch (smbus2 wrappers, GPIO libraries): a gap either way, never the
            # end of a service that must run for months.
            self.stats.gaps += 1
            if isinstance(e, TimeoutError):
                self.stats.timeouts += 1
            elif not isinstance(e, OSError):
                self.stats.other_errors += 1
            self.stats.last_error = f"{type(e).__name__}: {e}"
            return None
        t_after = self._clock()
        self.stats.samples += 1
        # The read's midpoint: for a single-shot conversion, close to the centre of the window
        # the ADS1115 averaged over.
        t_s = ((t_before + t_after) // 2 - self.t0_ns) * 1e-9
        return Sample(t_s, code, self.adc.to_volts(code), channel, k // self.n_inputs)

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
