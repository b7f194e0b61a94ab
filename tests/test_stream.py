"""Online classification on the (emulated) ADS1115 stream."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest
from whiskerid.hw import BackgroundClassifier, OnlineClassifier, run_stream

import whiskerid as wi
from whiskerid import hw
from whiskerid.cli import main
from whiskerid.io import TornRecordingWarning


class ThresholdModel:
    """A stand-in model: 'loud' when the window's std exceeds 1, else 'quiet'."""

    window, rate_hz, channel, labels, lookback_s = 200, 200.0, "adc", ("loud", "quiet"), 0.0

    def __init__(self):
        self.seen = []

    def window_proba(self, samples, speed=None):
        self.seen.append(np.asarray(samples))
        return np.array([0.9, 0.1]) if np.std(samples) > 1 else np.array([0.2, 0.8])


def _samples(t, x):
    return [hw.Sample(float(a), round(b), float(b)) for a, b in zip(t, x, strict=True)]


def _noise(t, scale=0.5):
    return scale * np.random.default_rng(0).standard_normal(np.shape(t))


def test_windows_every_hop_with_the_right_samples():
    model = ThresholdModel()
    online = OnlineClassifier(model, hop_s=0.5)
    t = np.arange(0, 3.0, 1 / 200)
    x = np.where(t < 1.5, 0.0, 10 * np.sin(2 * np.pi * 20 * t)) + _noise(t, 0.6)
    labels = [w for s in _samples(t, x) if (w := online.push(s.t_s, s.code)) is not None]
    # First window after 1 s, then every 0.5 s: ends near 1.0, 1.5, 2.0, 2.5 s.
    np.testing.assert_allclose([w.t_end_s for w in labels], [1.0, 1.5, 2.0, 2.5], atol=0.006)
    assert [w.label for w in labels] == ["quiet", "quiet", "loud", "loud"]
    assert all(len(w) == 200 for w in model.seen)
    assert all(w.latency_s >= 0 for w in labels)


def test_labels_fuse_the_models_context_by_time():
    """With ``lookback_s = 1`` and a 0.5 s hop, a label fuses the windows that ended in
    the last second (three): one loud window among quiet ones is reported as quiet, with
    its own label kept in ``window_label``; a lasting change wins after two windows."""
    model = ThresholdModel()
    model.lookback_s = 1.0
    online = OnlineClassifier(model, hop_s=0.5)
    t = np.arange(0, 6.0, 1 / 200)
    loud = ((t > 2.05) & (t < 2.45)) | (t > 4.0)  # a 0.4 s burst, then loud for good
    x = np.where(loud, 10 * np.sin(2 * np.pi * 20 * t), 0.0) + _noise(t, 0.6)
    got = [w for s in _samples(t, x) if (w := online.push(s.t_s, s.code)) is not None]
    ends = np.round([w.t_end_s for w in got], 1).tolist()
    own = [e for e, w in zip(ends, got, strict=True) if w.window_label == "loud"]
    fused = [e for e, w in zip(ends, got, strict=True) if w.label == "loud"]
    # Windows end at 1.0, 1.5, ..., 5.5 s; on their own, those holding the burst (2.5,
    # 3.0 s) and those reaching past 4 s (4.5 s on) are loud.
    assert own == [2.5, 3.0, 4.5, 5.0, 5.5]
    # Fused over three (log-odds 2.20 loud, -1.39 quiet): one loud window of three stays
    # quiet (2.5, 4.5 s), two of three are loud (3.0, 3.5, 5.0 s).
    assert fused == [3.0, 3.5, 5.0, 5.5]
    assert all(0.5 < w.confidence <= 1.0 for w in got)


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


def test_windows_with_long_gaps_are_labelled_no_data_not_guessed():
    model = ThresholdModel()
    online = OnlineClassifier(model, hop_s=0.5, min_fill=0.9)
    t = np.arange(0, 2.0, 1 / 200)
    keep = (t < 1.1) | (t > 1.3)  # 40 samples (20 %) lost: the windows ending at 1.5 s
    got = [w for s in _samples(t[keep], _noise(t[keep])) if (w := online.push(s.t_s, s.code))]
    np.testing.assert_allclose([w.t_end_s for w in got], [1.0, 1.5], atol=0.006)
    assert [w.label for w in got] == ["quiet", "no-data"] and got[1].confidence == 0
    assert "159 of 200 samples" in got[1].reason and len(model.seen) == 1
    assert online.skipped_windows == 1  # 1.5 s; the next one (2.0 s) would need t = 2.0


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


class SlowModel(ThresholdModel):
    """ThresholdModel that blocks until released: a model slower than the sample period."""

    def __init__(self):
        super().__init__()
        self.release = threading.Event()
        self.threads = set()

    def window_proba(self, samples, speed=None):
        self.threads.add(threading.current_thread().name)
        assert self.release.wait(10)
        return super().window_proba(samples, speed)


def test_background_labels_equal_inline_labels_in_order():
    t = np.arange(0, 6.0, 1 / 200)
    x = np.where((t // 1.3) % 2 == 0, 0.0, 10 * np.sin(2 * np.pi * 20 * t))

    def paced():  # 5x real time: a window every 20 ms, ample for this model
        for s in _samples(t, x):
            time.sleep(0.001)
            yield s

    x = x + _noise(t, 0.6)  # rounded to codes: never flat, std below 1
    inline, threaded = [], []
    summary = run_stream(_samples(t, x), OnlineClassifier(ThresholdModel()), background=False,
                         on_label=inline.append)  # fmt: skip
    again = run_stream(paced(), OnlineClassifier(ThresholdModel()), background=True,
                       on_label=threaded.append)  # fmt: skip
    assert len(inline) == summary.windows == again.windows == 10
    assert [(w.t_end_s, w.label) for w in threaded] == [(w.t_end_s, w.label) for w in inline]
    assert again.dropped_windows == 0
    assert set(summary.label_counts) == {"quiet", "loud"}  # never a fault on a live signal


def test_a_slow_model_never_holds_up_the_sampling_loop():
    model = SlowModel()
    online = OnlineClassifier(model, hop_s=0.5)
    labels = []
    previous = sys.getswitchinterval()
    worker = BackgroundClassifier(online, labels.append, max_pending=2).start()
    assert sys.getswitchinterval() == pytest.approx(5e-4)
    t = np.arange(0, 4.0, 1 / 200)
    submitted = []
    t0 = time.perf_counter()
    for s in _samples(t, _noise(t)):  # the model is stuck: cutting and submitting must not wait
        if (p := online.cut(s.t_s, s.code)) is not None:
            submitted.append(worker.submit(p))
    assert time.perf_counter() - t0 < 5.0  # 800 samples; a blocking put would hang 10 s
    # Windows at 1.0, 1.5, ..., 3.5 s: one taken by the worker, two queued, the rest dropped.
    assert len(submitted) == 6 and worker.dropped == submitted.count(False) >= 2
    model.release.set()
    worker.close()
    assert sys.getswitchinterval() == previous
    assert len(labels) == submitted.count(True) and model.threads == {"whiskerid-classify"}
    assert all(w.latency_s > 0 for w in labels)


def test_a_failing_model_is_reported_not_swallowed(tmp_path):
    class Broken(ThresholdModel):
        def window_proba(self, samples, speed=None):
            raise FloatingPointError("weights are NaN")

    recorder = hw.Recorder(tmp_path / "r.csv", columns=("adc",), rate_hz=200, units="code")
    t = np.arange(0, 3.0, 1 / 200)
    with pytest.raises(RuntimeError, match="classifier thread failed") as info:
        run_stream(_samples(t, _noise(t)), OnlineClassifier(Broken()), recorder=recorder)
    assert isinstance(info.value.__cause__, FloatingPointError)
    assert recorder.closed  # what was recorded is kept
    assert wi.read_recording(tmp_path / "r.csv").t.size > 0


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    """A real model trained on a small synthetic dataset (two terrains, one speed)."""
    root = tmp_path_factory.mktemp("stream")
    ds, model = root / "ds", root / "model"
    assert (
        main(
            [
                "dataset",
                "synth",
                "--out",
                str(ds),
                "--terrains",
                "brick",
                "sand",
                "--speeds",
                "0.2",
                "--runs",
                "2",
                "--duration",
                "15",
                "--seed",
                "3",
            ]
        )
        == 0
    )
    assert main(["train", str(ds), "--out", str(model), "--seed", "0"]) == 0
    return model


def test_stream_cli_on_the_emulated_chip(tiny_model, tmp_path, capsys):
    rec = tmp_path / "rec.csv"
    rec.write_text("taken")  # an existing file is never overwritten
    args = [
        "stream",
        "--model",
        str(tiny_model),
        "--simulate",
        "brick",
        "--speed",
        "0.2",
        "--duration",
        "12",
        "--fast",
        "--record",
        str(rec),
        "--json",
        "--quiet",
        "--compile-cache",
        "none",  # the cache is process-wide: tests must not switch it on for the others
    ]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["samples"] == pytest.approx(12 * 200, abs=2)
    # A tiny two-class model (57 training windows): well above chance, not a benchmark.
    assert out["windows"] == 22 and out["fraction_correct"] >= 0.7
    assert out["majority_label"] == "brick"
    assert out["latency_ms"]["p99"] < 1000  # compiled before the stream started
    assert rec.read_text() == "taken"
    written = wi.read_recording(out["record"])
    assert written.t.size == out["samples"] and written.meta["terrain"] == "brick"
    assert np.all(np.diff(written.t) > 0)


def test_stream_cli_refuses_bad_input(tiny_model, tmp_path, capsys):
    assert main(["stream", "--model", str(tiny_model), "--simulate", "ice", "--fast"]) == 2
    assert "not a terrain of this model" in capsys.readouterr().err
    assert main(["stream", "--model", str(tmp_path), "--simulate", "brick"]) == 2
    assert main(["stream", "--model", str(tiny_model), "--i2c-bus", "1", "--fast"]) == 2
    # A rate below the model's is refused at the start, in words (it used to stream for the
    # whole --duration without a label and then fail on the summary).
    args = ["stream", "--model", str(tiny_model), "--simulate", "brick", "--fast"]
    assert main([*args, "--duration", "20", "--rate", "100"]) == 2
    err = capsys.readouterr().err
    assert "--rate 100 Hz is below the 200 Hz this model was trained at" in err


_STREAM_TO_DISK = """
import sys
import numpy as np
from whiskerid import hw

class Loud:
    window, rate_hz, channel, labels, lookback_s = 200, 200.0, "adc", ("loud", "quiet"), 0.0

    def window_proba(self, samples, speed=None):
        return np.array([0.9, 0.1])

chip = hw.EmulatedADS1115(lambda t: 1.65 + 0.5 * np.sin(2 * np.pi * 5 * np.asarray(t)))
sampler = hw.Sampler(hw.ADS1115(chip), 200.0)
recorder = hw.open_recorder(hw.unique_path(sys.argv[1]), rate_hz=200.0, meta={})
online = hw.OnlineClassifier(Loud(), hop_s=0.5)
hw.run_stream(sampler.samples(duration_s=60.0), online, recorder=recorder)
"""


@pytest.mark.slow
def test_kill_9_mid_run_leaves_a_readable_recording(tmp_path):
    # The stream loop as `whiskerid stream --record` runs it, in real time, with a stand-in
    # model: what is on disk while it runs must survive a SIGKILL.
    rec = tmp_path / "rec.csv"
    proc = subprocess.Popen([sys.executable, "-c", _STREAM_TO_DISK, str(rec)],
                            stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)  # fmt: skip
    seen = 0
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # wait for over a second of data on disk
            seen = _complete_data_rows(rec)
            if seen >= 250:
                break
            assert proc.poll() is None, "the stream ended early"
            time.sleep(0.1)
        else:
            pytest.fail(f"the stream wrote only {seen} rows in 120 s")
        # Still running (it streams for a minute): the rows were on disk before any close.
        assert proc.poll() is None
    finally:
        proc.kill()  # SIGKILL: no chance to close or flush
        proc.wait()
    # The kill may cut the last row: only a torn-row warning is allowed.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = wi.read_recording(rec)
    assert all(w.category is TornRecordingWarning for w in caught)
    # Everything flushed before the kill is still there (the writer may have added more).
    assert got.t.size >= seen >= 250
    assert np.all(np.diff(got.t) > 0)


def _complete_data_rows(path):
    """Rows ending in a newline that are neither metadata (``#``) nor the column header."""
    if not path.exists():
        return 0
    lines = path.read_text().split("\n")[:-1]  # the last piece is torn or empty
    return sum(1 for line in lines if line and not line.startswith(("#", "t,")))


def test_stream_replays_a_recording_with_odometry_and_sends_labels(tiny_model, tmp_path, capsys):
    """A recording made with `whiskerid record` goes through the emulated chip as it would
    online; the odometry says the robot stops at 4 s; labels go out over loopback UDP."""
    import socket

    rec = tmp_path / "brick.csv"
    argv = ["record", str(rec), "--emulate", "brick", "--fast", "--duration", "8"]
    assert main(argv) == 0
    odo = tmp_path / "odo.csv"
    odo.write_text("t,speed_mps\n0,0.2\n3.99,0.2\n4.0,0\n9,0\n")
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(0.5)
    port = listener.getsockname()[1]
    argv = ["stream", "--model", str(tiny_model), "--replay", str(rec), "--fast", "--duration",
            "7.5", "--speed-from", str(odo), "--labels-to", f"udp:{port}", "--compile-cache",
            "none", "--json", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    msgs = []
    while True:
        try:
            msgs.append(json.loads(listener.recv(4096)))
        except TimeoutError:
            break
    listener.close()
    assert len(msgs) == out["windows"] == 13  # windows end at 1.5, 2.0, ..., 7.5 s
    moving = [m for m in msgs if m["t_s"] < 4.0]
    stopped = [m for m in msgs if m["t_s"] >= 4.0]
    assert all(m["label"] == "stopped" and m["speed_mps"] == 0 for m in stopped)
    assert all(m["label"] in ("brick", "sand") and m["speed_mps"] == 0.2 for m in moving)
    assert out["label_counts"]["stopped"] == len(stopped) and out["majority_label"] == "brick"


def test_stream_of_a_dead_sensor_labels_every_window_a_fault_and_fails(
    tiny_model, tmp_path, capsys
):
    rec = tmp_path / "dead.csv"
    t = np.arange(0, 5, 0.005)
    wi.write_csv(rec, wi.Recording(t=t, columns={"adc": np.full(t.size, 13_000)},
                                   meta={"units": "code"}))  # fmt: skip
    argv = ["stream", "--model", str(tiny_model), "--replay", str(rec), "--fast", "--duration",
            "4", "--compile-cache", "none"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("s  sensor-fault: flat: every sample is 13000") == 1  # once per episode
    assert "error: no window got a terrain: sensor-fault: flat (6)" in err


@pytest.mark.slow
def test_a_restart_reuses_the_compile_cache(tiny_model, tmp_path):
    """The stream's compiled functions land in --compile-cache; a second start loads them."""
    rec = tmp_path / "r.csv"
    assert main(["record", str(rec), "--emulate", "brick", "--fast", "--duration", "3"]) == 0
    # A resonance fitted per window runs compiled (the default features run in NumPy).
    model = tmp_path / "modal"
    assert main(["train", str(tiny_model.parent / "ds"), "--out", str(model), "--modal-fit",
                 "--seed", "0", "--quiet"]) == 0  # fmt: skip
    cache = tmp_path / "cache"
    argv = [sys.executable, "-m", "whiskerid.cli", "stream", "--model", str(model),
            "--replay", str(rec), "--fast", "--duration", "2",
            "--compile-cache", str(cache)]  # fmt: skip
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
        times.append(time.perf_counter() - t0)
        assert done.returncode == 0, done.stderr
    assert any(f.is_file() for f in cache.rglob("*"))
    assert len(list(cache.glob("window-proba-*.jaxexport"))) == 1  # the traced program too
    assert times[1] < times[0]
    # 'none' switches the cache off, even where the environment names one.
    elsewhere = tmp_path / "env-cache"
    env = {**os.environ, "WHISKERID_COMPILE_CACHE": str(elsewhere)}
    done = subprocess.run([*argv[:-1], "none"], capture_output=True, text=True, timeout=300,
                          env=env)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert not any(f.is_file() for f in elsewhere.rglob("*"))


def test_a_saved_program_labels_as_the_traced_one(tiny_model, tmp_path):
    """use_saved_program saves the traced window function, a new instance loads it, and
    the probabilities are the traced ones; other numbers never pick up that program."""
    x = 3000 * np.sin(2 * np.pi * 31 * np.arange(200) / 200) + _noise(np.arange(200), 300)
    traced = wi.ClassifierModel.load(tiny_model)
    p0 = traced.window_proba(x, 0.2)
    saving = wi.ClassifierModel.load(tiny_model)
    assert saving.use_saved_program(tmp_path) is False  # nothing there yet: saved now
    assert len(list(tmp_path.glob("*.jaxexport"))) == 1
    loading = wi.ClassifierModel.load(tiny_model)
    assert loading.use_saved_program(tmp_path) is True
    for m in (saving, loading):
        np.testing.assert_allclose(m.window_proba(x, 0.2), p0, atol=1e-6)
    (saved,) = tmp_path.glob("*.jaxexport")
    saved.write_bytes(b"torn")  # a damaged cache file is traced and saved again
    again = wi.ClassifierModel.load(tiny_model)
    assert again.use_saved_program(tmp_path) is False
    np.testing.assert_allclose(again.window_proba(x, 0.2), p0, atol=1e-6)
    assert wi.ClassifierModel.load(tiny_model).use_saved_program(tmp_path) is True
    other = wi.ClassifierModel(traced.spec, traced.labels, traced.mean, 2 * traced.std,
                               list(traced.nets), hop=traced.hop)  # fmt: skip
    assert other.use_saved_program(tmp_path) is False  # its own program, not the first's
    assert len(list(tmp_path.glob("*.jaxexport"))) == 2


def _stream_until_labelled(argv, *, new_session=False, timeout=300):
    """Start ``whiskerid stream`` in a process; return it once it printed a terrain label,
    with the stderr lines read so far."""
    proc = subprocess.Popen([sys.executable, "-m", "whiskerid.cli", "stream", *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=new_session)  # fmt: skip
    lines = []
    deadline = time.monotonic() + timeout
    assert proc.stderr is not None
    for line in proc.stderr:
        lines.append(line)
        if " p = " in line or time.monotonic() > deadline:
            break
    return proc, lines


@pytest.mark.slow
@pytest.mark.parametrize("sig, status, group", [(signal.SIGINT, 130, False),
                                                (signal.SIGTERM, 143, True)])  # fmt: skip
def test_a_signal_stops_the_stream_with_130_or_143_and_no_starved_window(
    tiny_model, tmp_path, sig, status, group
):
    """SIGTERM to the whole process group (what systemd sends) used to stop the sampling
    process first: the stream labelled its last windows 'bus starved' and exited 2."""
    rec = tmp_path / "brick.csv"
    assert main(["record", str(rec), "--emulate", "brick", "--fast", "--duration", "30"]) == 0
    argv = ["--model", str(tiny_model), "--replay", str(rec), "--json",
            "--compile-cache", str(tmp_path / "cache")]  # fmt: skip
    proc, lines = _stream_until_labelled(argv, new_session=group)
    try:
        time.sleep(1.2)  # a few more windows
        if group:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    err = "".join(lines) + err
    assert proc.returncode == status, err
    assert "no-data" not in err and "starved" not in err and "Traceback" not in err, err
    summary = json.loads(out)
    assert summary["stopped_by"] == "signal" and summary["majority_label"] in ("brick", "sand")
    assert summary["samples"] >= 200 and summary["sampling"]["handoff"]["dropped"] == 0


@pytest.mark.slow
def test_a_real_clock_simulation_plays_its_terrain_to_the_end(tiny_model, tmp_path):
    """The emulated chip's clock used to start before the model's compilation, the sampler's
    after it: the simulated terrain (made for the duration + 2 s) ran out before the stream
    did, and its tail was labelled 'sensor-fault: flat' (a stuck chip that was not there)."""
    done = subprocess.run([sys.executable, "-m", "whiskerid.cli", "stream", "--model",
                           str(tiny_model), "--simulate", "brick", "--duration", "8", "--json",
                           "--quiet", "--compile-cache", "none"],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert "sensor-fault" not in out["label_counts"], out
    assert out["sampling"]["process"] is True  # played by the sampling process
    assert out["samples"] >= 0.995 * 8 * 200 - 2, out


def test_a_replay_shorter_than_the_duration_ends_at_the_end_of_its_file(tiny_model, tmp_path,
                                                                         capsys):  # fmt: skip
    """Past a replayed file's end the chip would hold its last value, a frozen sensor to the
    window checks: the stream stops at the end of the file and says so, with no fault."""
    rec = tmp_path / "brick.csv"
    assert main(["record", str(rec), "--emulate", "brick", "--fast", "--duration", "4"]) == 0
    capsys.readouterr()
    argv = ["stream", "--model", str(tiny_model), "--replay", str(rec), "--fast", "--duration",
            "30", "--compile-cache", "none", "--json"]  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert "end of file" in captured.err and "--duration 30" in captured.err
    assert "fault" not in json.dumps(out.get("labels", {})) and "stuck" not in captured.err
    assert out["windows"] <= 8, out  # windows of 4 s of samples, not 30
