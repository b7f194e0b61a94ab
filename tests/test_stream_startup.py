"""The stream's start: the model loads on a thread while sampling starts, with the errors a
load always gave, and nothing it does not need (SciPy's statistics) is imported."""

import argparse
import subprocess
import sys
import threading

import numpy as np
import pytest

from whiskerid.cli import _main, _prestart, _stream, main
from whiskerid.io import Recording, write_csv


class _Model:
    """Records the warm-up's calls; stands in for a loaded ClassifierModel."""

    window, rate_hz = 200, 200.0

    def __init__(self):
        self.calls = []
        self.thread = None

    def use_saved_program(self, folder):
        self.calls.append(("saved", folder))

    def window_proba(self, x, speed):
        self.thread = threading.current_thread().name
        self.calls.append(("proba", x.shape, speed))
        return np.array([0.5, 0.5])


def test_the_loader_returns_the_model_warm_from_its_own_thread(monkeypatch, tmp_path):
    model = _Model()
    monkeypatch.setattr(_stream, "_load_model", lambda args, cache: (model, {"engine": "jax"}))
    assert _stream._ModelLoader(None, tmp_path).result() == (model, {"engine": "jax"})
    assert model.calls[0] == ("saved", tmp_path) and model.calls[1][:2] == ("proba", (200,))
    assert model.thread == "whiskerid-model-load"  # not the main thread


def test_the_loaders_error_is_raised_by_result(monkeypatch):
    error = _stream.CommandError("--rate 100 Hz is below the 200 Hz this model was trained at")

    def fails(args, cache):
        raise error

    monkeypatch.setattr(_stream, "_load_model", fails)
    loader = _stream._ModelLoader(None, None)
    with pytest.raises(_stream.CommandError) as got:
        loader.result()
    assert got.value is error


def test_a_model_that_cannot_load_is_refused_in_one_line(tmp_path, capsys):
    t = np.arange(400) / 200.0
    rec = tmp_path / "sine.csv"
    write_csv(rec, Recording(t, {"A0": np.round(5000 * np.sin(2 * np.pi * 20 * t)).astype(int)},
                             {"units": "code", "fsr_v": "4.096"}))  # fmt: skip
    argv = ["stream", "--model", str(tmp_path / "m"), "--replay", str(rec), "--fast"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "no classifier model here" in err


def test_a_refused_stream_ends_the_sampling_process_it_started_early(tmp_path, monkeypatch,
                                                                    capsys):  # fmt: skip
    started = []

    def spy(args):  # the real prestart, keeping the child it started
        _prestart.prestart(args)
        started.append(getattr(args, "_sampling_child", None))

    monkeypatch.setattr(_main, "prestart", spy)
    t = np.arange(400) / 200.0
    rec = tmp_path / "sine.csv"
    write_csv(rec, Recording(t, {"A0": np.zeros(400, dtype=int)}, {"units": "code"}))
    assert main(["stream", "--model", str(tmp_path / "m"), "--replay", str(rec)]) == 2
    assert "no classifier model here" in capsys.readouterr().err
    (child,) = started
    assert child is not None and child.returncode == 0  # started, then ended unused


def test_the_child_started_before_parsing_goes_to_the_stream_that_uses_one(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["/usr/bin/whiskerid", "stream", "--model", "m"])
    _prestart.spawn_early()
    (early,) = _prestart._early
    stream = argparse.Namespace(command="stream", fast=False, simulate=None)
    _prestart.prestart(stream)
    assert _prestart.take(stream) is early and not _prestart._early
    _prestart._end(early)
    assert early.returncode == 0  # its input ended before a spec: it exits unused
    monkeypatch.setattr(sys, "argv", ["/usr/bin/whiskerid", "stream", "--fast"])
    _prestart.spawn_early()  # --fast samples in the stream's own process
    assert not _prestart._early


def test_a_child_started_early_for_a_stream_that_samples_itself_is_ended(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["/usr/bin/whiskerid", "stream"])
    _prestart.spawn_early()
    (early,) = _prestart._early
    simulated = argparse.Namespace(command="stream", fast=False, simulate="brick")
    _prestart.prestart(simulated)
    assert early.returncode == 0 and _prestart.take(simulated) is None


def test_the_classifier_does_not_import_scipy_stats():
    code = "import sys, whiskerid.classify; print('scipy.stats' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
