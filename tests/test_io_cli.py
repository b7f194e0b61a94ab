"""Recordings on disk and the command line (simulate, demo, errors)."""

import json

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli import main


def test_csv_round_trip_with_metadata(tmp_path):
    rec = wi.Recording(
        t=np.array([0.0, 0.005, 0.0101]),
        columns={"adc": np.array([1, -2, 3])},
        meta={"rate_hz": "200", "units": "code"},
    )
    back = wi.read_recording(wi.write_csv(tmp_path / "r.csv", rec))
    np.testing.assert_array_equal(back.t, rec.t)
    np.testing.assert_array_equal(back.signal("adc"), [1, -2, 3])
    assert back.meta == {"rate_hz": "200", "units": "code"}
    with pytest.raises(wi.RecordingError, match="no column 'x'"):
        back.signal("x")


def test_npy_time_signal_layout(tmp_path):
    np.save(tmp_path / "a.npy", np.vstack([np.arange(5.0), np.ones(5)]))
    rec = wi.read_recording(tmp_path / "a.npy")
    np.testing.assert_array_equal(rec.t, np.arange(5.0))


@pytest.mark.parametrize(
    ("t", "x", "message"),
    [
        ([0, 1, 1, 2, 3, 4, 5, 6], np.ones(8), "duplicate timestamp at row 2"),
        ([0, 1, 0.5, 2, 3, 4, 5, 6], np.ones(8), "decreasing"),
        (np.arange(8.0), [0, 1, np.nan, 0, 0, 0, 0, 0], "non-finite signal"),
        (np.arange(3.0), np.ones(3), "only 3 samples"),
    ],
)
def test_bad_samples_are_refused(t, x, message):
    with pytest.raises(wi.RecordingError, match=message):
        wi.check_samples(np.asarray(t, float), np.asarray(x, float))


def test_simulate_writes_csv_plot_and_json(tmp_path, capsys):
    out, png = tmp_path / "s.csv", tmp_path / "s.png"
    code = main(
        [
            "simulate",
            "--model",
            "exact",
            "--excitation",
            "sine",
            "--fb",
            "30",
            "--hb",
            "2e-4",
            "--rate",
            "200",
            "--duration",
            "3",
            "--observable",
            "voltage",
            "--noise-db",
            "30",
            "--seed",
            "4",
            "--out",
            str(out),
            "--plot",
            str(png),
            "--json",
        ]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["samples"] == 600
    assert summary["dominant_peaks_hz"][0] == pytest.approx(30.0, abs=0.2)
    rec = wi.read_recording(out)
    assert list(rec.columns) == ["voltage"] and rec.t.size == 600
    assert rec.meta["units"] == "V" and rec.meta["fb_hz"] == "30"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_is_reproducible_by_seed(tmp_path):
    args = ["simulate", "--observable", "adc", "--duration", "1", "--noise-db", "20"]
    for name, seed in (("a", "1"), ("b", "1"), ("c", "2")):
        assert main([*args, "--seed", seed, "--out", str(tmp_path / f"{name}.csv")]) == 0
    read = lambda n: wi.read_recording(tmp_path / f"{n}.csv").signal()
    np.testing.assert_array_equal(read("a"), read("b"))
    assert not np.array_equal(read("a"), read("c"))


def test_simulate_base_motion_from_a_file(tmp_path):
    t = np.arange(0, 2, 1 / 1000)
    base = wi.Recording(t=t, columns={"acc": 5 * np.sin(2 * np.pi * 20 * t)})
    wi.write_csv(tmp_path / "base.csv", base)
    out = tmp_path / "o.csv"
    assert (
        main(
            [
                "simulate",
                "--excitation",
                "base",
                "--base",
                str(tmp_path / "base.csv"),
                "--duration",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    sim = wi.read_recording(out)
    late = sim.t > 1.0
    peaks = wi.dominant_peaks(sim.t[late], sim.signal()[late], n=1)
    assert peaks[0].frequency_hz == pytest.approx(20.0, abs=0.3)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--model", "paper", "--excitation", "decay"], "sine only"),
        (["--whisker", "/nonexistent.toml"], "no such whisker record"),
        (["--excitation", "base"], "--base FILE"),
        (["--rate", "-5"], "rate_hz"),
    ],
)
def test_simulate_bad_input_one_line_and_status_2(tmp_path, capsys, argv, message):
    assert main(["simulate", *argv, "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.slow  # every stage of the demo, with its plots
def test_demo_runs_end_to_end(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(
        summary["natural_frequencies_hz"], [46.0, 288.2, 807.1, 1581.6, 2614.4], rtol=1e-3
    )
    for row in summary["modal_analysis"]:
        assert row["paper"]["peaks_hz"][0] == row["fb_hz"] == row["exact"]["peaks_hz"][0]
    for name in ("modal_analysis_paper.png", "modal_analysis_exact.png", "pluck_adc.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    post = summary["posterior"]  # stage 5: emcee on the calibrated pluck (true zeta 0.04)
    z = post["zeta"]
    assert z["q2.5"] < z["q16"] < z["median"] < z["q84"] < z["q97.5"]
    assert abs(z["median"] - 0.04) < 0.002 and z["q84"] - z["q16"] < 0.002
    assert post["converged"] and post["steps"] >= post["steps_needed"] and z["tau"] > 1
    for name in ("posterior_corner.png", "posterior_trace.png", "posterior-whisker.toml"):
        assert (tmp_path / name).stat().st_size > 1_000
    cls = summary["classification"]  # stage 6: 7 terrains, held-out recordings (measured 0.96)
    assert cls["accuracy"] > 0.85 and cls["accuracy_per_recording"] > 0.85


def test_posterior_intervals_print_digits_that_tell_the_bounds_apart():
    from whiskerid.cli._posterior import interval_text

    narrow = {"median": 16.32812, "q16": 16.32801, "q84": 16.32823, "q2.5": 16.3279,
              "q97.5": 16.3284}  # fmt: skip
    text = interval_text(narrow)
    lo, hi = text.split("68%: ")[1].split(";")[0].split(" .. ")
    assert lo != hi and float(lo) < float(hi), text
    wide = {"median": 0.04, "q16": 0.039, "q84": 0.041, "q2.5": 0.038, "q97.5": 0.042}
    assert interval_text(wide).startswith("0.04 (68%: 0.039 .. 0.041;")
