"""Several inputs round-robin, and ``whiskerid record`` (no model, no JAX)."""

import json
import os
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
from whiskerid.hw import (
    EmulatedADS1115,
    EmulatedBus,
    FakeClock,
    InputScan,
    Recorder,
    Rounds,
    Sampler,
    data_rate_for,
    decode_config,
    max_scan_rate_hz,
    parse_inputs,
)

import whiskerid as wi
from whiskerid.cli import main
from whiskerid.io import Recording, TornRecordingWarning, write_csv


@pytest.mark.parametrize(
    "text, names, muxes, addresses",
    [
        ("A0", ["A0"], ["AIN0_GND"], [0x48]),
        ("A0,A1", ["A0", "A1"], ["AIN0_GND", "AIN1_GND"], [0x48, 0x48]),
        ("A0-A1", ["A0-A1"], ["AIN0_AIN1"], [0x48]),
        (" A2-A3 , A3", ["A2-A3", "A3"], ["AIN2_AIN3", "AIN3_GND"], [0x48, 0x48]),
        ("A0,0x49:A0", ["A0", "0x49:A0"], ["AIN0_GND", "AIN0_GND"], [0x48, 0x49]),
    ],
)
def test_inputs_are_named_like_the_pins(text, names, muxes, addresses):
    got = parse_inputs(text)
    assert [i.name for i in got] == names
    assert [i.mux for i in got] == muxes and [i.address for i in got] == addresses


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "no input"),
        ("A4", "not an ADS1115 input"),
        ("A1-A0", "not an ADS1115 input"),  # the mux has no such pair
        ("A0,A0", "named twice"),
        ("0x99:A0", "outside"),
    ],
)
def test_bad_inputs_are_refused_in_words(text, message):
    with pytest.raises(ValueError, match=message):
        parse_inputs(text)


def test_data_rate_is_the_slowest_that_fits_the_slot():
    assert data_rate_for(1 / 200) == 475  # one input at 200 Hz: 250 SPS (4.4 ms) is too slow
    assert data_rate_for(1 / 400) == 860  # two inputs at 200 Hz each
    assert 500 < max_scan_rate_hz(1) < 600 and max_scan_rate_hz(2) == max_scan_rate_hz(1) / 2
    with pytest.raises(ValueError, match="faster than single-shot"):
        data_rate_for(1 / 1000)


def _scan_rig(sources, text="A0,A1", **chip_kw):
    clock = FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    inputs = parse_inputs(text)
    chip = EmulatedADS1115(sources, **timing, **chip_kw)
    cfg = decode_config(0x8583).replace(fsr_v=4.096, data_rate_sps=860)
    scan = InputScan(chip, inputs, config=cfg, **timing)
    return chip, Sampler(scan, 200.0, **timing)


def test_round_robin_reads_each_input_at_the_rate_interleaved():
    chip, sampler = _scan_rig([lambda t: 1.0 + 0 * t, lambda t: 2.0 + t])
    got = list(sampler.samples(duration_s=1.0))
    ch = np.array([s.channel for s in got])
    t = np.array([s.t_s for s in got])
    v = np.array([s.volts for s in got])
    assert len(got) == 400 and ch.tolist() == [0, 1] * 200
    # Each input every 5 ms; A1 2.5 ms after A0: one fresh conversion per slot.
    np.testing.assert_allclose(np.diff(t[ch == 0]), 5e-3, atol=2e-6)
    np.testing.assert_allclose(t[ch == 1] - t[ch == 0], 2.5e-3, atol=2e-6)
    np.testing.assert_allclose(v[ch == 0], 1.0, atol=2e-4)
    # A1 is a ramp: its sample is the ramp at its own time (the conversion's midpoint).
    np.testing.assert_allclose(v[ch == 1], 2.0 + t[ch == 1], atol=2e-4)
    starts = [decode_config(b[0] << 8 | b[1]) for reg, b in chip.writes if reg == 1]
    assert [c.mux for c in starts[:4]] == ["AIN0_GND", "AIN1_GND"] * 2
    assert all(c.os and c.single_shot for c in starts)


def test_a_second_chip_answers_on_its_own_address():
    clock = FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    a = EmulatedADS1115(lambda t: 0.5 + 0 * t, address=0x48, **timing)
    b = EmulatedADS1115(lambda t: 1.5 + 0 * t, address=0x49, **timing)
    cfg = decode_config(0x8583).replace(fsr_v=4.096, data_rate_sps=860)
    scan = InputScan(EmulatedBus([a, b]), parse_inputs("A0,0x49:A0"), config=cfg, **timing)
    got = list(Sampler(scan, 100.0, **timing).samples(n=4))
    np.testing.assert_allclose([s.volts for s in got], [0.5, 1.5, 0.5, 1.5], atol=2e-4)
    assert a.conversions == b.conversions == 2


def test_a_lost_slot_drops_its_round_and_rows_stay_whole():
    chip, sampler = _scan_rig([lambda t: 1.0 + 0 * t, lambda t: 2.0 + 0 * t])
    rounds = Rounds(2)
    rows, injected = [], False
    for s in sampler.samples(duration_s=0.1, gaps=True):
        if s.t_s > 0.03 and not injected:
            chip.fail_next(4)  # exhausts the driver's retries: the next slot is lost
            injected = True
        if hasattr(s, "code") and (r := rounds.push(s)) is not None:
            rows.append(r)
    assert sampler.stats.gaps == 1 and rounds.incomplete >= 1
    assert len(rows) == 20 - rounds.incomplete
    # Every row is one round: A0 then A1 a slot (2.5 ms) later; the slot after the failed
    # read's retries may be read late, by under half a slot, with its real timestamp.
    lags = np.array([times[1] - times[0] for times, _ in rows])
    assert np.all((lags > 1.25e-3) & (lags < 3.75e-3))
    assert np.count_nonzero(np.abs(lags - 2.5e-3) < 1e-5) >= len(rows) - 1
    for _, codes in rows:
        assert codes == pytest.approx([1.0 / 4.096 * 32768, 2.0 / 4.096 * 32768], abs=2)


def test_own_times_columns_round_trip_through_the_reader(tmp_path):
    rec = Recorder(tmp_path / "r.csv", columns=("A0", "A1"), own_times=True, units="code")
    rec.write_round([0.0, 0.0025], [10, 20])
    rec.write_round([0.005, 0.0075], [11, 21])
    rec.close()
    got = wi.read_recording(tmp_path / "r.csv")
    assert list(got.columns) == ["A0", "A1"]  # t_A1 is a time, not a signal
    np.testing.assert_allclose(got.time_of("A1"), [0.0025, 0.0075])
    np.testing.assert_allclose(got.time_of("A0"), got.t)
    write_csv(tmp_path / "again.csv", got)
    assert wi.read_recording(tmp_path / "again.csv").times.keys() == {"A1"}
    with Recorder(tmp_path / "x.csv", columns=("A0", "A1"), own_times=True) as bad:
        with pytest.raises(ValueError, match="write_round"):
            bad.write(0.0, 1, 2)


@pytest.fixture
def two_plane(tmp_path):
    """A recording in volts with a column per input, to feed the emulated chip."""
    t = np.arange(0, 3.0, 1e-4)
    cols = {"A0": 1.6 + 0.3 * np.sin(2 * np.pi * 7 * t),
            "A1": 1.2 + 0.2 * np.cos(2 * np.pi * 3 * t)}  # fmt: skip
    return write_csv(tmp_path / "src.csv", Recording(t=t, columns=cols, meta={"units": "V"}))


def test_record_two_inputs_each_with_its_own_time(tmp_path, two_plane, capsys):
    out = tmp_path / "rec.csv"
    argv = ["record", str(out), "--inputs", "A0,A1", "--emulate", str(two_plane), "--fast",
            "--duration", "2", "--units", "V", "--json"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == 400 and summary["data_rate_sps"] == 860 and summary["gaps"] == 0
    rec = wi.read_recording(out)
    assert list(rec.columns) == ["A0", "A1"] and rec.meta["interleave_s"] == "0.0025"
    np.testing.assert_allclose(rec.time_of("A1") - rec.t, 2.5e-3, atol=1e-5)
    for name, f in (("A0", lambda t: 1.6 + 0.3 * np.sin(2 * np.pi * 7 * t)),
                    ("A1", lambda t: 1.2 + 0.2 * np.cos(2 * np.pi * 3 * t))):  # fmt: skip
        np.testing.assert_allclose(rec.columns[name], f(rec.time_of(name)), atol=2e-3)
    assert main(argv) == 2  # the file exists now: never overwritten
    assert "exists" in capsys.readouterr().err


def test_record_one_input_at_the_chips_fastest_rate(tmp_path, two_plane, capsys):
    out = tmp_path / "fast.csv"
    argv = ["record", str(out), "--rate", "860", "--emulate", str(two_plane), "--fast",
            "--duration", "1", "--json", "--speed", "0.3"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["mode"] == "continuous" and 855 <= summary["rows"] <= 860
    rec = wi.read_recording(out)
    assert rec.meta["units"] == "code" and list(rec.columns) == ["A0"]
    assert rec.meta["speed_mps"] == "0.3"  # for train and classify
    assert np.median(np.diff(rec.t)) == pytest.approx(1 / 860, rel=1e-3)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--inputs", "A7"], "not an ADS1115 input"),
        (["--inputs", "A0,A1", "--rate", "400"], "at most 2"),
        (["--rate", "1000"], "at most"),
        (["--rate", "nan"], "positive number"),
        (["--data-rate", "200"], "does not exist"),
    ],
)
def test_record_refuses_bad_options_in_one_line(tmp_path, two_plane, capsys, args, message):
    argv = ["record", str(tmp_path / "o.csv"), "--emulate", str(two_plane), "--fast",
            "--duration", "1", *args]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_record_survives_kill_9_and_needs_no_jax(tmp_path, two_plane):
    """Real time on the emulated chip: a kill -9 leaves a readable file; JAX never loads."""
    out = tmp_path / "k.csv"
    probe = (
        "import sys; from whiskerid.cli import main; "
        "main(sys.argv[1:]); print('jax' in sys.modules)"
    )
    cmd = [sys.executable, "-c", probe, "record", str(out), "--inputs", "A0,A1",
           "--emulate", str(two_plane)]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # wait for the first synced second of rows
            if out.exists() and out.read_text().count("\n") > 150:
                break
            time.sleep(0.1)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornRecordingWarning)  # a torn last row at most
        rec = wi.read_recording(out, allow_empty=True)
    assert rec.t.size >= 100 and rec.columns.keys() == {"A0", "A1"}
    # The same, stopped by SIGTERM: a clean close, and no JAX in the process.
    done = subprocess.run([*cmd[:4], str(tmp_path / "j.csv"), *cmd[5:], "--duration", "0.5"],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.returncode == 0 and done.stdout.strip() == "False", done.stderr


def test_a_bus_error_of_another_type_is_retried_like_an_oserror():
    clock = FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    chip = EmulatedADS1115(lambda t: 1.0 + 0 * t, **timing)
    from whiskerid.hw import ADS1115, I2CError

    adc = ADS1115(chip, **timing)
    chip.fail_next(2, RuntimeError("bus glitch"))
    assert adc.read_volts() == pytest.approx(1.0, abs=2e-4)  # retried, not raised
    assert adc.stats.retries == 2
    chip.fail_next(4, KeyError("odd"))
    with pytest.raises(I2CError, match="KeyError"):
        adc.read()


@pytest.mark.slow
def test_a_pluck_recorded_fast_calibrates_to_the_truth(tmp_path, capsys):
    """A held pluck of the paper whisker on the emulated chip, recorded with `record` at
    500 Hz (above twice the second mode's alias-free limit for the first), calibrates with
    `calibrate` as it is: the file needs no conversion."""
    rec, out = tmp_path / "pluck.csv", tmp_path / "fit.toml"
    whisker = tmp_path / "paper.toml"
    wi.paper_record().save(whisker)
    argv = ["record", str(rec), "--emulate", "pluck", "--rate", "500", "--duration", "2",
            "--fast"]  # fmt: skip
    assert main(argv) == 0
    assert main(["calibrate", str(rec), "--whisker", str(whisker), "--out", str(out),
                 "--json"]) == 0  # fmt: skip
    fit = json.loads(capsys.readouterr().out)
    truth = wi.paper_record()
    assert fit["params"]["f1_hz"]["value"] == pytest.approx(
        float(truth.whisker().natural_frequencies_hz[0]), abs=0.05
    )
    assert fit["params"]["zeta"]["value"] == pytest.approx(float(truth.zeta), rel=0.03)
