"""``dataset synth`` stopped part-way keeps the recordings it finished, and ``--resume``
simulates only the rest: the same dataset as a run that was never stopped."""

import pytest

from whiskerid.cli import main
from whiskerid.terrain import _terrain, synthesize_dataset

KW = {"terrains": ("flat", "brick"), "speeds": (0.2,), "runs": 2, "duration_s": 2.0, "seed": 3}


def test_an_interrupted_synth_keeps_its_finished_runs_and_resumes(tmp_path, monkeypatch):
    whole = synthesize_dataset(tmp_path / "whole", **KW)
    real = _terrain.write_csv
    calls = []

    def interrupted(path, rec):
        calls.append(path)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(path, rec)

    monkeypatch.setattr(_terrain, "write_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        synthesize_dataset(tmp_path / "cut", **KW)
    kept = sorted((tmp_path / "cut").glob("*/*.csv"))
    assert len(kept) == 2
    assert not list((tmp_path / "cut").glob(".synth-*"))  # the staging folder is gone
    monkeypatch.setattr(_terrain, "write_csv", real)
    # without --resume the folder is refused (old and new would mix)
    with pytest.raises(ValueError, match="already holds"):
        synthesize_dataset(tmp_path / "cut", **KW)
    written = []
    monkeypatch.setattr(_terrain, "write_csv", lambda p, r: written.append(p) or real(p, r))
    paths = synthesize_dataset(tmp_path / "cut", resume=True, **KW)
    assert len(written) == 2 and len(paths) == 4
    for a, b in zip(whole, paths, strict=True):
        assert a.read_bytes() == b.read_bytes(), (a, b)


def test_resume_does_not_keep_a_recording_of_other_settings(tmp_path):
    synthesize_dataset(tmp_path / "d", **{**KW, "runs": 1})
    with pytest.raises(ValueError, match="already holds"):
        # another seed: its recordings are not this dataset's, and are not replaced
        synthesize_dataset(tmp_path / "d", resume=True, **{**KW, "seed": 4, "runs": 1,
                                                           "terrains": ("sand",)})  # fmt: skip
    other = synthesize_dataset(tmp_path / "d", resume=True, **{**KW, "seed": 4, "runs": 1})
    assert len(other) == 2


def test_the_command_says_how_to_finish(tmp_path, monkeypatch, capsys):
    real = _terrain.write_csv
    calls = []

    def interrupted(path, rec):
        calls.append(path)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(path, rec)

    monkeypatch.setattr(_terrain, "write_csv", interrupted)
    argv = ["dataset", "synth", "--out", str(tmp_path / "t"), "--terrains", "flat", "brick",
            "--speeds", "0.2", "--runs", "1", "--duration", "2", "--quiet"]  # fmt: skip
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert "interrupted" in err and "kept (complete): 1 finished" in err and "--resume" in err
    monkeypatch.setattr(_terrain, "write_csv", real)
    assert main([*argv, "--resume"]) == 0
    assert len(list((tmp_path / "t").glob("*/*.csv"))) == 2
