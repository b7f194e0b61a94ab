"""The sampling child process: samples in order and on schedule, a clean stop, no orphan,
start-up errors said, and the stream's latencies counted from a sample's arrival."""

import subprocess
import sys
import time

import numpy as np
import pytest

from whiskerid import hw
from whiskerid.io import Recording, write_csv


@pytest.fixture(scope="module")
def slow_sine(tmp_path_factory):
    """A 2 Hz sine of 10 000 codes (1 kHz, 4 s), as ``whiskerid record`` writes codes."""
    path = tmp_path_factory.mktemp("replay") / "sine.csv"
    t = np.arange(4000) / 1000.0
    code = np.round(10_000 * np.sin(2 * np.pi * 2.0 * t))
    write_csv(path, Recording(t, {"A0": code.astype(int)}, {"units": "code", "fsr_v": "4.096"}))
    return path, t, code


def test_the_child_replays_the_recording_on_schedule(slow_sine):
    path, t, code = slow_sine
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0, duration_s=1.5))
    items = list(proc)
    proc.close()
    got = [s for s in items if isinstance(s, hw.Sample)]
    ts = np.array([s.t_s for s in got])
    codes = np.array([s.code for s in got])
    assert proc.stats.samples == len(got) >= 0.5 * 300  # a loaded machine may skip slots
    assert np.all(np.diff(ts) > 0) and ts[-1] < 1.5
    # The chip converts the replayed signal at the read's time, the replay starting when the
    # chip was made, a little before the sampling: within a conversion's slope of the
    # recording (2 Hz x 10 000 codes changes <= 126 codes per ms) at one constant lag, for
    # most samples (a loaded machine may preempt a read between conversion and timestamp).
    lags = np.arange(0.0, 0.02, 2.5e-4)
    err = [np.median(np.abs(codes - np.interp(ts + lag, t, code))) for lag in lags]
    assert min(err) < 250, (lags[np.argmin(err)], min(err))
    assert np.corrcoef(codes, np.interp(ts, t, code))[0, 1] > 0.99
    assert [s.channel for s in got] == [0] * len(got)


def test_close_after_the_child_ended_closes_its_pipes(slow_sine):
    """A child that has ended breaks the pipe: ``close`` still closes both ends (a pipe left
    open fails later, in whatever code runs when the collector closes it)."""
    path, _, _ = slow_sine
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0, duration_s=0.2))
    assert list(proc)
    assert proc._proc.wait(timeout=30) == 0  # gone: the pipe to it is broken
    proc.close()
    assert proc._proc.stdin.closed and proc._proc.stdout.closed


def test_close_stops_the_child_and_brings_back_its_counters(slow_sine):
    path, _, _ = slow_sine
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0))  # no end
    n = 0
    t0 = time.monotonic()
    for item in proc:
        n += isinstance(item, hw.Sample)
        if n == 50:
            break
    now = time.perf_counter()
    assert now - 1.0 < proc.arrived_s <= now  # just arrived, on the caller's clock
    proc.close()
    assert time.monotonic() - t0 < 10
    assert proc._proc.returncode == 0
    assert proc.stats.samples >= 50  # counted by the child, sent with its last line


def test_a_parent_that_goes_away_leaves_no_sampling_child(slow_sine):
    path, _, _ = slow_sine
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0))
    next(iter(proc))
    proc._proc.stdin.close()  # what the parent's death (kill -9) does to the pipe
    try:
        assert proc._proc.wait(timeout=10) == 0
    except subprocess.TimeoutExpired:
        pytest.fail("the child kept sampling after its parent's pipe closed")
    finally:
        proc.close()


def _waiting_child():
    """A child started without a spec, as ``whiskerid stream`` starts it before its imports."""
    return subprocess.Popen([sys.executable, "-m", "whiskerid.hw._sampling_child"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            bufsize=1)  # fmt: skip


def test_a_child_started_early_samples_once_sent_its_spec(slow_sine):
    path, _, _ = slow_sine
    early = _waiting_child()
    time.sleep(0.3)  # it waits for the spec: nothing sampled, nothing written
    assert early.poll() is None
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0, duration_s=0.5),
                              process=early)  # fmt: skip
    got = [s for s in proc if isinstance(s, hw.Sample)]
    proc.close()
    assert proc._proc is early and early.returncode == 0
    assert proc.stats.samples == len(got) >= 0.5 * 100


def test_a_child_started_early_and_not_sent_a_spec_exits_without_sampling(slow_sine):
    early = _waiting_child()
    early.stdin.close()  # the stream stopped on bad input (or died) before it sampled
    try:
        assert early.wait(timeout=30) == 0
        assert early.stdout.read() == ""
    finally:
        early.stdout.close()


def test_a_child_started_early_that_died_is_replaced(slow_sine):
    path, _, _ = slow_sine
    early = _waiting_child()
    early.kill()
    early.wait()
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(path), rate_hz=200.0, duration_s=0.3),
                              process=early)  # fmt: skip
    got = [s for s in proc if isinstance(s, hw.Sample)]
    proc.close()
    assert proc._proc is not early and proc._proc.returncode == 0 and got


def test_a_child_that_cannot_start_says_why(tmp_path):
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(tmp_path / "missing.csv")))
    with pytest.raises(hw.SamplingError, match=r"missing\.csv"):
        list(proc)
    t0 = time.perf_counter()
    proc.close(timeout_s=60.0)  # the child has ended: no end line to wait for
    assert time.perf_counter() - t0 < 30.0


def test_a_stream_counts_latency_from_the_samples_arrival():
    class Model:
        window, rate_hz, labels = 20, 200.0, ["a", "b"]

        def window_proba(self, samples, speed=None):
            return np.array([0.9, 0.1])

    class Waited:  # items that arrived 0.3 s before they are read, as after a slow start
        arrived_s = None

        def __iter__(self):
            for k in range(60):
                self.arrived_s = time.perf_counter() - 0.3
                yield hw.Sample(k / 200.0, 1000 + (k % 7), 0.1, 0, k)

    online = hw.OnlineClassifier(Model(), hop_s=0.05)
    labels = []
    hw.run_stream(Waited(), online, on_label=labels.append, background=False)
    assert labels and all(w.latency_s >= 0.3 for w in labels)
