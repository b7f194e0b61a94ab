"""What must never stop or fool the Pi side: absurd inputs refused in one line, signals that
always stop a stream or a recording with 130/143, a full disk, a missing robot speed, a long
replay, a busy machine."""

import errno
import gc
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from whiskerid import hw
from whiskerid.cli import main
from whiskerid.io import Recording, write_csv


class Model:
    """A stand-in model: 'loud' when the window's std exceeds 1, else 'quiet'."""

    window, rate_hz, channel, labels, lookback_s = 200, 200.0, "adc", ("loud", "quiet"), 0.0
    needs_speed = False

    def __init__(self):
        self.speeds = []

    def window_proba(self, samples, speed=None):
        if self.needs_speed and speed is None:
            raise ValueError("this model needs the robot speed (m/s) of each window")
        self.speeds.append(speed)
        return np.array([0.9, 0.1]) if np.std(samples) > 1 else np.array([0.2, 0.8])


class SpeedModel(Model):
    needs_speed = True


def _live(n=1200):
    t = np.arange(n) / 200.0
    x = 10 * np.sin(2 * np.pi * 20 * t) + np.random.default_rng(0).standard_normal(n)
    return [hw.Sample(float(a), round(b), float(b)) for a, b in zip(t, x, strict=True)]


@pytest.fixture
def sine_csv(tmp_path):
    """Four seconds of a 20 Hz sine in codes at 200 Hz, as ``whiskerid record`` writes."""
    t = np.arange(800) / 200.0
    code = np.round(5000 * np.sin(2 * np.pi * 20 * t)).astype(int)
    path = tmp_path / "sine.csv"
    write_csv(path, Recording(t, {"A0": code}, {"units": "code", "fsr_v": "4.096"}))
    return path


def _millis(path, out):
    """The same recording with its times in milliseconds."""
    lines = path.read_text().splitlines()
    rows = [ln for ln in lines if ln and ln[0].isdigit()]
    head = [ln for ln in lines if not (ln and ln[0].isdigit())]
    rows = [f"{float(r.split(',')[0]) * 1e3:.6f},{r.split(',', 1)[1]}" for r in rows]
    out.write_text("\n".join(head + rows) + "\n")
    return out


# --------------------------------------------------------------------------- absurd input
def _refused(capsys, argv, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for w in words:
        assert w in err, err
    return err


def test_record_refuses_a_data_rate_slower_than_its_slots(tmp_path, sine_csv, capsys):
    # Today an 8 SPS file is written with rate_hz: 200: 25 of every 26 rows repeat a
    # conversion under a new timestamp.
    out = tmp_path / "o.csv"
    argv = ["record", str(out), "--emulate", str(sine_csv), "--fast", "--duration", "1"]
    _refused(capsys, [*argv, "--data-rate", "8"], "--data-rate 8 SPS converts in 125 ms",
             "5 ms slot", "--data-rate 475")  # fmt: skip
    assert not out.exists()
    assert main([*argv, "--data-rate", "250"]) == 0  # 4 ms fits the 5 ms slot


def test_record_refuses_an_unknown_terrain_naming_the_known_ones(tmp_path, capsys):
    argv = ["record", str(tmp_path / "o.csv"), "--emulate", "lava", "--fast", "--duration", "1"]
    _refused(capsys, argv, "'lava'", "brick", "soft-grass", "pluck")


def test_millisecond_timestamps_are_refused_by_record_and_stream(tmp_path, sine_csv, capsys):
    ms = _millis(sine_csv, tmp_path / "ms.csv")
    out = tmp_path / "o.csv"
    argv = ["record", str(out), "--emulate", str(ms), "--fast", "--duration", "1"]
    _refused(capsys, argv, "0.2 Hz", "is the time column in seconds?")
    assert not out.exists()
    # The stream reads the recording before the model: a model folder need not exist.
    argv = ["stream", "--model", str(tmp_path / "m"), "--replay", str(ms), "--fast"]
    _refused(capsys, argv, "--replay", "0.2 Hz", "is the time column in seconds?")


@pytest.mark.parametrize("speed", ["50", "1e6", "-1", "nan"])
def test_implausible_speeds_are_refused(tmp_path, sine_csv, capsys, speed):
    model = str(tmp_path / "m")
    argv = ["stream", "--model", model, "--replay", str(sine_csv), "--fast", "--speed", speed]
    _refused(capsys, argv, "--speed")
    argv = ["record", str(tmp_path / "o.csv"), "--emulate", str(sine_csv), "--fast",
            "--duration", "1", "--speed", speed]  # fmt: skip
    _refused(capsys, argv, "--speed")


def test_an_implausible_speed_in_a_replayed_recording_is_refused(tmp_path, sine_csv, capsys):
    text = sine_csv.read_text().replace("# units: code", "# units: code\n# speed_mps: 50")
    fast = tmp_path / "fast.csv"
    fast.write_text(text)
    argv = ["stream", "--model", str(tmp_path / "m"), "--replay", str(fast), "--fast"]
    _refused(capsys, argv, "speed_mps", "50", "not plausible as a robot speed")


def test_a_live_speed_beyond_any_robot_is_ignored_and_counted():
    import io

    feed = hw.SpeedFeed("-", stream=io.StringIO('{"speed_mps": 0.3}\n{"speed_mps": 50}\n1e6\n'))
    feed._thread.join(5)
    assert feed.latest == 0.3 and feed.messages == 1 and feed.bad_messages == 2


# --------------------------------------------------------------------------- signals
def test_a_sigint_inside_a_garbage_collection_callback_still_stops_the_stream():
    """JAX registers gc callbacks; Python prints and drops an exception raised in one. A
    handler that raised KeyboardInterrupt there lost the Ctrl-C: the stream ran to its end."""
    fired = []

    def callback(phase, info):
        if phase == "start" and not fired:
            fired.append(True)
            signal.raise_signal(signal.SIGINT)  # the handler runs here, inside the callback

    def source():
        for i, s in enumerate(_live()):
            if i == 300:
                gc.callbacks.append(callback)
                try:
                    gc.collect()
                finally:
                    gc.callbacks.remove(callback)
            yield s

    summary = hw.run_stream(source(), hw.OnlineClassifier(Model()), background=False)
    assert fired and summary.stopped_by == "signal" and summary.signal == signal.SIGINT
    assert summary.samples == 300  # not one sample, nor one window, after the signal


@pytest.mark.parametrize("sig, status", [pytest.param(signal.SIGINT, 130, marks=pytest.mark.slow),
                                         (signal.SIGTERM, 143)])  # fmt: skip
def test_record_exits_130_or_143_on_a_signal_with_its_file_whole(tmp_path, sine_csv, sig,
                                                                  status):  # fmt: skip
    out = tmp_path / "r.csv"
    cmd = [sys.executable, "-m", "whiskerid.cli", "record", str(out), "--emulate", str(sine_csv),
           "--json"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out.exists() and out.stat().st_size > 3000):
            time.sleep(0.05)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == status, stderr
    assert f"interrupted ({signal.Signals(sig).name})" in stderr and "Traceback" not in stderr
    import json

    summary = json.loads(stdout)
    assert summary["stopped_by"] == "signal" and summary["rows"] > 100
    assert summary["priority"].startswith(("SCHED_FIFO", "nice", "normal ("))
    rec = hw.read_recording_csv(out)  # whole: no torn row, no warning
    assert rec.t.size == summary["rows"]


# --------------------------------------------------------------------------- faults
def test_a_full_disk_stops_the_recording_not_the_labels(tmp_path):
    syncs = []

    def fsync(fd):
        syncs.append(fd)
        if len(syncs) >= 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        os.fsync(fd)

    clock = hw.FakeClock()
    rec = hw.Recorder(tmp_path / "r.csv", columns=("adc",), rate_hz=200, units="code",
                      fsync=fsync, clock=clock.now_ns)  # fmt: skip
    notes = []

    def paced():
        for s in _live(1200):
            clock.advance_to_ns(round(s.t_s * 1e9))  # the recorder syncs every second
            yield s

    summary = hw.run_stream(paced(), hw.OnlineClassifier(Model()), recorder=rec,
                            background=False, on_note=notes.append)  # fmt: skip
    assert summary.samples == 1200 and summary.windows == 10  # ends at 1.0, 1.5, ..., 5.5 s
    assert summary.label_counts == {"loud": 10}
    assert rec.closed and len(notes) == 1 and "No space left on device" in notes[0]
    assert summary.to_dict()["record_stopped"] == notes[0]


def test_no_speed_yet_a_nan_and_a_silent_feed_never_stop_the_stream():
    """A model that needs the speed: before any reading its windows are no-data (said why),
    a NaN or an implausible reading is replaced by the last good one, and a silent feed
    too once it is stale; each such label says so."""
    values = {0: None, 1: None, 2: 0.3, 3: float("nan"), 4: 40.0, 5: 0.25}

    def speed(t_s):
        return values[min(int(t_s), 5)]

    model = SpeedModel()
    online = hw.OnlineClassifier(model, hop_s=0.5, speed_mps=speed)
    online.warm_up()  # compiles with a nominal speed: no speed is needed yet
    got = hw.run_stream(_live(1400), online, background=False)
    assert got.stopped_by == "duration" and got.windows == 12  # 1.0, 1.5, ..., 6.5 s
    labels = []
    online = hw.OnlineClassifier(SpeedModel(), hop_s=0.5, speed_mps=speed)
    hw.run_stream(_live(1400), online, background=False, on_label=labels.append)
    early = [w for w in labels if w.t_end_s < 1.99]
    assert all(w.label == "no-data" and "no robot speed" in w.reason for w in early)
    assert all(w.speed_note == "none received yet" for w in early)
    fresh = [w for w in labels if 2.0 <= w.t_end_s < 2.99 or w.t_end_s >= 5.0]
    assert all(w.label == "loud" and w.speed_note == "" for w in fresh)
    stale = [w for w in labels if 3.0 <= w.t_end_s < 4.99]
    assert stale and all(w.label == "loud" and w.speed_mps == 0.3 for w in stale)
    assert all(w.speed_note.startswith("last known 0.3 m/s") for w in stale)

    class Silent:  # a live feed whose last message is 10 s old
        def __call__(self, t_s):
            return 0.2

        def age_s(self):
            return 10.0

    online = hw.OnlineClassifier(SpeedModel(), speed_mps=Silent())
    assert online.speed_with_note(5.0) == (0.2, "last known 0.2 m/s, 10.0 s old")


def test_an_odometry_log_with_nan_and_an_end_gives_nan_not_a_guess(tmp_path):
    odo = tmp_path / "odo.csv"
    odo.write_text("t,speed_mps\n0,0.2\n1,nan\n2,0.2\n3,80\n4,0.3\n")
    speed = hw.odometry_speed(odo)
    assert speed(0.0) == 0.2 and speed(4.0) == 0.3
    assert np.isnan(speed(0.5)) and np.isnan(speed(3.5)) and np.isnan(speed(9.0))


def test_a_replay_costs_the_same_per_sample_however_long_the_recording():
    """Times read from CSV are a strided column: np.interp copied the whole recording on
    every conversion (about 1 s of CPU per replayed second at 2 M rows)."""

    def cost(n):
        table = np.stack([np.arange(n) / 200.0, np.sin(np.arange(n) / 10.0)], axis=1)
        src = hw.source_from_recording(table[:, 0], table[:, 1])  # strided, as read_csv gives
        q = 2.0 + np.arange(16) / 16 / 475
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(200):
                src(q)
            best = min(best, time.perf_counter() - t0)
        return best

    short, long = cost(2_000), cost(2_000_000)
    assert long < 5 * short + 2e-3, (short, long)


def test_the_sampling_process_reports_its_priority_and_hand_off(sine_csv):
    proc = hw.SamplingProcess(hw.SamplerSpec(replay=str(sine_csv), duration_s=0.3))
    items = list(proc)
    proc.close()
    assert items and proc.priority is not None
    assert proc.priority.startswith(("SCHED_FIFO", "nice", "normal ("))
    assert proc.handoff["dropped"] == 0 and proc.handoff["pipe_bytes"] >= 0


def test_the_hand_off_never_waits_for_a_stalled_reader():
    r, w = os.pipe()
    try:
        writer = hw.PipeWriter(w, pipe_bytes=4096, max_backlog=64 << 10)
        line = b"x" * 99 + b"\n"
        t0 = time.perf_counter()
        for _ in range(2000):  # 200 kB into a reader that never reads
            writer.write(line)
        assert time.perf_counter() - t0 < 1.0
        assert writer.dropped > 0 and writer.backlog <= 64 << 10
        got = b""
        os.set_blocking(r, False)
        while True:
            try:
                chunk = os.read(r, 1 << 16)
            except BlockingIOError:
                if not writer.backlog:
                    break
                writer.drain(0.1)
                continue
            got += chunk
        assert got.count(b"\n") == 2000 - writer.dropped  # whole lines, in order
    finally:
        os.close(r)
        os.close(w)


def test_raise_priority_says_what_it_got():
    done = subprocess.run([sys.executable, "-c", "from whiskerid import hw; "
                           "print(hw.raise_priority('nice', nice=5)); "
                           "print(hw.raise_priority('none'))"],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.stdout.splitlines() == ["nice 5", "normal (asked for none)"], done.stderr
    script = ("import os; from whiskerid import hw\n"
              "with hw.raised_priority('realtime') as got:\n"
              "    print(got, os.sched_getscheduler(0) == os.SCHED_FIFO)\n"
              "print(os.sched_getscheduler(0) == os.SCHED_OTHER)")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60)  # fmt: skip
    lines = done.stdout.splitlines()
    assert lines[-1] == "True", done.stderr  # put back, whatever was granted
    assert lines[0] in ("SCHED_FIFO 20 True",) or lines[0].startswith("normal (")
    with pytest.raises(ValueError, match="use auto, realtime, nice or none"):
        hw.raise_priority("fastest")
