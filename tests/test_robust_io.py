"""Bad input on disk and on the command line: one-line refusals, inputs never destroyed.

Every refusal is checked through ``main`` (exit status 2, one line on stderr, no traceback)
or through the reader (a :class:`RecordingError` naming file, line and column).
"""

import json
import math

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli._main import json_safe, main
from whiskerid.fit._result import poor_fit_warnings
from whiskerid.io import TornRecordingWarning
from whiskerid.terrain import RunSpec, dataset_paths, speed_tag, synthesize_dataset

T = np.round(np.arange(12) / 200.0, 6)
X = np.arange(12) * 3 - 7


def _rows(sep=",") -> list[str]:
    return [f"{a!r}{sep}{b}" for a, b in zip(T.tolist(), X.tolist(), strict=True)]


def _write(path, text: str | bytes):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _refused(capsys, argv, *needles) -> str:
    """Run the CLI: exit status 2 and one line on stderr holding every needle."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for needle in needles:
        assert needle in err[0], err[0]
    return err[0]


# --------------------------------------------------------------------------- CSV variants
GOOD_VARIANTS = {
    "bom": "\ufeff" + "\n".join(["t,adc", *_rows()]),
    "bom and metadata": "\ufeff# rate_hz: 200\n" + "\n".join(["t,adc", *_rows()]),
    "blank lines after metadata": "# rate_hz: 200\n\n\n" + "\n".join(["t,adc", *_rows()]),
    "tab": "\n".join(["t\tadc", *_rows("\t")]),
    "semicolon": "\n".join(["t;adc", *_rows(";")]),
    "spaces and crlf": "\r\n".join(["t, adc", *_rows(", ")]),
    "blank line inside": "\n".join(["t,adc", *_rows()[:5], "", *_rows()[5:], "", ""]),
}


@pytest.mark.parametrize("case", GOOD_VARIANTS)
def test_csv_dialects_read_like_the_plain_file(tmp_path, case):
    rec = wi.read_recording(_write(tmp_path / "r.csv", GOOD_VARIANTS[case]))
    np.testing.assert_array_equal(rec.t, T)
    assert list(rec.columns) == ["adc"]
    np.testing.assert_array_equal(rec.signal(), X)
    if "metadata" in case:
        assert rec.meta == {"rate_hz": "200"}


def _with_row(index: int, row: str, header: str = "t,adc") -> str:
    rows = _rows()
    rows[index] = row
    return "\n".join([header, *rows])


BAD_CSV = {
    "empty cell": (_with_row(3, "0.015,"), "line 5, column 'adc': '' is not a number"),
    "NA cell": (_with_row(3, "0.015,NA"), "line 5, column 'adc': 'NA' is not a number"),
    "decimal comma": (
        "\n".join(["t;adc", "0,0;1", "0,005;2"]),
        "line 2, column 't': '0,0' is not a number; use a decimal point",
    ),
    "comment inside the data": (_with_row(6, "# paused here"), "line 8: a comment line"),
    "ragged row": (_with_row(2, "0.01,4,5"), "line 4: 3 value(s) but the header has 2"),
    "trailing comma on rows": (
        "\n".join(["t,adc", *[r + "," for r in _rows()]]),
        "line 2: 3 value(s) but the header has 2 column(s) ['t', 'adc'] (a trailing",
    ),
    "trailing comma everywhere": (
        "\n".join(["t,adc,", *[r + "," for r in _rows()]]),
        "line 1: column 3 has no name",
    ),
    "duplicate column": (
        "\n".join(["t,code,code", *[r + ",0" for r in _rows()]]),
        "column name(s) ['code'] appear more than once",
    ),
    "only a time column": ("\n".join(["t", *map(str, T)]), "no signal column"),
    "header only": ("t,adc\n", "no data rows"),
    "latin-1": (b"# units: \xb5V\nt,adc\n0,1\n", "line 1: not UTF-8 text (byte 0xb5)"),
}


@pytest.mark.parametrize("case", BAD_CSV)
def test_bad_csv_is_refused_with_file_line_and_column(tmp_path, case):
    text, message = BAD_CSV[case]
    path = _write(tmp_path / "x.csv", text)
    with pytest.raises(wi.RecordingError) as info:
        wi.read_recording(path)
    assert str(info.value).startswith(str(path)) and message in str(info.value)


TORN_TAILS = {
    # What follows the 12 complete rows, without a newline; the rows read back.
    "short row": ("0.06", 12),
    "row cut after the delimiter": ("0.06,", 12),
    "row cut mid-exponent": ("0.06,1e", 12),
    "complete row (a hand-edited file)": ("0.06,29", 13),
}


@pytest.mark.parametrize("case", TORN_TAILS)
def test_a_torn_last_row_is_dropped_with_a_warning_a_complete_one_kept(tmp_path, case):
    tail, rows = TORN_TAILS[case]
    path = _write(tmp_path / "r.csv", "\n".join(["t,adc", *_rows(), tail]))
    if rows == 12:
        with pytest.warns(TornRecordingWarning, match=r"r\.csv line 14: dropped the torn last"):
            rec = wi.read_recording(path)
    else:
        rec = wi.read_recording(path)  # no warning: filterwarnings = error
    assert rec.t.size == rows
    np.testing.assert_array_equal(rec.signal()[:12], X)


def test_a_recording_without_signal_columns_has_no_signal():
    rec = wi.Recording(t=T, columns={}, source="r.csv")
    with pytest.raises(wi.RecordingError, match=r"r\.csv: no signal column"):
        rec.signal()


def test_a_cli_reports_a_bad_cell_on_one_line(tmp_path, capsys):
    base = _write(tmp_path / "base.csv", BAD_CSV["empty cell"][0])
    out = tmp_path / "o.csv"
    argv = ["simulate", "--excitation", "base", "--base", str(base), "--out", str(out)]
    _refused(capsys, argv, f"{base} line 5, column 'adc'")
    assert not out.exists()


# --------------------------------------------------------------------------- NumPy files
def _numpy_files(tmp_path) -> dict:
    good_npy = tmp_path / "good.npy"
    np.save(good_npy, np.vstack([T, X]))
    good_npz = tmp_path / "good.npz"
    np.savez(good_npz, t=T, adc=X)
    objects = tmp_path / "objects.npy"
    np.save(objects, np.array([{"t": 1}, None], dtype=object), allow_pickle=True)
    return {
        "not a zip": _write(tmp_path / "corrupt.npz", b"PK\x03\x04garbage"),
        "truncated npz": _write(tmp_path / "trunc.npz", good_npz.read_bytes()[:200]),
        "truncated npy": _write(tmp_path / "trunc.npy", good_npy.read_bytes()[:150]),
        "text named npy": _write(tmp_path / "text.npy", b"hello world"),
        "pickled objects": objects,
    }


@pytest.mark.parametrize(
    "case", ["not a zip", "truncated npz", "truncated npy", "text named npy", "pickled objects"]
)
def test_corrupt_numpy_files_are_refused_without_pickle_advice(tmp_path, capsys, case):
    path = _numpy_files(tmp_path)[case]
    with pytest.raises(wi.RecordingError) as info:
        wi.read_recording(path)
    message = str(info.value)
    assert message.startswith(f"{path}: not a valid NumPy") and "pickle=" not in message
    out = tmp_path / "o.csv"
    argv = ["simulate", "--excitation", "base", "--base", str(path), "--out", str(out)]
    _refused(capsys, argv, str(path), "not a valid NumPy")


def test_npz_signal_of_the_wrong_length_is_named(tmp_path):
    np.savez(tmp_path / "r.npz", t=T, adc=X[:-2])
    with pytest.raises(wi.RecordingError, match="array 'adc' has shape \\(10,\\)"):
        wi.read_recording(tmp_path / "r.npz")


# --------------------------------------------------------------------------- JSON
def test_json_safe_replaces_every_non_finite_float_by_null():
    value = {
        "a": math.nan,
        "b": [1.5, np.float64(np.inf), {"c": np.float32(-np.inf)}],
        "d": (np.int64(3), np.bool_(True)),
        "e": np.array([0.5, np.nan]),
    }
    text = json.dumps(json_safe(value), allow_nan=False)
    assert json.loads(text) == {
        "a": None,
        "b": [1.5, None, {"c": None}],
        "d": [3, True],
        "e": [0.5, None],
    }


def test_cli_json_is_standard_json(tmp_path, capsys, monkeypatch):
    import whiskerid.cli._simulate as command

    monkeypatch.setattr(command, "run", lambda args: {"x": np.float64(np.nan), "y": [-np.inf]})
    assert main(["simulate", "--out", str(tmp_path / "s.csv"), "--json"]) == 0

    def strict(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    out = json.loads(capsys.readouterr().out, parse_constant=strict)
    assert out["x"] is None and out["y"] == [None]


# --------------------------------------------------------------------------- overwrites
@pytest.fixture
def files(tmp_path):
    """A recording, a whisker record and a static test, with their bytes."""
    rec = wi.write_csv(tmp_path / "rec.csv", wi.Recording(t=T, columns={"deflection": X * 1e-6}))
    whisker = wi.paper_record().save(tmp_path / "w.toml")
    static = _write(tmp_path / "static.csv", "force_n,deflection_m\n0,0\n0.01,0.001\n")
    return {p: p.read_bytes() for p in (rec, whisker, static)}


def _unchanged(files) -> bool:
    return all(p.read_bytes() == b for p, b in files.items())


@pytest.mark.parametrize("victim", ["rec.csv", "w.toml", "static.csv"])
def test_calibrate_refuses_to_write_over_an_input(tmp_path, capsys, files, victim):
    argv = ["calibrate", str(tmp_path / "rec.csv"), "--whisker", str(tmp_path / "w.toml"),
            "--static", str(tmp_path / "static.csv")]  # fmt: skip
    _refused(capsys, [*argv, "--out", str(tmp_path / victim)], "--out", "is also the input")
    _refused(capsys, [*argv, "--out", str(tmp_path / "o.toml"), "--plot", str(tmp_path / victim)],
             "--plot", "is also the input")  # fmt: skip
    assert _unchanged(files) and not (tmp_path / "o.toml").exists()


def test_simulate_refuses_to_write_over_its_base_motion(tmp_path, capsys, files):
    base = tmp_path / "rec.csv"
    argv = ["simulate", "--excitation", "base", "--base", str(base), "--duration", "0.05"]
    _refused(capsys, [*argv, "--out", str(base)], "--out", "is also the input --base")
    whisker = str(tmp_path / "w.toml")
    _refused(capsys, [*argv, "--whisker", whisker, "--out", whisker], "is also the input --whisker")
    link = tmp_path / "link.csv"
    link.symlink_to(base)
    _refused(capsys, [*argv, "--out", str(link)], "is also the input --base")
    assert _unchanged(files)


def test_posterior_refuses_an_input_among_its_outputs(tmp_path, capsys, files):
    out = tmp_path / "post"
    out.mkdir()
    fit = wi.paper_record().save(out / "posterior.toml")
    before = fit.read_bytes()
    _refused(capsys, ["posterior", str(tmp_path / "rec.csv"), "--fit", str(fit), "--out", str(out)],
             "would be overwritten")  # fmt: skip
    assert fit.read_bytes() == before and not (out / "chain.h5").exists()


# --------------------------------------------------------------------------- dataset synth
def test_speed_tags_keep_the_default_names_and_never_collide():
    assert [speed_tag(v) for v in wi.SPEEDS_MPS] == ["0.10", "0.15", "0.20", "0.25", "0.30"]
    assert speed_tag(0.201) != speed_tag(0.204)
    assert (
        dataset_paths("d", [RunSpec("sand", 0.2, 3)])[0].as_posix() == "d/sand/sand_v0.20_r03.csv"
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--terrains", "flat", "flat"], "flat given more than once"),
        (["--speeds", "0.2001", "0.2004"], "same to 1 mm/s"),
        (["--speeds", "nan"], "not a number"),
        (["--duration", "nan"], "from 2 to 3600 s"),
        (["--duration", "0.5"], "at least 2 s"),
    ],
)
def test_dataset_synth_refuses_collisions_and_silly_durations(tmp_path, capsys, args, message):
    out = tmp_path / "ds"
    _refused(capsys, ["dataset", "synth", "--out", str(out), "--runs", "1", *args], message)
    assert not out.exists()


def test_dataset_synth_refuses_a_folder_holding_recordings(tmp_path, capsys):
    old = _write(tmp_path / "ds" / "mine" / "old.csv", "t,adc\n0,1\n")
    _refused(capsys, ["dataset", "synth", "--out", str(tmp_path / "ds"), "--duration", "2"],
             "already holds 1 recording(s)", "new or empty folder")  # fmt: skip
    assert old.read_text() == "t,adc\n0,1\n" and sorted((tmp_path / "ds").iterdir()) == [old.parent]
    _refused(capsys, ["dataset", "synth", "--out", str(old)], "is a file")


def test_demo_style_rerun_replaces_only_the_simulators_own_files(tmp_path):
    kwargs = {"terrains": ("flat",), "speeds": (0.2,), "runs": 1, "duration_s": 2.0}
    first = synthesize_dataset(tmp_path, **kwargs)
    with pytest.raises(ValueError, match="already holds"):
        synthesize_dataset(tmp_path, **kwargs)
    again = synthesize_dataset(tmp_path, **kwargs, replace_synthetic=True)
    assert again == first and len(list(tmp_path.rglob("*.csv"))) == 1
    _write(tmp_path / "flat" / "mine.csv", "t,adc\n0,1\n")
    with pytest.raises(ValueError, match="already holds 1"):
        synthesize_dataset(tmp_path, **kwargs, replace_synthetic=True)


# --------------------------------------------------------------------------- numbers
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--noise-db", "nan"], "noise_db = nan"),
        (["--noise-db", "inf"], "noise_db = inf"),
        (["--duration", "1e9"], "more than the limit"),
        (["--duration", "nan"], "duration_s = nan"),
        (["--tip-deflection", "nan", "--excitation", "decay"], "tip_deflection_m"),
        (["--jitter", "-1"], "jitter_s"),
        (["--jitter", "nan"], "jitter_s"),
    ],
)
def test_simulate_refuses_non_finite_and_absurd_numbers(tmp_path, capsys, argv, message):
    out = tmp_path / "o.csv"
    _refused(capsys, ["simulate", *argv, "--out", str(out)], message)
    assert not out.exists()


@pytest.mark.parametrize(
    ("t", "duration", "message"),
    [
        (np.arange(0, 1, 1e-3), "2", "covers t = 0 .. 0.999 s but the simulation needs 0 .. 2 s"),
        (np.arange(0.5, 3, 1e-3), "2", "starts at t = 0.5 s"),
        (np.arange(5, 2000, 5.0), "1", "sampled every 5 s"),  # time in ms
        (np.arange(0, 2000, 5.0), "1", "is its time column in seconds"),  # ms from 0
    ],
)
def test_simulate_refuses_a_base_motion_not_covering_the_run(
    tmp_path, capsys, t, duration, message
):
    base = wi.write_csv(tmp_path / "b.csv", wi.Recording(t=t, columns={"acc": np.sin(t)}))
    out = tmp_path / "o.csv"
    argv = ["simulate", "--excitation", "base", "--base", str(base), "--duration", duration]
    _refused(capsys, [*argv, "--out", str(out)], message)
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scale", "nan"], "--scale nan"),
        (["--scale", "0"], "--scale 0"),
        (["--fb", "inf"], "--fb inf"),
        (["--hb", "-1"], "--hb -1"),
        (["--t-start", "nan"], "--t-start nan"),
        (["--sensor-x", "inf"], "--sensor-x inf"),
        (["--t-start", "2", "--t-end", "1"], "must be later"),
    ],
)
def test_calibrate_and_posterior_refuse_bad_numbers(tmp_path, capsys, files, argv, message):
    rec, whisker = str(tmp_path / "rec.csv"), str(tmp_path / "w.toml")
    out = tmp_path / "o"
    _refused(capsys, ["calibrate", rec, "--whisker", whisker, "--out", str(out), *argv], message)
    _refused(capsys, ["posterior", rec, "--fit", whisker, "--out", str(out), *argv], message)
    assert not out.exists()


def test_posterior_refuses_a_non_finite_nu(tmp_path, capsys, files):
    argv = ["posterior", str(tmp_path / "rec.csv"), "--fit", str(tmp_path / "w.toml")]
    _refused(capsys, [*argv, "--out", str(tmp_path / "p"), "--nu", "nan"], "--nu nan")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--duration", "inf"], "--duration inf"),
        (["--speed", "0"], "needs a moving robot"),
        (["--rate", "nan"], "--rate nan"),
        (["--hop", "nan"], "--hop nan"),
        (["--speed", "-0.2"], "--speed -0.2"),
        (["--speed", "50"], "not plausible"),
    ],
)
def test_stream_refuses_bad_numbers(tmp_path, capsys, argv, message):
    model = tmp_path / "no-model"
    _refused(capsys, ["stream", "--model", str(model), "--simulate", "brick", *argv], message)


# --------------------------------------------------------------------------- poor fits
def test_poor_fit_warning_names_the_recording_below_3_db():
    per_rec = [{"name": "good.csv", "snr_db": 18.1}, {"name": "ms.csv", "snr_db": 0.015}]
    (warning,) = poor_fit_warnings(per_rec)
    assert "ms.csv" in warning and "time units" in warning
    assert poor_fit_warnings([{"name": "x", "snr_db": math.nan}])


def test_calibrating_a_recording_timed_in_ms_is_refused(tmp_path, capsys):
    """With rate_hz metadata the timestamps contradict it; without, the sampling is far
    too slow for the whisker's first mode. Either way nothing is fitted or written."""
    t_s = np.arange(600) / 200.0  # 3 s at 200 Hz of a decaying 30 Hz deflection, with noise
    rng = np.random.default_rng(1)
    w = 1e-5 * np.exp(-2.0 * t_s) * np.cos(2 * np.pi * 30.0 * t_s) + 3e-7 * rng.normal(size=600)
    sim = wi.Recording(t=t_s * 1000.0, columns={"deflection": w},  # ms where s are expected
                       meta={"rate_hz": "200", "units": "m"})  # fmt: skip
    whisker = wi.paper_record().save(tmp_path / "w.toml")
    out = tmp_path / "cal.toml"
    assert "rate_hz" in sim.meta
    for name, message in (("meta.csv", "the time column must be in seconds"),
                          ("bare.csv", "far too slowly for the whisker's first mode")):  # fmt: skip
        rec = wi.write_csv(tmp_path / name, sim)
        _refused(capsys, ["calibrate", str(rec), "--whisker", str(whisker), "--out", str(out)],
                 message)  # fmt: skip
        assert not out.exists()
        sim.meta.pop("rate_hz", None)


def test_observations_from_file_reads_checks_and_converts_as_the_command_does(tmp_path):
    """The library's one call from a file to observations: the same observations as reading
    and converting by hand, and a time column in ms refused before anything is fitted."""
    from whiskerid.fit import observations_from_file, observations_from_recording

    t = np.arange(600) / 200.0
    y = 1e-5 * np.exp(-2.0 * t) * np.cos(2 * np.pi * 30.0 * t)
    record = wi.paper_record()
    good = wi.write_csv(tmp_path / "s.csv", wi.Recording(t=t, columns={"deflection": y}))
    (a,) = observations_from_file(good, record, excitation="decay", t_start=0.0)
    (b,) = observations_from_recording(wi.read_recording(good), record, excitation="decay",
                                       t_start=0.0)  # fmt: skip
    np.testing.assert_array_equal(a.y, b.y)
    assert a.t[0] == b.t[0] == 0.0 and a.excitation == "decay"
    ms = wi.write_csv(tmp_path / "ms.csv", wi.Recording(t=t * 1000.0, columns={"deflection": y}))
    with pytest.raises(wi.RecordingError, match="is the time column in seconds"):
        observations_from_file(ms, record)
