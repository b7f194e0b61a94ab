"""The README's main command works every time: ``whiskerid demo`` into a folder it wrote
replaces its own output (recognised by its marker file) and nothing else."""

from pathlib import Path

import pytest

from whiskerid.cli import _demo_stages, main
from whiskerid.cli._demo import MARKER


@pytest.fixture
def fake_demo(monkeypatch):
    """The demo's stages replaced by one file written (the policy is what is tested here)."""
    runs = []

    def run_demo(out, *, plots=True, say=print):
        runs.append(out)
        (Path(out) / "summary.txt").write_text(f"run {len(runs)}\n")
        return {"runs": len(runs)}

    monkeypatch.setattr(_demo_stages, "run_demo", run_demo)
    monkeypatch.setattr(_demo_stages, "summary_lines", lambda summary, out: ["ok"])
    return runs


def test_the_demo_runs_twice_into_its_default_folder(tmp_path, monkeypatch, fake_demo, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--quiet"]) == 0
    assert (tmp_path / "whiskerid-demo" / MARKER).is_file()
    (tmp_path / "whiskerid-demo" / "mine.txt").write_text("a user's note\n")
    assert main(["demo", "--quiet"]) == 0, capsys.readouterr().err
    assert len(fake_demo) == 2
    assert (tmp_path / "whiskerid-demo" / "summary.txt").read_text() == "run 2\n"
    # what the demo did not write is left alone
    assert (tmp_path / "whiskerid-demo" / "mine.txt").read_text() == "a user's note\n"


def test_a_folder_the_demo_did_not_write_is_refused_without_force(tmp_path, fake_demo, capsys):
    other = tmp_path / "results"
    other.mkdir()
    (other / "paper.tex").write_text("mine\n")
    assert main(["demo", "--quiet", "--out", str(other)]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "--force" in err and MARKER in err
    assert not fake_demo and not (other / MARKER).exists()
    assert main(["demo", "--quiet", "--out", str(other), "--force"]) == 0
    assert (other / "paper.tex").read_text() == "mine\n"


def test_a_file_named_like_the_marker_but_a_folder_does_not_count(tmp_path, fake_demo):
    out = tmp_path / "d"
    (out / MARKER).mkdir(parents=True)
    assert main(["demo", "--quiet", "--out", str(out)]) == 2
    assert not fake_demo
