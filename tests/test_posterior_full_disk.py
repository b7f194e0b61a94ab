"""A disk that fills during ``posterior``: HDF5 crashed the process (SIGSEGV, h5py's
"Can't decrement id ref count") when a write of the open chain file failed with ENOSPC.
The chain is now held in memory and written whole at checkpoints by plain Python, so a
full disk ends the run with exit 2 and one line saying what was kept, and ``--resume``
continues from that checkpoint."""

import errno
import json

import h5py
import pytest
from test_posterior import decay

import whiskerid as wi
from whiskerid.cli._main import main
from whiskerid.posterior import _sample


@pytest.mark.slow
def test_a_full_disk_mid_run_keeps_the_last_checkpoint_for_resume(tmp_path, capsys, monkeypatch):
    o = decay(5)
    csv = tmp_path / "decay.csv"
    wi.write_csv(csv, wi.Recording(o.t, {"deflection": o.y}))
    fit = tmp_path / "fit.toml"
    paper = str(wi.paper_record().save(tmp_path / "paper.toml"))
    data = ["--t-start", "0", "--modes", "1"]
    assert main(["calibrate", str(csv), "--whisker", paper, "--out", str(fit), *data]) == 0
    capsys.readouterr()

    full_at = 30  # the 30th checkpoint finds the disk full
    calls = []
    write = _sample.write_image

    def filling(path, image):
        calls.append(path)
        if len(calls) >= full_at:
            raise OSError(errno.ENOSPC, "No space left on device")
        write(path, image)

    monkeypatch.setattr(_sample, "CHECKPOINT_S", 0.0)  # a checkpoint after every step
    monkeypatch.setattr(_sample, "write_image", filling)
    out = tmp_path / "post"
    run = ["posterior", str(csv), "--fit", str(fit), "--out", str(out), "--walkers", "16",
           "--t-start", "0", "--no-plots", "--quiet"]  # fmt: skip
    assert main([*run, "--steps", "200"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    kept = full_at - 1
    assert "No space left on device" in err[0]
    assert f"kept {out / 'chain.h5'} with {kept} finished steps" in err[0]
    assert "--resume" in err[0] and "Traceback" not in err[0]
    with h5py.File(out / "chain.h5", "r") as f:
        assert int(f["whiskerid"].attrs["iteration"]) == kept
        assert f["whiskerid"]["chain"].shape[0] >= kept

    monkeypatch.setattr(_sample, "write_image", write)  # space freed
    assert main([*run, "--steps", "10", "--resume", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["diagnostics"]["steps"] == kept + 10
