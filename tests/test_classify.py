"""MLP, model files, evaluation and the classification CLI on a tiny dataset."""

import collections
import itertools
import json
import logging
import re
from dataclasses import replace

import jax
import numpy as np
import pytest

import whiskerid as wi
from whiskerid.classify import (
    TrainConfig,
    _mlp,
    confusion_matrix,
    default_spec,
    format_confusion,
    grouped_split,
    recording_folds,
)
from whiskerid.classify._mlp import train_mlp
from whiskerid.cli import main

FAST = TrainConfig(hidden=(32, 16), max_epochs=60, patience=20, batch_size=64)


def test_mlp_learns_a_separable_toy_problem():
    rng = np.random.default_rng(0)
    centres = rng.standard_normal((3, 4)) * 3
    y = rng.integers(0, 3, 600)
    x = centres[y] + rng.standard_normal((600, 4))
    res = train_mlp(x[:450], y[:450], x[450:], y[450:], 3, FAST)
    assert res.val_accuracy > 0.95
    res2 = train_mlp(x[:450], y[:450], x[450:], y[450:], 3, FAST)
    leaves = zip(jax.tree_util.tree_leaves(res.model), jax.tree_util.tree_leaves(res2.model),
                 strict=True)  # fmt: skip
    assert all(np.array_equal(a, b) for a, b in leaves)  # seeded: identical


def test_class_weights_change_nothing_when_balanced_and_lift_a_minority():
    """Inverse-frequency weights (the default for fitted): identical training on equal
    classes; with 9:1 overlapping classes the minority's recall rises (unweighted, the
    network leans to the class recorded longest)."""
    rng = np.random.default_rng(6)
    y = np.repeat([0, 1], 200)
    x = rng.standard_normal((400, 2)) + 1.5 * y[:, None]
    on, off = (train_mlp(x, y, x[:0], y[:0], 2, replace(FAST, balance=b), epochs=40)
               for b in (True, False))  # fmt: skip
    leaves = zip(jax.tree_util.tree_leaves(on.model), jax.tree_util.tree_leaves(off.model),
                 strict=True)  # fmt: skip
    assert all(np.array_equal(a, b) for a, b in leaves)
    y = np.repeat([0, 1], [900, 100])
    x = rng.standard_normal((1000, 1)) + 1.5 * y[:, None]
    recall = {}
    for b in (True, False):
        res = train_mlp(x, y, x[:0], y[:0], 2, replace(FAST, balance=b), epochs=60)
        pred = np.argmax(np.asarray(_mlp.predict_proba(res.model, x)), axis=1)
        recall[b] = np.mean(pred[y == 1] == 1)
    assert recall[True] > recall[False] + 0.2, recall
    assert TrainConfig().balance and not _mlp.PAPER_CONFIG.balance


def test_train_refuses_bad_settings_before_reading(tmp_path, capsys):
    """Each bad setting is named, and refused before the (here missing) dataset is read."""
    args = ["train", str(tmp_path / "none"), "--out", str(tmp_path / "m")]
    assert main([*args, "--weight-decay", "-1"]) == 2
    assert "--weight-decay must be a finite number at least 0" in capsys.readouterr().err
    assert main([*args, "--input-noise", "nan"]) == 2
    assert "--input-noise must be a finite number at least 0" in capsys.readouterr().err
    assert main([*args, "--cv", "1"]) == 2
    assert "--cv must be at least 2 folds" in capsys.readouterr().err
    assert main([*args, "--span-whiskers", "-1"]) == 2
    assert "--span-whiskers must be 0 or more, not -1" in capsys.readouterr().err
    assert main([*args, "--span-whiskers", "2"]) == 2
    assert "--span-whiskers goes with --whisker" in capsys.readouterr().err


def test_full_batch_and_fixed_epoch_refit():
    """The default full-batch training learns; ``epochs=`` trains exactly that long on
    everything (no validation rows) and keeps the final parameters."""
    rng = np.random.default_rng(4)
    centres = rng.standard_normal((3, 4)) * 3
    y = rng.integers(0, 3, 300)
    x = centres[y] + rng.standard_normal((300, 4))
    cfg = TrainConfig(max_epochs=400)
    res = train_mlp(x[:200], y[:200], x[200:], y[200:], 3, cfg)
    assert res.val_accuracy > 0.9 and res.best_epoch <= res.epochs <= 400
    refit = train_mlp(x, y, x[:0], y[:0], 3, cfg, epochs=45)
    assert refit.epochs == 60  # rounded up to whole chunks of 20
    pred = np.argmax(np.asarray(_mlp.predict_proba(refit.model, x)), axis=1)
    assert np.mean(pred == y) > 0.9


def _toy_windows(n_rec=8, per=10, tone=lambda r: 20.0 if r % 2 == 0 else 60.0):
    """Two classes (``r % 2``): by default a 20 Hz or a 60 Hz tone in noise; ``tone(r)``
    gives recording ``r``'s tone (Hz)."""
    rng = np.random.default_rng(1)
    t = np.arange(200) / 200.0
    wins, labels, recs = [], [], []
    for r in range(n_rec):
        f = tone(r)
        for _ in range(per):
            wins.append(np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) + rng.standard_normal(200))
            labels.append(r % 2)
            recs.append(r)
    n = len(labels)
    return wi.WindowSet(np.array(wins), np.array(labels), ("low", "high"), np.array(recs),
                        np.full(n, np.nan), [f"r{i}" for i in range(n_rec)], 200.0)  # fmt: skip


def test_split_by_recording_keeps_recordings_whole():
    ws = _toy_windows()
    train, test = wi.split_by_recording(ws, 0.25, seed=0)
    assert not set(train.recording) & set(test.recording)
    assert set(test.labels) == {0, 1} and len(train) + len(test) == len(ws)
    assert grouped_split(ws, 0.25, 0).sum() == len(test)


def test_recording_folds_deal_whole_recordings_stratified():
    ws = _toy_windows(n_rec=12)
    fold = recording_folds(ws, 3, seed=1)
    for r in range(12):  # a recording lies in one fold
        assert np.unique(fold[ws.recording == r]).size == 1
    for k in range(3):  # each fold: two recordings of each class
        in_k = np.unique(ws.recording[fold == k])
        assert np.bincount(np.asarray(in_k) % 2, minlength=2).tolist() == [2, 2]
    loro = recording_folds(ws, 12, seed=0)
    assert sorted(np.unique(ws.recording[loro == k]).size for k in range(12)) == [1] * 12
    for bad in (1, 13):
        with pytest.raises(ValueError, match="pass 2 to 12"):
            recording_folds(ws, bad)


def test_cross_validation_scores_every_recording_once_and_compiles_once():
    """Folds share compiled functions, and so do other numeric training settings."""
    ws, cfg = _toy_windows(n_rec=8), replace(FAST, max_epochs=100)
    cv = wi.cross_validate(ws, folds=4, config=cfg)
    assert cv["accuracy"] > 0.9 and cv["context_s"] == 3.0 and cv["n_windows"] == 80
    assert cv["n_recordings"] == 8 and cv["accuracy_per_recording"] >= 7 / 8
    assert len(cv["per_recording"]) == 8 and len(cv["accuracy_by_fold"]) == 4
    with _Compiles() as compiled:  # other folds, step size and regularisation
        other = replace(cfg, learning_rate=1e-2, weight_decay=0.1, input_noise=0.1, seed=5)
        wi.cross_validate(ws, folds=4, seed=3, config=other)
    assert not {"_run_chunk", "_predict_proba", "_batch_features"} & set(compiled), compiled


@pytest.mark.slow
def test_cross_validation_tests_recordings_a_model_never_saw():
    """Each recording has its own tone (15 + 5 r Hz) and the labels alternate, so a
    network can learn every recording's tone but a new recording's neighbours in frequency
    both carry the other label. Random windows (the paper's protocol) reward the
    memorising; cross-validation by recording must not."""
    ws = _toy_windows(n_rec=8, per=12, tone=lambda r: 15.0 + 5.0 * r)
    cfg = replace(FAST, hidden=(64,), max_epochs=300, patience=300, weight_decay=1e-4,
                  input_noise=0.0)  # fmt: skip
    cv = wi.cross_validate(ws, folds=4, config=cfg, context_s=1.0)
    pp = wi.paper_protocol(ws, features="fitted", repeats=2, config=cfg)
    assert pp["accuracy_mean"] > 0.65  # measured 0.77 (chance 0.5)
    assert cv["accuracy"] < 0.4 and cv["n_windows"] == len(ws)  # measured 0.28
    assert len(cv["per_recording"]) == 8 and len(cv["accuracy_by_fold"]) == 4
    honest = wi.cross_validate(_toy_windows(n_rec=8), folds=4, config=cfg)
    assert honest["accuracy"] > 0.9 and honest["context_s"] == 3.0
    assert honest["n_recordings"] == 8 and honest["accuracy_per_recording"] >= 7 / 8
    assert cv["accuracy_per_recording"] <= 0.5


def test_recording_scores_label_a_recording_by_its_mean_probability():
    """Recording ``b`` (class 1) has two of three windows right, but the mean probability
    leans to class 0: wrong, as ``classify`` would label it (a majority vote would not)."""
    ws = replace(_toy_windows(n_rec=2, per=3), sources=["dir/a.csv", "dir/b.csv"])
    ws = ws.subset(np.arange(1, 6))  # a: 2 windows, b: 3
    p = np.array([[0.9, 0.1], [0.2, 0.8], [0.8, 0.2], [0.4, 0.6], [0.4, 0.6]])
    res = wi.recording_scores(p, ws.labels, ws)
    assert res["accuracy_per_recording"] == 0.5 and res["n_recordings"] == 2
    assert res["wrong_recordings"] == [
        {
            "recording": "high/b.csv",
            "predicted": "low",
            "confidence": pytest.approx(0.5333, abs=1e-4),
        }
    ]


def _tone_csvs(root, runs: int, seed: int = 2) -> None:
    """``root/low`` and ``root/high``: ``runs`` CSV recordings each, 6 s at 200 Hz of a 20
    or a 60 Hz tone in noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(1200) / 200.0
    for label, f in (("low", 20.0), ("high", 60.0)):
        for r in range(runs):
            x = np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) + rng.standard_normal(t.size)
            wi.write_csv(root / label / f"{label}{r}.csv",
                         wi.Recording(t=t, columns={"hall": x}, meta={"rate_hz": 200}))  # fmt: skip


@pytest.fixture(scope="module")
def tone_model(tmp_path_factory):
    """A model trained by ``whiskerid train`` on :func:`_tone_csvs` (3 runs of each tone),
    and its dataset: ``(dataset folder, model folder)``. Tests read both, never write them."""
    root = tmp_path_factory.mktemp("tones")
    _tone_csvs(root / "ds", runs=3)
    model = root / "m"
    assert main(["train", str(root / "ds"), "--out", str(model), "--hidden", "8",
                 "--max-epochs", "40"]) == 0  # fmt: skip
    return root / "ds", model


def test_cli_evaluate_names_the_recordings_labelled_wrong(tone_model, tmp_path, capsys):
    """A 60 Hz recording filed under ``low`` is the one recording labelled wrong whole."""
    _, model = tone_model
    _tone_csvs(tmp_path / "test", runs=2, seed=5)
    (tmp_path / "test" / "high" / "high1.csv").rename(tmp_path / "test" / "low" / "misfiled.csv")
    capsys.readouterr()
    assert main(["evaluate", str(model), str(tmp_path / "test"), "--json"]) == 0
    captured = capsys.readouterr()
    res = json.loads(captured.out)
    assert res["n_recordings"] == 4 and res["accuracy_per_recording"] == 0.75
    assert [(w["recording"], w["predicted"]) for w in res["wrong_recordings"]] == [
        ("low/misfiled.csv", "high")
    ]
    assert "labelled wrong whole: low/misfiled.csv as high" in captured.err


def test_cli_classify_plot(tone_model, tmp_path, capsys):
    """``classify --plot`` saves the signal and its labels over time, under exactly the
    name given; a --plot naming an input is refused before anything is written."""
    ds, model = tone_model
    rec, png = ds / "high" / "high0.csv", tmp_path / "plots" / "high0.png"
    capsys.readouterr()
    assert main(["classify", str(model), str(rec), "--plot", str(png), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["plot"] == str(png) and png.stat().st_size > 10_000
    before = rec.read_bytes()
    assert main(["classify", str(model), str(rec), "--plot", str(rec)]) == 2
    assert "is also the input REC" in capsys.readouterr().err and rec.read_bytes() == before
    bare = tmp_path / "labels"  # no suffix: written under exactly that name, as PNG
    assert main(["classify", str(model), str(rec), "--plot", str(bare)]) == 0
    assert bare.read_bytes()[:4] == b"\x89PNG" and not bare.with_suffix(".png").exists()
    assert main(["evaluate", str(model), str(ds), "--plot", str(model)]) == 2
    assert "is also the input MODEL" in capsys.readouterr().err


def test_absolute_octave_levels_only_with_the_speed():
    """Without the speed a level says how fast a run went as much as what the ground is."""
    ws = _toy_windows()
    assert not default_spec(ws).octave_bands and not default_spec(ws).use_speed
    spec = default_spec(replace(ws, speeds=np.full(len(ws), 0.2)))
    assert spec.octave_bands and spec.use_speed
    n_oct = len(spec.octave_edges()) - 1
    assert spec.n_features == replace(spec, octave_bands=False).n_features + n_oct


def test_train_save_load_round_trip_and_refusals(tmp_path):
    ws = _toy_windows()
    model = wi.train_classifier(ws, config=replace(FAST, ensemble=2))
    assert len(model.nets) == 2
    res = wi.evaluate_classifier(model, ws)
    assert res["accuracy"] > 0.9 and set(res["per_class"]) == {"low", "high"}
    path = model.save(tmp_path / "m")
    loaded = wi.ClassifierModel.load(path)
    np.testing.assert_allclose(loaded.predict_proba(ws.windows), model.predict_proba(ws.windows),
                               rtol=1e-5, atol=1e-6)  # fmt: skip
    label, conf = loaded.predict_window(ws.windows[0])
    assert label in ("low", "high") and 0.5 <= conf <= 1.0
    p = model.predict_proba(ws.windows[:1])[0]  # the single-window path agrees with the batch
    assert label == model.labels[int(np.argmax(p))] and abs(conf - p.max()) < 1e-5
    with pytest.raises(ValueError, match="200 samples"):
        loaded.predict_window(ws.windows[0][:100])
    head = json.loads((path / "model.json").read_text())
    assert head["labels"] == ["low", "high"] and head["window"] == 200
    assert head["network"]["members"] == 2 and len(loaded.nets) == 2

    (path / "model.json").write_text(json.dumps({**head, "format": "whiskerid.classifier/1"}))
    with pytest.raises(wi.ModelError, match="retrain"):  # older feature set
        wi.ClassifierModel.load(path)
    (path / "model.json").write_text(json.dumps({**head, "format": "whiskerid.classifier/99"}))
    with pytest.raises(wi.ModelError, match="incompatible"):
        wi.ClassifierModel.load(path)
    (path / "model.json").write_text("{not json")
    with pytest.raises(wi.ModelError, match="corrupt"):
        wi.ClassifierModel.load(path)
    (path / "model.json").write_text(json.dumps(head))
    (path / "weights.npz").write_bytes(b"garbage")
    with pytest.raises(wi.ModelError, match="corrupt model weights"):
        wi.ClassifierModel.load(path)
    np.savez(path / "weights.npz", W0=np.zeros((3, 3)))
    with pytest.raises(wi.ModelError):
        wi.ClassifierModel.load(path)


def _fused_by_loop(proba, recording, start_s, lookback_s):
    """fuse_context written out window by window (the reference)."""
    out = np.empty_like(proba)
    for i in range(len(proba)):
        near = ((recording == recording[i]) & (start_s <= start_s[i])
                & (start_s >= start_s[i] - lookback_s - 1e-9))  # fmt: skip
        m = np.mean(np.log(proba[near]), axis=0)
        out[i] = np.exp(m) / np.exp(m).sum()
    return out


def test_fuse_context_uses_the_past_of_the_same_recording_only():
    rng = np.random.default_rng(3)
    n = 40
    proba = rng.dirichlet(np.ones(4), n)
    recording = rng.integers(0, 3, n)  # interleaved recordings
    start_s = rng.permutation(n) * 0.5  # out of order, hop 0.5 s
    for lookback in (0.0, 0.5, 2.0, 100.0):
        got = wi.fuse_context(proba, recording, start_s, lookback_s=lookback)
        np.testing.assert_allclose(got, _fused_by_loop(proba, recording, start_s, lookback),
                                   rtol=1e-12)  # fmt: skip
    np.testing.assert_array_equal(wi.fuse_context(proba, recording, start_s, lookback_s=0), proba)
    # A window's label never depends on a later window or on another recording.
    later = proba.copy()
    last = np.argmax(np.where(recording == 0, start_s, -1))
    later[last] = [0.97, 0.01, 0.01, 0.01]
    later[recording == 1] = [0.01, 0.01, 0.01, 0.97]
    a = wi.fuse_context(proba, recording, start_s, lookback_s=2.0)
    b = wi.fuse_context(later, recording, start_s, lookback_s=2.0)
    same = (recording == 2) | ((recording == 0) & (np.arange(n) != last))
    np.testing.assert_allclose(a[same], b[same], rtol=1e-12)
    with pytest.raises(ValueError, match="lookback_s"):
        wi.fuse_context(proba, recording, start_s, lookback_s=-1)


def test_context_lifts_ambiguous_windows_and_round_trips(tmp_path):
    """Windows that are each barely informative (a weak tone in noise): fusing three per
    label beats one per label, on recordings the model has not seen; the context is saved
    in the model file, and a file without it (older) labels every window on its own."""
    rng = np.random.default_rng(5)
    t = np.arange(200) / 200.0

    def windows(n_rec, per, seed):
        g = np.random.default_rng(seed)
        w, y, r = [], [], []
        for k in range(n_rec):
            f = 20.0 if k % 2 == 0 else 60.0
            for _ in range(per):
                tone = 0.25 * np.sin(2 * np.pi * f * t + g.uniform(0, 6))
                w.append(tone + g.standard_normal(200))
                y.append(k % 2)
                r.append(k)
        names = [f"r{i}" for i in range(n_rec)]
        return wi.WindowSet(np.array(w), np.array(y), ("low", "high"), np.array(r),
                            np.full(len(y), np.nan), names, 200.0)  # fmt: skip

    train, test = windows(8, 30, 6), windows(6, 30, int(rng.integers(100, 200)))
    model = wi.train_classifier(train, config=FAST)
    assert model.context_s == pytest.approx(3.0)  # three 1 s windows by default (fitted)
    res = wi.evaluate_classifier(model, test)
    assert res["context_s"] == pytest.approx(3.0)
    assert res["accuracy"] > res["accuracy_per_window"] + 0.05, res
    assert 0.55 < res["accuracy_per_window"] < 0.95  # the windows really are ambiguous

    path = model.save(tmp_path / "m")
    head = json.loads((path / "model.json").read_text())
    assert head["context_s"] == pytest.approx(3.0)
    loaded = wi.ClassifierModel.load(path)
    assert loaded.context_s == pytest.approx(3.0) and loaded.lookback_s == pytest.approx(2.0)
    del head["context_s"]
    (path / "model.json").write_text(json.dumps(head))
    old = wi.ClassifierModel.load(path)
    assert old.lookback_s == 0.0
    assert wi.evaluate_classifier(old, test)["accuracy"] == pytest.approx(
        res["accuracy_per_window"], abs=1e-9
    )
    (path / "model.json").write_text(json.dumps({**head, "context_s": 0.5}))
    with pytest.raises(wi.ModelError, match="shorter than one window"):
        wi.ClassifierModel.load(path)


def test_confusion_matrix_and_text():
    c = confusion_matrix([0, 0, 1, 1, 1], [0, 1, 1, 1, 0], 2)
    assert c.tolist() == [[1, 1], [1, 2]]
    text = format_confusion(c, ["a", "b"])
    assert "0.500" in text and "0.667" in text


@pytest.mark.slow
def test_cli_synth_train_evaluate_classify(tmp_path, capsys):
    ds, model = tmp_path / "ds", tmp_path / "model"
    args = ["--terrains", "brick", "sand", "--speeds", "0.2", "--runs", "2", "--duration", "6"]
    assert main(["dataset", "synth", "--out", str(ds), *args]) == 0
    assert len(list(ds.glob("*/*.csv"))) == 4
    train = ["train", str(ds), "--out", str(model), "--hidden", "16", "16", "--max-epochs", "40"]
    assert main([*train, "--cv", "5"]) == 2  # four recordings
    assert "pass 2 to 4" in capsys.readouterr().err and not model.exists()
    assert main([*train, "--ensemble", "1", "--cv", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["labels"] == ["brick", "sand"] and 20 <= out["windows"] <= 24
    assert (out["weight_decay"], out["input_noise"]) == (1.0, 0.3)  # fitted's defaults
    cv = out["cross_validation"]
    assert cv["folds"] == 2 and len(cv["accuracy_by_fold"]) == 2 and 0 <= cv["accuracy"] <= 1
    head = json.loads((model / "model.json").read_text())
    assert head["training"]["cross_validation"] == cv
    assert main(["evaluate", str(model), str(ds), "--json", "--plot", str(tmp_path / "c.png")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert {"accuracy", "per_class", "confusion", "labels"} <= set(res)
    assert (tmp_path / "c.png").stat().st_size > 1000
    rec = next((ds / "sand").glob("*.csv"))
    assert main(["classify", str(model), str(rec), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["label"] in ("brick", "sand") and len(res["windows"]) in (5, 6)
    assert main(["classify", str(rec), str(model)]) == 2  # the arguments swapped
    assert "MODEL " + str(rec) + " is a file that looks like a recording" in capsys.readouterr().err
    (model / "model.json").write_text("{}")
    assert main(["classify", str(model), str(rec)]) == 2
    assert "incompatible model format" in capsys.readouterr().err


def test_multichannel_model_round_trip(tmp_path):
    """Windows of two signals: the tone is in the second one only. (The paper's features:
    they compile in a fraction of the time; the fitted ones per channel are tested in
    test_features.py.)"""
    ws = _toy_windows()
    noise = np.random.default_rng(6).standard_normal(ws.windows.shape)
    ws2 = replace(ws, windows=np.stack([noise, ws.windows], axis=1))
    model = wi.train_classifier(ws2, features="paper", config=FAST)
    assert model.spec.channels == 2 and model.spec.n_features == 2 * 200
    assert wi.evaluate_classifier(model, ws2)["accuracy"] > 0.9
    loaded = wi.ClassifierModel.load(model.save(tmp_path / "m2"))
    label, _ = loaded.predict_window(ws2.windows[0])
    assert label == model.labels[int(np.argmax(model.predict_proba(ws2.windows[:1])[0]))]
    with pytest.raises(ValueError, match=r"\(2, 200\)"):
        loaded.predict_window(ws2.windows[0, 1])


class _Compiles(logging.Handler):
    """Counts JAX compilations by function name while installed (``jax.log_compiles``)."""

    def __init__(self):
        super().__init__()
        self.names = collections.Counter()

    def emit(self, record):
        found = re.search(r"Compiling jit\((\w+)\)", record.getMessage())
        if found:
            self.names[found.group(1)] += 1

    def __enter__(self):
        self._ctx = jax.log_compiles(True)
        self._ctx.__enter__()
        logging.getLogger("jax").addHandler(self)
        return self.names

    def __exit__(self, *exc):
        logging.getLogger("jax").removeHandler(self)
        self._ctx.__exit__(*exc)


def test_one_compilation_per_architecture(tmp_path):
    """Models of one architecture share compiled functions: loading a model file twice, or
    a second model with other weights, compiles nothing more."""
    ws = _toy_windows(n_rec=6, per=8)
    cfg = replace(FAST, max_epochs=20)  # compiled for other tests too
    for seed in (0, 1):
        wi.train_classifier(ws, config=replace(cfg, seed=seed)).save(tmp_path / f"m{seed}")
    with _Compiles() as compiled:
        for folder in ("m0", "m0", "m1"):
            model = wi.ClassifierModel.load(tmp_path / folder)
            for n in (3, 5, 7):  # recordings of several lengths: one size class
                model.predict_proba(ws.windows[:n])
            model.predict_window(ws.windows[0])
    assert compiled["_batch_proba"] <= 1 and compiled["_window_proba"] <= 1, compiled


@pytest.mark.slow
def test_cli_two_sensors_whisker_aware_model_on_another_calibrated_whisker(tmp_path, capsys):
    """The paper's two orthogonal sensors through synth, train (whisker-aware), evaluate
    and classify; a recording of another whisker is refused until its calibrated record is
    given, then classified; re-evaluating the training recordings is pointed out and the
    report has precision, recall and F1."""
    ds, other, model = tmp_path / "ds", tmp_path / "other", tmp_path / "model"
    paper = tmp_path / "paper.toml"
    wi.paper_record().save(paper)
    damp = tmp_path / "damp.toml"
    wi.paper_record().replace(name="damp", zeta=0.08).save(damp)
    args = ["--terrains", "brick", "sand", "--speeds", "0.2", "--duration", "3", "--channels", "2"]
    assert main(["dataset", "synth", "--out", str(ds), "--runs", "2", *args]) == 0
    assert main(["dataset", "synth", "--out", str(other), "--runs", "1", "--seed", "3",
                 "--whisker", str(damp), *args]) == 0  # fmt: skip
    train = ["train", str(ds), "--out", str(model), "--hidden", "8", "--max-epochs", "20",
             "--channel", "hall_a,hall_b", "--span-whiskers", "2"]  # fmt: skip
    assert main(train) == 2
    assert "--span-whiskers goes with --whisker" in capsys.readouterr().err
    assert main([*train, "--whisker", str(paper), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["channel"] == "hall_a,hall_b" and out["whisker"] == "paper-whisker"
    assert out["span_whiskers"] == 2 and out["train_windows"] == 3 * out["windows"]
    head = json.loads((model / "model.json").read_text())
    assert head["features"]["deconvolve"] and head["features"]["cross_channel"]
    assert head["features"]["channels"] == 2 and "zeta = 0.04" in head["whisker"]["toml"]
    assert len(head["training"]["recordings_sha256"]) == 4
    assert main(["evaluate", str(model), str(ds), "--json"]) == 0
    captured = capsys.readouterr()
    res = json.loads(captured.out)
    assert "4 of these 4 recording(s) trained this model" in captured.err
    assert "f1-score" in captured.err and res["training_recordings_evaluated"] == 4
    assert set(res["report"]["per_class"]["sand"]) == {"precision", "recall", "f1", "support"}
    rec = next((other / "sand").glob("*.csv"))
    assert main(["classify", str(model), str(rec)]) == 2
    err = capsys.readouterr().err
    assert "made with whisker 'damp'" in err and "pass --whisker" in err
    assert main(["classify", str(model), str(rec), "--whisker", str(damp), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["channel"] == "hall_a,hall_b" and res["label"] in ("brick", "sand")
    assert main(["evaluate", str(model), str(other), "--whisker", str(damp)]) == 0
    assert "trained this model" not in capsys.readouterr().err


def test_model_files_without_the_new_settings_still_load(tmp_path):
    """A model file written before whisker-aware and cross-channel features, and before
    training hashes, loads and labels as before; it cannot take another whisker."""
    ws = _toy_windows()
    model = wi.train_classifier(ws, features="paper", config=FAST)
    path = model.save(tmp_path / "m")
    head = json.loads((path / "model.json").read_text())
    for key in ("deconvolve", "cross_channel"):
        del head["features"][key]
    head["training"].pop("recordings_sha256", None)
    (path / "model.json").write_text(json.dumps(head))
    old = wi.ClassifierModel.load(path)
    np.testing.assert_array_equal(old.predict_proba(ws.windows[:5]),
                                  model.predict_proba(ws.windows[:5]))  # fmt: skip
    assert old.whisker is None and not old.needs_whisker
    with pytest.raises(ValueError, match="raw signal's"):
        old.use_whisker(wi.WhiskerResponse(wi.paper_record(), 20.0))


def _tone_dataset(root, tone):
    """``ROOT/<label>/r<k>.csv``: 8 s at 200 Hz, a tone ``tone(label, speed)`` with two
    weaker side tones 5 Hz away, in noise, at speeds 0.1 and 0.3 m/s (two runs each)."""
    rng = np.random.default_rng(0)
    t = np.arange(1600) / 200.0
    for label in ("a", "b"):
        for k, (v, _run) in enumerate(itertools.product((0.1, 0.3), range(2))):
            f = tone(label, v)
            x = (
                np.sin(2 * np.pi * f * t)
                + 0.3 * np.sin(2 * np.pi * (f - 5) * t)
                + 0.2 * np.sin(2 * np.pi * (f + 5) * t)
                + 0.1 * rng.standard_normal(t.size)
            )
            rec = wi.Recording(t=t, columns={"adc": x}, meta={"speed_mps": str(v)})
            wi.write_csv(root / label / f"r{k}.csv", rec)


@pytest.mark.parametrize(
    ("tone", "holds"),
    [(lambda label, v: (20.0 if label == "a" else 40.0) + 50 * v, True),  # by terrain and speed
     (lambda label, v: 30.0, False)],  # one frequency for all: not distinct
)  # fmt: skip
def test_cli_analyze_dominant_components_and_the_papers_claim(tmp_path, capsys, tone, holds):
    root = tmp_path / "ds"
    _tone_dataset(root, tone)
    out, png = tmp_path / "a.json", tmp_path / "a.png"
    assert main(["analyze", str(root), "--out", str(out), "--plot", str(png), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    g = res["groups"]["b"]["0.3"]
    assert abs(g["dominant_hz"] - tone("b", 0.3)) < 0.1 and g["sandwiched"]
    assert g["recordings"] == 2 and len(g["components"]) == 3
    assert res["claim"]["verdict"].startswith("the claim holds" if holds else "the claim does not")
    assert res["claim"]["sandwiched"] == 1.0
    assert json.loads(out.read_text())["groups"] == res["groups"] and png.stat().st_size > 5000


def test_spectrum_plot_labels_peaks_not_noise_bumps():
    from whiskerid.plot import real_peaks

    rng = np.random.default_rng(0)
    f = np.fft.rfftfreq(2000, 1 / 200)
    noise = np.abs(np.fft.rfft(rng.standard_normal(2000)))
    assert real_peaks(f, noise) == []  # the largest noise bumps stand about 2x over the median
    tone = noise.copy()
    tone[np.searchsorted(f, 37.0)] += 40 * np.median(noise)
    peaks = real_peaks(f, tone)
    assert len(peaks) == 1 and abs(peaks[0].frequency_hz - 37.0) < 0.2


@pytest.mark.slow
def test_modal_fit_model_round_trip(tmp_path):
    """``window_fit`` features go through training, the model file and both predict
    paths."""
    ws = _toy_windows(n_rec=4, per=6)
    model = wi.train_classifier(ws, config=replace(FAST, max_epochs=20), window_fit=True,
                                use_speed=False)  # fmt: skip
    assert model.spec.window_fit
    loaded = wi.ClassifierModel.load(model.save(tmp_path / "m"))
    p = loaded.predict_proba(ws.windows[:3])
    np.testing.assert_allclose(loaded.window_proba(ws.windows[0]), p[0], rtol=1e-5, atol=1e-6)


def test_modal_fit_option_goes_with_the_fitted_features(tmp_path, capsys):
    (tmp_path / "data").mkdir()
    assert main(["train", str(tmp_path / "data"), "--out", str(tmp_path / "x"), "--features",
                 "paper", "--modal-fit"]) == 2  # fmt: skip
    assert "--modal-fit goes with --features fitted" in capsys.readouterr().err
