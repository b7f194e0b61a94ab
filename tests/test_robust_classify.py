"""Real recordings as users bring them to train, evaluate and classify: wrong time units,
mixed or low rates, gaps, several columns, untidy dataset folders, flat-lined sensors.
Each is refused with a message that says what to do, or handled correctly."""

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.classify import FeatureSpec, TrainConfig, compute_features, confusion_matrix, scores
from whiskerid.classify._dataset import (
    check_speed,
    load_dataset,
    recording_signal,
    recording_speed,
    windows_of,
)


def _rec(path, *, rate=200.0, seconds=4.0, f=20.0, scale=1.0, meta=None, columns=("adc",)):
    """A tone recording at ``rate`` written as CSV; ``scale`` multiplies the time column
    (1000: milliseconds)."""
    t = np.arange(round(seconds * rate)) / rate
    cols = {c: np.sin(2 * np.pi * (f + 7 * i) * t) for i, c in enumerate(columns)}
    wi.write_csv(path, wi.Recording(t=t * scale, columns=cols, meta=dict(meta or {})))
    return path


def _dataset(root, specs):
    """``{label: [kwargs of _rec, ...]}`` written as ROOT/<label>/r<i>.csv."""
    for label, recs in specs.items():
        for i, kw in enumerate(recs):
            _rec(root / label / f"r{i}.csv", **kw)
    return root


def test_time_in_milliseconds_is_refused_with_a_hint(tmp_path):
    _dataset(tmp_path / "a", {"x": [{"scale": 1000.0, "meta": {"rate_hz": 200}}], "y": [{}]})
    with pytest.raises(wi.RecordingError, match="time column must be in seconds"):
        load_dataset(tmp_path / "a")
    _dataset(tmp_path / "b", {"x": [{"scale": 1000.0}], "y": [{"scale": 1000.0}]})
    with pytest.raises(ValueError, match=r"holds 0 samples at 0\.2 Hz.*in seconds"):
        load_dataset(tmp_path / "b")  # 0.2 Hz from the steps: no 1 s window fits


def test_mixed_rates_need_a_common_rate_and_no_recording_below_it(tmp_path):
    root = _dataset(tmp_path / "d", {"x": [{"rate": 400.0}], "y": [{"rate": 200.0}]})
    with pytest.raises(wi.RecordingError, match=r"200 Hz \(r0.csv\) to 400 Hz.*pass --rate"):
        load_dataset(root)
    ws = load_dataset(root, rate_hz=200.0)
    assert ws.rate_hz == 200.0 and ws.windows.shape == (8, 200)
    with pytest.raises(wi.RecordingError, match="sampled at 200 Hz, below the 400 Hz"):
        load_dataset(root, rate_hz=400.0)


def test_downsampling_removes_what_would_alias():
    """A 180 Hz tone recorded at 1 kHz is above the Nyquist frequency of 200 Hz windows:
    plain interpolation folds it to 20 Hz at nearly full amplitude; it must be filtered
    out. A 30 Hz tone passes unchanged."""
    t = np.arange(5000) / 1000.0
    high, _ = windows_of(t, np.sin(2 * np.pi * 180 * t), rate_hz=200.0, window=200, hop=200)
    low, _ = windows_of(t, np.sin(2 * np.pi * 30 * t), rate_hz=200.0, window=200, hop=200)
    naive = np.interp(np.arange(1000) / 200.0, t, np.sin(2 * np.pi * 180 * t))
    assert np.std(naive) > 0.5  # what the filter is there to prevent
    assert np.std(high[1:-1]) < 0.02
    assert abs(np.std(low[1:-1]) - np.sqrt(0.5)) < 0.01


def test_windows_never_span_a_gap():
    t = np.concatenate([np.arange(2000), 22000 + np.arange(2000)]) / 200.0  # 100 s hole
    w, starts = windows_of(t, np.sin(t), rate_hz=200.0, window=200, hop=200)
    assert len(w) == 20
    assert not ((starts > 9.5) & (starts < 110.0)).any() and starts.max() == pytest.approx(119.0)


def test_channels_are_named_and_kept(tmp_path):
    root = _dataset(tmp_path / "d", {"x": [{"columns": ("ax", "az")}],
                                     "y": [{"columns": ("az", "ax")}]})  # fmt: skip
    with pytest.raises(wi.RecordingError, match=r"'ax' in r0.csv, 'az' in r0.csv.*--channel"):
        load_dataset(root)
    assert load_dataset(root, channel="az").channel == "az"
    root = _dataset(tmp_path / "e", {"x": [{"columns": ("az", "ax")}] * 2,
                                     "y": [{"columns": ("az", "ax"), "f": 60.0}] * 2})  # fmt: skip
    ws = load_dataset(root)
    assert ws.channel == "az"
    model = wi.train_classifier(ws, features="paper",
                                config=TrainConfig(hidden=(8,), max_epochs=20))  # fmt: skip
    assert model.channel == "az"
    other = wi.read_recording(_rec(tmp_path / "other.csv", columns=("ax", "ay")))
    with pytest.raises(wi.RecordingError, match="no column 'az', the one the model"):
        model.classify_recording(other)
    np.save(tmp_path / "one.npy", np.stack([np.arange(800) / 200.0, np.sin(np.arange(800))]))
    res = model.classify_recording(wi.read_recording(tmp_path / "one.npy"))  # one column
    assert res["channel"] == "signal" and len(res["windows"]) == 4
    slow = wi.read_recording(_rec(tmp_path / "slow.csv", rate=50.0, columns=("az",)))
    with pytest.raises(wi.RecordingError, match="sampled at 50 Hz, below the 200 Hz"):
        model.classify_recording(slow)


def test_untidy_dataset_folders(tmp_path):
    root = _dataset(tmp_path / "d", {"x": [{}], "y": [{"f": 60.0}]})
    (root / ".ipynb_checkpoints").mkdir()
    _rec(root / ".ipynb_checkpoints" / "r0.csv")
    (root / "x" / "._r0.csv").write_bytes(b"\x00\x05\x16\x07 Mac OS X")
    ws = load_dataset(root)
    assert ws.label_names == ("x", "y") and len(ws.sources) == 2
    (root / "z").mkdir()
    with pytest.raises(wi.RecordingError, match=r"\['z'\] hold no recordings"):
        load_dataset(root)
    one = _dataset(tmp_path / "one", {"x": [{}, {}]})
    with pytest.raises(ValueError, match="at least two terrains"):
        wi.train_classifier(load_dataset(one))
    short = _dataset(tmp_path / "s", {"x": [{}], "y": [{"seconds": 0.5}]})
    with pytest.raises(wi.RecordingError, match=r"no windows of \['y'\]"):
        load_dataset(short, labels=("x", "y"))  # evaluating as much as training
    ws = load_dataset(_dataset(tmp_path / "t", {"x": [{}], "y": [{"f": 60.0}]}))
    with pytest.raises(ValueError, match=r"no windows of \['y'\]"):
        wi.train_classifier(ws.subset(ws.labels == 0))


def test_a_constant_signal_is_refused(tmp_path):
    t = np.arange(800) / 200.0
    wi.write_csv(tmp_path / "flat.csv", wi.Recording(t=t, columns={"adc": np.full(800, 13200)}))
    with pytest.raises(wi.RecordingError, match=r"'adc' is constant.*disconnected or saturated"):
        recording_signal(wi.read_recording(tmp_path / "flat.csv"), None)


def test_flat_lined_sensor_gives_finite_features():
    spec = FeatureSpec(kind="fitted", rate_hz=200.0, window=200, use_speed=True,
                       octave_bands=True, spatial_lo=1.0, spatial_hi=300.0)  # fmt: skip
    f = np.asarray(compute_features(spec, np.full((2, 200), 512.0), np.full(2, 0.2)))
    assert np.isfinite(f).all()


def test_speeds_must_be_positive_numbers():
    with pytest.raises(wi.RecordingError, match="speed_mps 'fast' is not a positive"):
        recording_speed(wi.Recording(t=np.arange(3.0), columns={}, meta={"speed_mps": "fast"}))
    assert np.isnan(recording_speed(wi.Recording(t=np.arange(3.0), columns={})))
    for bad in (0.0, -0.2, np.nan, np.inf):
        with pytest.raises(ValueError, match="must be a positive number"):
            check_speed(bad)
    check_speed([0.1, 0.3])


def test_classes_without_windows_score_none_not_zero():
    res = scores(confusion_matrix([0, 0, 1], [0, 1, 1], 3), ["a", "b", "c"])
    assert res["per_class"] == {"a": 0.5, "b": 1.0, "c": None}


def test_huge_or_non_finite_weights_are_refused_naming_the_file(tmp_path):
    """Weights scaled by 3e37 are finite but overflow every logit (confidence NaN): the
    model file is refused on loading, naming the weights file."""
    ws = _toy_windows(tmp_path)
    model = wi.train_classifier(ws, features="paper",
                                config=TrainConfig(hidden=(8,), max_epochs=10))  # fmt: skip
    path = model.save(tmp_path / "m")
    with np.load(path / "weights.npz") as z:
        arrays = {k: z[k] for k in z.files}
    for scale, match in ((3e37, "weights m0_W0 reach 3"), (np.inf, "non-finite")):
        np.savez(path / "weights.npz", **{k: a * scale for k, a in arrays.items()})
        with pytest.raises(wi.ModelError, match=f"weights.npz: .*{match}"):
            wi.ClassifierModel.load(path)


def test_a_1e308_cell_refuses_training_naming_the_recording(tmp_path, capsys):
    from whiskerid.cli import main

    root = _dataset(tmp_path / "d", {"x": [{}, {}], "y": [{"f": 50.0}, {"f": 50.0}]})
    bad = root / "y" / "r1.csv"
    lines = bad.read_text().splitlines()
    t = lines[-100].split(",")[0]
    lines[-100] = f"{t},1e308"
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "model"
    assert main(["train", str(root), "--out", str(out), "--features", "paper",
                 "--max-epochs", "5"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "r1.csv" in err and "1e308" in err and not out.exists()


def _toy_windows(tmp_path):
    root = _dataset(tmp_path / "toy", {"x": [{}, {}], "y": [{"f": 50.0}, {"f": 50.0}]})
    return load_dataset(root)
