"""The stream's JAX-free labelling path: the same probabilities and labels as the compiled
model, window by window, and a stream that never imports JAX when it uses it."""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
from whiskerid.hw._numpy_classifier import load_numpy_classifier
from whiskerid.hw._numpy_features import SPEC_DEFAULTS, unsupported

import whiskerid as wi
from whiskerid.cli import main


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """Models trained by ``whiskerid train``: fitted features with the speed (a synthetic
    terrain set, two speeds, an ensemble of two), fitted without it, and the paper's; and
    the synthetic windows with their speeds."""
    root = tmp_path_factory.mktemp("numpy")
    ds = root / "ds"
    assert main(["dataset", "synth", "--out", str(ds), "--terrains", "brick", "sand", "carpet",
                 "--speeds", "0.15", "0.3", "--runs", "1", "--duration", "8",
                 "--seed", "4"]) == 0  # fmt: skip
    out = {}
    for name, extra in (("speed", ["--ensemble", "2"]), ("nospeed", ["--no-speed"]),
                        ("paper", ["--features", "paper"])):  # fmt: skip
        out[name] = root / name
        assert main(["train", str(ds), "--out", str(out[name]), "--hidden", "12",
                     "--max-epochs", "30", *extra]) == 0  # fmt: skip
    return out, wi.load_dataset(ds), ds


@pytest.mark.parametrize("name", ["speed", "nospeed", "paper"])
def test_numpy_gives_the_compiled_models_probabilities(models, name):
    paths, ws, _ = models
    model = wi.ClassifierModel.load(paths[name])
    fast, why = load_numpy_classifier(paths[name])
    assert fast is not None, why
    rng = np.random.default_rng(0)
    rows = rng.choice(len(ws.windows), size=40, replace=False)
    labels_differ = 0
    for i in rows:
        x, v = ws.windows[i], float(ws.speeds[i])
        want = np.asarray(model.window_proba(x, v))
        got = fast.window_proba(x, v)
        np.testing.assert_allclose(got, want, atol=2e-6, rtol=0)
        labels_differ += int(np.argmax(got) != np.argmax(want))
        assert fast.window_health(x) == model.window_health(x)
    assert labels_differ == 0
    # Not a vacuous agreement: the windows get different, confident labels.
    probs = np.stack([fast.window_proba(ws.windows[i], float(ws.speeds[i])) for i in rows])
    assert len(set(np.argmax(probs, axis=1))) >= 2


def test_numpy_features_match_the_compiled_ones_to_float_precision(models):
    paths, ws, _ = models
    model = wi.ClassifierModel.load(paths["speed"])
    fast, _ = load_numpy_classifier(paths["speed"])
    # Recorded windows, and noise at the slowest and fastest training speeds: there a bin
    # lies exactly on the first and the last spatial band edge.
    noise = 4000 * np.random.default_rng(2).standard_normal((4, ws.windows.shape[1])) + 1e4
    x = np.concatenate([ws.windows[:8], noise])
    v = np.concatenate([ws.speeds[:8], np.repeat([ws.speeds.min(), ws.speeds.max()], 2)])
    want = np.asarray(wi.compute_features(model.spec, x, v))
    from whiskerid.hw._numpy_features import window_features

    got = np.stack([window_features(fast.spec, w, s) for w, s in zip(x, v, strict=True)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)  # float64 both


def test_the_defaults_are_the_feature_specs():
    assert SPEC_DEFAULTS == dataclasses.asdict(wi.FeatureSpec())


def test_features_numpy_does_not_compute_go_to_jax(models, tmp_path):
    assert unsupported({"kind": "fitted", "modal_fit": True}) is not None
    assert unsupported({"kind": "fitted", "deconvolve": True}) is not None
    assert unsupported({"kind": "fitted", "channels": 2}) is not None
    assert unsupported({"kind": "fitted", "use_speed": True, "octave_bands": True}) is None
    head = json.loads((models[0]["speed"] / "model.json").read_text())
    head["features"]["window_fit"] = True
    (tmp_path / "model.json").write_text(json.dumps(head))
    fast, why = load_numpy_classifier(tmp_path)
    assert fast is None and "window_fit" in why


def test_the_stream_labels_without_importing_jax(models, tmp_path):
    rec = models[2] / "brick" / "brick_v0.30_r00.csv"
    code = (
        "import sys, json\n"
        "from whiskerid.cli import main\n"
        f"rc = main(['stream', '--model', {str(models[0]['nospeed'])!r}, '--replay', "
        f"{str(rec)!r}, '--duration', '4', '--fast', '--quiet', '--json', "
        "'--compile-cache', 'none'])\n"
        "print('JAX', rc, 'jax' in sys.modules, 'equinox' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout  # fmt: skip
    summary = json.loads(out[: out.rindex("JAX")])
    assert summary["classifier"]["engine"] == "numpy" and summary["windows"] > 0
    assert out.splitlines()[-1] == "JAX 0 False False"


def test_a_model_numpy_cannot_run_streams_with_jax_and_says_why(models, tmp_path, capsys,
                                                               monkeypatch):  # fmt: skip
    from whiskerid.cli import _stream

    rec = models[2] / "brick" / "brick_v0.30_r00.csv"
    monkeypatch.setattr(
        _stream,
        "load_numpy_classifier",
        lambda path: (None, "a resonance fitted to each window (modal_fit)"),
    )
    argv = ["stream", "--model", str(models[0]["nospeed"]), "--replay", str(rec), "--fast",
            "--duration", "4", "--json", "--compile-cache", "none"]  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["classifier"] == {
        "engine": "jax",
        "why": "a resonance fitted to each window (modal_fit)",
    }
    assert "labelling with JAX: a resonance fitted" in captured.err


def test_the_stream_runs_with_jax_not_installed(models):
    """JAX, jaxlib and equinox made unimportable, as on a Pi without them."""
    rec = models[2] / "sand" / "sand_v0.15_r00.csv"
    code = (
        "import sys\n"
        "for name in ('jax', 'jaxlib', 'equinox', 'optimistix', 'optax'):\n"
        "    sys.modules[name] = None  # import raises ImportError\n"
        "from whiskerid.cli import main\n"
        f"sys.exit(main(['stream', '--model', {str(models[0]['speed'])!r}, '--replay', "
        f"{str(rec)!r}, '--duration', '3', '--fast', '--json', '--compile-cache', 'none']))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["classifier"]["engine"] == "numpy" and summary["windows"] >= 4
    assert "labelling with NumPy" in done.stderr
