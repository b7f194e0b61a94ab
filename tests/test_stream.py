"""Online classification on the (emulated) ADS1115 stream."""

import os
import signal

import numpy as np

import whiskerid as wi
from whiskerid import hw
from whiskerid._stream import OnlineClassifier, run_stream


class ThresholdModel:
    """A stand-in model: 'loud' when the window's std exceeds 1, else 'quiet'."""

    window, rate_hz, channel = 200, 200.0, "adc"

    def __init__(self):
        self.seen = []

    def predict_window(self, samples, speed=None):
        self.seen.append(np.asarray(samples))
        return ("loud", 0.9) if np.std(samples) > 1 else ("quiet", 0.8)


def _samples(t, x):
    return [hw.Sample(float(a), round(b), float(b)) for a, b in zip(t, x, strict=True)]


def test_windows_every_hop_with_the_right_samples():
    model = ThresholdModel()
    online = OnlineClassifier(model, hop_s=0.5)
    t = np.arange(0, 3.0, 1 / 200)
    x = np.where(t < 1.5, 0.0, 10 * np.sin(2 * np.pi * 20 * t))
    labels = [w for s in _samples(t, x) if (w := online.push(s.t_s, s.code)) is not None]
    # First window after 1 s, then every 0.5 s: ends near 1.0, 1.5, 2.0, 2.5 s.
    np.testing.assert_allclose([w.t_end_s for w in labels], [1.0, 1.5, 2.0, 2.5], atol=0.006)
    assert [w.label for w in labels] == ["quiet", "quiet", "loud", "loud"]
    assert all(len(w) == 200 for w in model.seen)
    assert all(w.latency_s >= 0 for w in labels)


def test_gaps_are_interpolated_not_shifted():
    model = ThresholdModel()
    online = OnlineClassifier(model, hop_s=1.0)
    t = np.arange(0, 1.0 + 1e-9, 1 / 200)
    keep = (t < 0.3) | (t > 0.35)  # 10 samples lost
    for s in _samples(t[keep], 100 * t[keep]):
        online.push(s.t_s, s.volts)
    window = model.seen[-1]
    # A ramp stays a ramp: the resampled window is uniform in time despite the gap.
    np.testing.assert_allclose(np.diff(window), 100 / 200, atol=1e-9)


def test_run_stream_records_and_stops_on_sigterm(tmp_path):
    model = ThresholdModel()
    recorder = hw.Recorder(tmp_path / "r.csv", columns=("adc",), rate_hz=200, units="code")

    def source():
        for i, s in enumerate(_samples(np.arange(0, 5, 0.005), np.zeros(1000))):
            if i == 300:
                os.kill(os.getpid(), signal.SIGTERM)
            yield s

    summary = run_stream(source(), OnlineClassifier(model, hop_s=0.5), recorder=recorder)
    assert summary.stopped_by == "signal" and summary.samples == 300
    assert recorder.closed
    rec = wi.read_recording(tmp_path / "r.csv")
    assert rec.t.size == 300 and rec.meta["units"] == "code"
