"""The crash-tolerant Recorder, read back by the library's reader (which drops a torn end)."""

import re
import warnings

import numpy as np
import pytest
from whiskerid.hw import (
    ADS1115,
    EmulatedADS1115,
    FakeClock,
    Recorder,
    Sampler,
    read_recording_csv,
    unique_path,
)

from whiskerid.io import RecordingError, TornRecordingWarning, read_recording


class FsyncCounter:
    def __init__(self):
        self.calls = 0

    def __call__(self, fd):
        self.calls += 1


def test_file_format_metadata_and_header(tmp_path):
    path = tmp_path / "rec.csv"
    with Recorder(path, rate_hz=200, whisker="paper", metadata={"terrain": "sand"}) as rec:
        rec.write(0.0, 1.5)
        rec.write(0.005, -0.000125)
        rec.write(0.0100004, 3.3)
    lines = path.read_text().splitlines()
    assert lines[:3] == ["# rate_hz: 200", "# units: V", "# whisker: paper"]
    assert re.fullmatch(r"# started_utc: \d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", lines[3])
    assert lines[4:] == [
        "# terrain: sand",
        "t,voltage",
        "0.000000000,1.5",
        "0.005000000,-0.000125",
        "0.010000400,3.3",
    ]
    back = read_recording(path)
    np.testing.assert_array_equal(back.t, [0.0, 0.005, 0.0100004])
    np.testing.assert_array_equal(back.columns["voltage"], [1.5, -0.000125, 3.3])
    assert back.meta["rate_hz"] == "200" and back.meta["terrain"] == "sand"
    assert back.meta["units"] == "V"


def test_fsync_at_least_once_per_second_not_per_row(tmp_path):
    clock = FakeClock()
    fsync = FsyncCounter()
    rec = Recorder(tmp_path / "r.csv", clock=clock.now_ns, fsync=fsync)
    assert fsync.calls == 1  # header durable at once
    for k in range(2000):  # 10 s at 200 Hz
        rec.write(k * 0.005, 0.1)
        clock.advance(0.005)
    assert 10 <= fsync.calls <= 12
    rec.close()
    assert fsync.calls == rec.syncs


def test_crash_without_close_leaves_all_but_the_last_second(tmp_path):
    clock = FakeClock()
    path = tmp_path / "crash.csv"
    rec = Recorder(path, rate_hz=200, clock=clock.now_ns)
    written = []
    for k in range(700):  # 3.5 s
        t = k * 0.005
        rec.write(t, np.sin(t))
        written.append((t, np.sin(t)))
        clock.advance(0.005)
    try:
        # "Crash": read from another handle without closing or flushing the recorder. Python's
        # buffer may have gone to disk mid-row: only a torn-row warning is allowed.
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            back = read_recording(path)
    finally:
        rec.close()
    assert all(w.category is TornRecordingWarning for w in caught)
    n = len(back.t)
    assert written[-1][0] - back.t[-1] <= 1.0
    assert n >= 700 - 200
    np.testing.assert_allclose(back.t, [t for t, _ in written[:n]], rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.columns["voltage"], [v for _, v in written[:n]], rtol=1e-8)
    assert len(read_recording(path).t) == 700


def write_rows(path, n=10):
    with Recorder(path, rate_hz=200) as rec:
        for k in range(n):
            rec.write(k * 0.005, 1.0 + k * 0.0123456)
    return path.read_bytes()


TORN = {
    # The last row is "0.045000000,1.1111104\n"; cut: bytes dropped from the end; tail: bytes
    # added after the cut.
    "cut mid-number, still parses": (-4, b""),  # "...,1.111"
    "cut after the comma": (-10, b""),
    "cut inside the time, a short row": (-13, b""),
    "cut mid-number, then NULs": (-3, b"\0" * 4096),
}


@pytest.mark.parametrize("case", TORN)
def test_torn_last_row_is_dropped_with_a_warning_naming_the_file(tmp_path, case):
    cut, tail = TORN[case]
    path = tmp_path / "torn.csv"
    path.write_bytes(write_rows(path)[:cut] + tail)
    with pytest.warns(TornRecordingWarning, match="torn.csv"):
        back = read_recording(path)
    assert len(back.t) == 9
    np.testing.assert_allclose(back.columns["voltage"], 1.0 + np.arange(9) * 0.0123456)


def test_nul_tail_after_complete_rows_keeps_every_row(tmp_path):
    path = tmp_path / "nul.csv"
    path.write_bytes(write_rows(path) + b"\0" * 100)
    with pytest.warns(TornRecordingWarning, match=r"nul.csv: ignored 100 NUL"):
        assert len(read_recording(path).t) == 10


def test_malformed_row_before_the_end_is_an_error(tmp_path):
    path = tmp_path / "bad.csv"
    data = write_rows(path).decode()
    lines = data.split("\n")
    lines[8] = "0.02,abc"
    path.write_text("\n".join(lines))
    with pytest.raises(RecordingError, match=r"bad.csv line 9, column 'voltage': 'abc'"):
        read_recording(path)
    path.write_text("# rate_hz: 200\n")
    with pytest.raises(RecordingError, match="no header"):
        read_recording(path)


def test_header_only_file_reads_as_empty(tmp_path):
    path = tmp_path / "empty.csv"
    Recorder(path, columns=("voltage", "adc")).close()
    back = read_recording(path, allow_empty=True)
    assert back.t.shape == (0,) and set(back.columns) == {"voltage", "adc"}
    assert read_recording_csv(path).columns.keys() == back.columns.keys()  # the old name
    with pytest.raises(RecordingError, match="no data rows"):
        read_recording(path)


def test_no_overwrite_unless_asked_and_unique_path(tmp_path):
    path = tmp_path / "rec.csv"
    write_rows(path, 3)
    with pytest.raises(FileExistsError):
        Recorder(path)
    assert unique_path(path) == tmp_path / "rec-1.csv"
    (tmp_path / "rec-1.csv").touch()
    assert unique_path(path) == tmp_path / "rec-2.csv"
    assert unique_path(tmp_path / "new.csv") == tmp_path / "new.csv"
    Recorder(path, overwrite=True).close()
    assert len(read_recording(path, allow_empty=True).t) == 0


def test_bad_use_raises(tmp_path):
    with pytest.raises(ValueError, match="column"):
        Recorder(tmp_path / "a.csv", columns=("a,b",))
    with pytest.raises(ValueError, match="metadata"):
        Recorder(tmp_path / "b.csv", metadata={"note": "two\nlines"})
    rec = Recorder(tmp_path / "c.csv", columns=("x", "y"))
    with pytest.raises(ValueError, match="expected 2 values"):
        rec.write(0.0, 1.0)
    rec.close()
    rec.close()  # idempotent
    assert rec.closed
    with pytest.raises(ValueError, match="closed"):
        rec.write(0.0, 1.0, 2.0)


def test_sampler_into_recorder(tmp_path):
    clock = FakeClock()
    emu = EmulatedADS1115(lambda t: 0.75, clock=clock.now_ns, sleep=clock.sleep)
    drv = ADS1115(emu, clock=clock.now_ns, sleep=clock.sleep)
    sampler = Sampler(drv, 200.0, clock=clock.now_ns, sleep=clock.sleep)
    path = tmp_path / "stream.csv"
    with Recorder(path, rate_hz=sampler.rate_hz, clock=clock.now_ns) as rec:
        samples = []
        sampler.run(lambda s: (samples.append(s), rec(s)), n=50)
    back = read_recording(path)
    np.testing.assert_allclose(back.t, [s.t_s for s in samples], atol=1e-9)
    np.testing.assert_array_equal(back.columns["voltage"], 0.75)
    assert back.meta["rate_hz"] == "200.0"
