"""Outputs: never a device or a dangling link without --force, never merged into a model
folder, published exclusively (concurrent runs), all or nothing, no empty chain left."""

import errno
import os
import signal

import numpy as np
import pytest
from helpers import one_step_chain

import whiskerid as wi
from whiskerid.cli import main
from whiskerid.cli._common import Interrupted, InterruptPolicy
from whiskerid.io import WriteError, atomic_write, clear_expected, expect_new
from whiskerid.terrain import _terrain

PAPER = "fits/paper-whisker.toml"


def _refused(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err, err


def test_a_device_is_never_replaced_and_a_dangling_link_needs_force(tmp_path, capsys):
    _refused(capsys, ["simulate", "--out", os.devnull, "--force", "--duration", "1"],
             "is not a regular file")  # fmt: skip
    link = tmp_path / "out.csv"
    link.symlink_to(tmp_path / "missing" / "target.csv")
    _refused(capsys, ["simulate", "--out", str(link), "--duration", "1"], "which does not exist")
    assert link.is_symlink()


def test_dataset_synth_never_merges_into_a_model_folder(tmp_path, capsys):
    model = tmp_path / "model"
    model.mkdir()
    (model / "model.json").write_text("{}")
    _refused(capsys, ["dataset", "synth", "--out", str(model), "--force", "--duration", "2"],
             "holds files of its own (e.g. model.json)")  # fmt: skip
    assert sorted(p.name for p in model.iterdir()) == ["model.json"]


def test_an_output_that_appears_meanwhile_is_not_overwritten(tmp_path):
    """Three concurrent commands each found the output absent: the first to publish wins,
    the others fail (it was 'all exit 0', each overwriting the last)."""
    out = tmp_path / "same.toml"
    try:
        expect_new(out)
        out.write_text("the other process's")
        with pytest.raises(WriteError) as err:
            atomic_write(out, "mine")
        assert err.value.errno == errno.EEXIST and "appeared while" in str(err.value)
        assert out.read_text() == "the other process's"
        assert [p.name for p in tmp_path.iterdir()] == ["same.toml"]  # no temporary left
        out.unlink()
        atomic_write(out, "mine")  # still absent: published
        assert out.read_text() == "mine"
    finally:
        clear_expected()


def test_dataset_synth_is_all_or_nothing(tmp_path, monkeypatch):
    """A full disk at the third of four recordings leaves none (it left the first two)."""
    t = np.arange(400) / 200.0

    def runs(specs, **kwargs):
        for _ in specs:
            yield wi.Recording(t=t, columns={"adc": np.sin(t)}, meta={"rate_hz": 200})

    written = []

    def write(path, rec):
        if len(written) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        written.append(path)
        return wi.write_csv(path, rec)

    monkeypatch.setattr(_terrain, "iter_runs", runs)
    monkeypatch.setattr(_terrain, "write_csv", write)
    out = tmp_path / "ds"
    with pytest.raises(OSError, match="No space"):
        _terrain.synthesize_dataset(out, terrains=("flat", "sand"), speeds=(0.2,), runs=2,
                                    duration_s=2.0)  # fmt: skip
    assert len(written) == 2 and not out.exists()
    monkeypatch.setattr(_terrain, "write_csv", wi.write_csv)
    paths = _terrain.synthesize_dataset(out, terrains=("flat", "sand"), speeds=(0.2,), runs=2,
                                        duration_s=2.0)  # fmt: skip
    assert len(paths) == 4 and sorted(out.rglob("*.csv")) == sorted(paths)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_a_refused_posterior_leaves_no_chain_to_block_the_rerun(tmp_path, capsys):
    sim = wi.simulate(wi.paper_record(), excitation="decay", tip_deflection_m=2e-3,
                      rate_hz=200.0, duration_s=1.0, seed=1)  # fmt: skip
    wi.write_csv(tmp_path / "rec.csv", sim)
    out = tmp_path / "post"
    argv = ["posterior", str(tmp_path / "rec.csv"), "--fit", PAPER, "--out", str(out),
            "--steps", "1", "--no-plots"]  # fmt: skip
    _refused(capsys, [*argv, "--modes", "50"], "n_modes = 50")
    assert not (out / "chain.h5").exists()


def test_a_second_signal_never_reaches_a_command_that_is_stopping():
    """Once the command has caught its interrupt, another signal (systemd's SIGTERM to the
    group, a second Ctrl-C) is ignored: raised in the teardown it crashed the process."""
    policy = InterruptPolicy()
    with pytest.raises(Interrupted):
        policy._handle(signal.SIGTERM, None)
    with pytest.raises(Interrupted):  # not caught yet (swallowed where it landed?): again
        policy._handle(signal.SIGTERM, None)
    policy.stopping = True  # what main sets once it has caught the interrupt
    assert policy._handle(signal.SIGTERM, None) is None
    assert policy._handle(signal.SIGINT, None) is None
    assert policy.status(Interrupted(signal.SIGTERM)) == 143


def test_the_chain_stops_whole_before_the_disk_is_full(tmp_path, monkeypatch):
    """HDF5 crashed the process when a step's write failed on a full disk (the chain left
    torn): the chain is held in memory and a checkpoint is refused short of
    CHAIN_FREE_BYTES beyond its size, the last one on disk staying readable for --resume."""
    import emcee

    from whiskerid.posterior import _sample

    path = tmp_path / "chain.h5"
    be, state = one_step_chain(path)
    monkeypatch.setattr(_sample, "CHAIN_FREE_BYTES", 1 << 62)  # no disk has that much
    be.save_step(state, np.ones(4, bool))  # in memory: the first step was saved just now
    with pytest.raises(OSError, match="on its disk, too little to save") as err:
        be.checkpoint()
    assert err.value.errno == errno.ENOSPC
    again = emcee.backends.HDFBackend(str(path), name="whiskerid", read_only=True)
    assert again.iteration == 1 and again.get_chain().shape == (1, 4, 2)
