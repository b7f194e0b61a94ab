"""The stream under faults: never a confident terrain from a dead sensor, a dead bus or a
broken model; counts that stay small; files that stay durable while the bus is down."""

import os
import tracemalloc

import numpy as np
import pytest
from whiskerid.hw import OnlineClassifier, StreamSummary, WindowLabel, run_stream

import whiskerid as wi
from whiskerid import hw


class Model:
    """A stand-in model that is sure of 'carpet' whatever it is shown (as a real one was on
    a chip stuck at one code)."""

    window, rate_hz, channel, labels, lookback_s = 200, 200.0, "adc", ("carpet", "brick"), 0.0

    def __init__(self, proba=(1.0, 0.0)):
        self.proba = np.array(proba)

    def window_proba(self, samples, speed=None):
        return self.proba


def _live(t):
    return 1.65 + 0.3 * np.sin(2 * np.pi * 17 * np.asarray(t))


def _stuck(chip):
    chip.stuck_code = 13_000


def _never_ready(chip):
    chip.never_ready = True


def _bus_errors(chip):
    chip.error_rate = 0.5


def _slow_reads(chip):
    chip.read_delay_s = 3e-3


def _odd_errors(chip):  # a bus library that raises something other than OSError
    chip.error_rate, chip.error = 1.0, ValueError("bus glitch")


FAULTS = [
    # (fault, source, model probabilities, label, reason, windows that must have it)
    ("stuck code", _stuck, _live, (1.0, 0.0), "sensor-fault", "flat", 1.0),
    ("clipped", None, lambda t: 2.25 + _live(t), (1.0, 0.0), "sensor-fault", "clipped", 1.0),
    ("never ready", _never_ready, _live, (1.0, 0.0), "no-data", "bus starved", 1.0),
    ("50% bus errors", _bus_errors, _live, (1.0, 0.0), "no-data", "bus starved", 0.5),
    ("slow reads", _slow_reads, _live, (1.0, 0.0), "no-data", "bus starved", 1.0),
    ("not OSError", _odd_errors, _live, (1.0, 0.0), "no-data", "bus starved", 1.0),
    ("NaN model", None, _live, (np.nan, np.nan), "model-fault", "not a probability", 1.0),
    ("huge weights", None, _live, (np.inf, 0.0), "model-fault", "not a probability", 1.0),
]


@pytest.mark.parametrize("case", FAULTS, ids=[c[0] for c in FAULTS])
def test_each_fault_gets_its_label_and_reason_never_a_terrain(case):
    _, fault, source, proba, label, reason, share = case
    clock = hw.FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    chip = hw.EmulatedADS1115(source, seed=1, **timing)
    if fault is not None:
        fault(chip)
    sampler = hw.Sampler(hw.ADS1115(chip, **timing), 200.0, **timing)
    got = []
    summary = run_stream(sampler.samples(duration_s=6.0, gaps=True),
                         OnlineClassifier(Model(proba), hop_s=0.5), on_label=got.append,
                         background=False)  # fmt: skip
    assert summary.windows == len(got) == 10  # a label every hop, bus or no bus
    faulty = [w for w in got if w.label == label]
    assert len(faulty) >= share * len(got)
    assert all(reason in w.reason and w.confidence == 0 for w in faulty)
    assert all(w.label == "carpet" for w in got if not w.fault)  # what the model says when it can
    assert summary.fault_episodes >= 1
    if share == 1.0:
        assert summary.all_failed and summary.fault_episodes == 1
        assert summary.to_dict()["majority_label"] is None


def test_a_fault_episode_is_reported_once_and_its_end_too():
    summary = StreamSummary()
    labels = ["brick", "sensor-fault", "sensor-fault", "sensor-fault", "brick", "no-data"]
    reasons = ["", "flat: every sample is 5", "flat: every sample is 6", "clipped: 5%", "", "x"]
    got = [summary.add(WindowLabel(i, lab, 0.5, 1e-3, lab, why))
           for i, (lab, why) in enumerate(zip(labels, reasons, strict=True))]  # fmt: skip
    assert got == [None, "start", None, "start", "end", "start"]
    out = summary.to_dict()
    assert out["fault_episodes"] == 3
    # 2 terrain windows of 6: the stream mostly could not label, so no majority terrain
    assert out["majority_label"] is None and out["unlabelled_windows"] == 4
    assert out["faults"] == {"no-data: x": 1, "sensor-fault: clipped": 1, "sensor-fault: flat": 2}
    summary.add(WindowLabel(6, "brick", 0.5, 1e-3, "brick", ""))
    for i in range(7, 10):
        summary.add(WindowLabel(i, "stopped", 0.0, 1e-3, "stopped", "the robot is stopped"))
    out = summary.to_dict()  # stopped windows count for neither side
    assert out["majority_label"] is None and out["terrain_windows"] == 3
    summary.add(WindowLabel(10, "sand", 0.5, 1e-3, "sand", ""))
    summary.add(WindowLabel(11, "brick", 0.5, 1e-3, "brick", ""))
    assert summary.to_dict()["majority_label"] == "brick"  # 5 terrain windows against 4


def test_the_summary_keeps_counts_not_every_window():
    summary = StreamSummary()
    w = [WindowLabel(0.0, "brick", 0.9, 1e-3, "brick"), WindowLabel(0.0, "sand", 0.8, 2e-3, "sand")]
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for i in range(100_000):  # about 14 hours of windows at a 0.5 s hop
        summary.add(w[i % 2])
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert grown < 100_000  # bytes; a list of every label held 800 kB and counting
    out = summary.to_dict()
    assert out["windows"] == 100_000 and out["label_counts"] == {"brick": 50_000, "sand": 50_000}
    assert out["latency_ms"]["p50"] == pytest.approx(1.5, abs=0.5)


def test_the_recorder_syncs_on_its_timer_while_the_bus_is_down(tmp_path):
    clock = hw.FakeClock()
    syncs = []
    rec = hw.Recorder(tmp_path / "r.csv", columns=("adc",), clock=clock.now_ns,
                      fsync=lambda fd: syncs.append(clock.now_s()))  # fmt: skip

    def stream():  # 2 s of samples, then a 16 s outage: only gaps
        for k in range(3600):
            clock.advance(0.005)
            t = k * 0.005
            yield hw.Sample(t, 100 + k % 7, 0.0) if t < 2.0 else hw.Gap(t, 0, "I2CError: NACK")

    summary = run_stream(stream(), OnlineClassifier(Model(), hop_s=0.5), recorder=rec,
                         background=False)  # fmt: skip
    during = [s for s in syncs if 2.5 < s < 18.0]
    assert len(during) >= 14  # once a second, though no row was written
    assert summary.label_counts["no-data"] >= 30  # every hop of the outage is labelled
    assert wi.read_recording(tmp_path / "r.csv").t.size == 400


def test_a_simulated_terrain_without_end_stays_fresh():
    """No duration: chunks of fresh terrain, made ahead, two kept in memory."""
    source = hw.terrain_source(wi.paper_record(), "brick", 0.2, None, chunk_s=2.0)
    spans = [np.asarray(source(np.arange(a, a + 1.0, 1e-3))) for a in (0.5, 2.2, 4.5, 6.5, 9.0)]
    assert all(np.all(np.isfinite(v)) and np.ptp(v) > 1e-3 for v in spans)
    # Not a repeat: different terrain in every chunk.
    assert not np.allclose(spans[2], spans[3], atol=1e-4)
    assert len(source._chunks) <= 2
    # The seam is a cross-fade, not a jump: no step larger than the signal's own.
    seam = np.asarray(source(np.arange(3.9, 4.1, 1e-4)))
    inner = np.asarray(source(np.arange(4.9, 5.1, 1e-4)))
    assert np.max(np.abs(np.diff(seam))) < 3 * np.max(np.abs(np.diff(inner)))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs a POSIX system")
def test_speed_comes_in_and_labels_go_out_over_loopback_udp():
    import json
    import socket
    import time

    feed = hw.SpeedFeed(0)  # port 0: the system picks a free one
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    out.sendto(b'{"speed_mps": 0.31}\nnot json\n', ("127.0.0.1", feed.port))
    deadline = time.monotonic() + 5
    while feed.latest is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert feed(0.0) == 0.31 and feed.bad_messages == 1
    feed.close()
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(5)
    sink = hw.LabelSink(listener.getsockname()[1])
    sink(WindowLabel(2.5, "stopped", 0.0, 1e-3, "stopped", "the robot is stopped (0 m/s)", 0.0))
    msg = json.loads(listener.recv(4096))
    assert msg == {"t_s": 2.5, "label": "stopped", "confidence": 0.0, "speed_mps": 0.0,
                   "reason": "the robot is stopped (0 m/s)"}  # fmt: skip
    sink.close()
    out.close()
    listener.close()


def test_a_stopped_robot_is_labelled_stopped_not_a_terrain():
    speed = lambda t: 0.2 if t < 3.0 else 0.0
    online = OnlineClassifier(Model(), hop_s=0.5, speed_mps=speed)
    t = np.arange(0, 6.0, 1 / 200)
    x = np.round(1000 * np.sin(2 * np.pi * 17 * t))
    got = [w for ti, xi in zip(t, x, strict=True) if (w := online.push(ti, xi)) is not None]
    assert [w.label for w in got] == ["carpet"] * 4 + ["stopped"] * 6
    assert got[-1].speed_mps == 0.0 and "stopped" in got[-1].reason


def test_a_quiet_whisker_is_labelled_stopped_a_moving_one_is_classified():
    online = OnlineClassifier(Model(), hop_s=0.5, quiet_std=3.0)
    t = np.arange(0, 4.0, 1 / 200)
    rest = np.round(np.random.default_rng(2).standard_normal(t.size))  # noise of about 1 code
    x = np.where(t < 2.0, rest, np.round(200 * np.sin(2 * np.pi * 17 * t)))
    got = [w for ti, xi in zip(t, x, strict=True) if (w := online.push(ti, xi)) is not None]
    assert [w.label for w in got] == ["stopped"] * 3 + ["carpet"] * 3  # ends 1.0 .. 3.5 s
    assert "quiet" in got[0].reason
