"""The fixed-rate Sampler: drift-free schedule, overruns without bursts, gaps that never crash."""

import numpy as np
import pytest
from whiskerid.hw import (
    ADS1115,
    EmulatedADS1115,
    FakeClock,
    I2CError,
    Sample,
    Sampler,
    code_to_volts,
)


class TimedADC:
    """A fake ADC whose reads take a given time on the fake clock."""

    def __init__(self, clock, durations_s=lambda i: 0.0, code=123):
        self.clock = clock
        self.durations_s = durations_s
        self.code = code
        self.calls = 0

    def read(self):
        self.clock.advance(self.durations_s(self.calls))
        self.calls += 1
        return self.code

    def to_volts(self, code):
        return code * 1e-3


def make_rig(clock, source=lambda t: 1.0, **driver_kw):
    emu = EmulatedADS1115(source, clock=clock.now_ns, sleep=clock.sleep)
    drv = ADS1115(emu, clock=clock.now_ns, sleep=clock.sleep, **driver_kw)
    return emu, drv


def test_emulated_stream_is_on_schedule():
    clock = FakeClock(start_ns=123_456_789)
    _, drv = make_rig(clock, lambda t: 0.5 + 0.25 * np.sin(2 * np.pi * 10 * np.asarray(t)))
    sampler = Sampler(drv, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    samples = list(sampler.samples(n=2000))
    assert len(samples) == 2000 and sampler.stats.samples == 2000
    t = np.array([s.t_s for s in samples])
    period = np.diff(t)
    assert abs((t[-1] - t[0]) / (len(t) - 1) - 0.005) < 1e-6 * 0.005
    assert np.all(np.abs(period - 0.005) < 1e-6)
    assert sampler.stats.overruns == sampler.stats.gaps == 0
    # Each sample sits in its slot: the read's midpoint, inside the conversion window.
    offset = t - 0.005 * np.arange(len(t))
    assert np.all((offset > 0) & (offset < 1 / 475 * 1.2))
    # Values follow the source and volts match codes.
    for s in samples[:50]:
        assert isinstance(s, Sample) and s.volts == code_to_volts(s.code, 4.096)
    volts = np.array([s.volts for s in samples])
    assert volts.min() == pytest.approx(0.25, abs=0.01) and volts.max() == pytest.approx(
        0.75, abs=0.01
    )


def test_schedule_does_not_drift_with_variable_read_times():
    clock = FakeClock()
    rng = np.random.default_rng(0)
    durations = rng.uniform(0.0, 0.004, size=20_000)
    adc = TimedADC(clock, lambda i: durations[i])
    sampler = Sampler(adc, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    t = np.array([s.t_s for s in sampler.samples(n=20_000)])
    # Deadlines come from t0 + k / rate: a sleep(period)-after-read loop would run 2 ms slow
    # per sample on average here (mean period 7 ms instead of 5 ms).
    starts = t - durations / 2  # undo the midpoint timestamp to recover the slot start
    assert abs((starts[-1] - starts[0]) / (len(t) - 1) - 0.005) < 1e-6 * 0.005
    assert np.max(np.abs(starts - 0.005 * np.arange(len(t)))) < 2e-9
    assert sampler.stats.overruns == 0


def test_deadlines_are_exact_for_a_period_that_is_not_whole_nanoseconds():
    clock = FakeClock()
    adc = TimedADC(clock)
    sampler = Sampler(adc, 300.0, clock=clock.now_ns, sleep=clock.sleep)
    n = 30_001
    t_ns = np.array([round(s.t_s * 1e9) for s in sampler.samples(n=n)])
    k = np.arange(n)
    # floor(k * 10^9 / 300) ns exactly: no accumulated rounding of 3333333.33 ns.
    np.testing.assert_array_equal(t_ns, k * 10**9 // 300)
    assert t_ns[-1] == 100 * 10**9  # 100 s after 30 000 periods
    assert sampler.deadline_ns(3) == 10_000_000


@pytest.mark.parametrize(
    ("stall_s", "read_late", "skipped"),
    [(0.012, True, 1), (0.014, False, 2)],
    ids=["less-than-half-a-slot-late", "more"],
)
def test_overrun_is_counted_and_schedule_skips_ahead_without_burst(stall_s, read_late, skipped):
    clock = FakeClock()
    adc = TimedADC(clock, lambda i: stall_s if i == 10 else 0.001)
    sampler = Sampler(adc, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    t = np.array([s.t_s for s in sampler.samples(n=30)])
    # Read 10 starts at 50 ms and ends at 62 (64) ms: slots 11 (55) and 12 (60) are due.
    # Slot 12 is 2 ms late, under half a slot: read at once; 4 ms late: skipped too, and
    # the next read is at slot 13 (65 ms), not immediately.
    assert sampler.stats.overruns == 1
    assert sampler.stats.skipped_slots == skipped
    start = t - np.where(np.arange(30) == 10, stall_s / 2, 0.0005)  # read midpoints
    expected = list(range(11)) + ([12] if read_late else []) + list(range(13, 32))
    expected = np.array(expected[:30]) * 0.005
    if read_late:  # slot 12 starts when read 10 ends
        expected[11] = 0.050 + stall_s
    np.testing.assert_allclose(start, expected, atol=1e-9)
    assert np.min(np.diff(start)) >= 0.003 - 1e-9  # never back to back


def test_read_that_ends_exactly_on_the_next_deadline_is_not_an_overrun():
    clock = FakeClock()
    adc = TimedADC(clock, lambda i: 0.005)
    sampler = Sampler(adc, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    t = np.array([s.t_s for s in sampler.samples(n=100)])
    assert sampler.stats.overruns == 0
    np.testing.assert_allclose(np.diff(t), 0.005, atol=1e-9)


def test_repeated_overruns_each_counted():
    clock = FakeClock()
    adc = TimedADC(clock, lambda i: 0.0075)  # every read overruns by half a period
    sampler = Sampler(adc, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    t = np.array([s.t_s for s in sampler.samples(n=20)])
    assert sampler.stats.overruns == 19
    assert sampler.stats.skipped_slots == 19
    np.testing.assert_allclose(np.diff(t), 0.010, atol=1e-9)


def test_i2c_failure_is_a_gap_and_the_stream_continues():
    clock = FakeClock()
    emu, drv = make_rig(clock, retries=3)
    sampler = Sampler(drv, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    got = []

    def callback(sample):
        got.append(sample)
        if len(got) == 5:
            # 10 failures: two reads exhaust their 4 attempts, the third succeeds on retry 2.
            emu.fail_next(10)

    stats = sampler.run(callback, n=20)
    assert stats is sampler.stats
    assert len(got) == 20 and stats.samples == 20
    assert stats.gaps == 2 and stats.timeouts == 0 and stats.overruns == 0
    assert stats.last_error.startswith("I2CError")
    assert drv.stats.i2c_errors == 10 and drv.stats.retries == 2 * 3 + 2
    slots = np.rint(np.array([s.t_s for s in got]) / 0.005).astype(int)
    np.testing.assert_array_equal(slots, [*range(5), *range(7, 22)])
    assert all(s.code == 8000 for s in got)


def test_exhausted_retries_raise_to_a_direct_caller_but_not_through_the_sampler():
    clock = FakeClock()
    emu, drv = make_rig(clock, retries=3)
    emu.fail_next(4)
    with pytest.raises(I2CError):
        drv.read()
    emu.fail_next(1000)  # the bus is dead for a while
    sampler = Sampler(drv, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    samples = list(sampler.samples(duration_s=2.0))
    assert sampler.stats.gaps == 250  # 1000 failures / 4 attempts per read
    assert len(samples) == 400 - 250


def test_conversion_timeout_is_a_gap():
    clock = FakeClock()
    emu, drv = make_rig(clock, timeout_s=4e-3)

    class Flaky:
        calls = 0

        def read(self):
            self.calls += 1
            emu.never_ready = self.calls in (4, 5)  # reads 4 and 5 never finish
            return drv.read()

        to_volts = staticmethod(drv.to_volts)

    sampler = Sampler(Flaky(), 200.0, clock=clock.now_ns, sleep=clock.sleep)
    got = list(sampler.samples(n=10))
    assert len(got) == 10
    assert sampler.stats.gaps == 2 and sampler.stats.timeouts == 2
    assert sampler.stats.overruns == 0
    assert sampler.stats.last_error.startswith("ConversionTimeout")
    assert drv.stats.timeouts == 2


def test_duration_and_stop():
    clock = FakeClock()
    sampler = Sampler(TimedADC(clock), 200.0, clock=clock.now_ns, sleep=clock.sleep)
    samples = list(sampler.samples(duration_s=1.0))
    assert len(samples) == 200 and samples[-1].t_s == pytest.approx(0.995)
    assert samples[0] == (0.0, 123, 0.123, 0, 0)  # t_s, code, volts, channel, round

    sampler = Sampler(TimedADC(clock), 200.0, clock=clock.now_ns, sleep=clock.sleep)
    got = []

    def callback(sample):
        got.append(sample)
        if len(got) == 7:
            sampler.stop()

    sampler.run(callback)
    assert len(got) == 7


def test_spin_wait_reaches_deadline_with_a_moving_clock():
    now = [0]
    slept = []

    def clock():
        now[0] += 10_000  # every reading takes 10 us
        return now[0]

    def sleep(s):
        slept.append(s)
        now[0] += round(s * 1e9)

    sampler = Sampler(TimedADC(FakeClock()), 100.0, clock=clock, sleep=sleep, spin_s=1e-3)
    t = [s.t_s for s in sampler.samples(n=5)]
    assert all(s <= 0.01 for s in slept)
    assert np.all(np.diff(t) == pytest.approx(0.01, abs=30e-6))


def test_bad_rate_and_not_started():
    with pytest.raises(ValueError, match="rate_hz"):
        Sampler(TimedADC(FakeClock()), 0.0)
    with pytest.raises(RuntimeError, match="not started"):
        Sampler(TimedADC(FakeClock())).deadline_ns(1)
    assert Sampler(TimedADC(FakeClock())).period_s == 0.005
