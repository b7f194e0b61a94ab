"""No traceback: a .npy file named .npz, a reader that closes the pipe (``| head``)."""

import subprocess
import sys

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli import main
from whiskerid.io import RecordingError

PAPER = "fits/paper-whisker.toml"


def test_a_npy_file_named_npz_is_refused_in_words(tmp_path, capsys):
    fake = tmp_path / "rec.npz"
    with open(fake, "wb") as fh:
        np.save(fh, np.arange(400.0))
    with pytest.raises(RecordingError, match=r"a single NumPy array .* rename it to \.npy"):
        wi.read_recording(fake)
    assert (
        main(["calibrate", str(fake), "--whisker", PAPER, "--out", str(tmp_path / "c.toml")]) == 2
    )
    err = capsys.readouterr().err
    assert "rename it to .npy" in err and "Traceback" not in err


def test_a_closed_pipe_ends_the_command_quietly(tmp_path):
    """``whiskerid … --json | head -c 20``: the reader leaves early; exit 141 (SIGPIPE's
    status, as for any program), no BrokenPipeError traceback."""
    t = np.arange(2400) / 200.0
    x = np.sin(2 * np.pi * 30 * t) + 0.1 * np.random.default_rng(0).standard_normal(t.size)
    wi.write_csv(tmp_path / "ds" / "a" / "r.csv",
                 wi.Recording(t=t, columns={"adc": x}, meta={"rate_hz": 200}))  # fmt: skip
    cmd = [sys.executable, "-m", "whiskerid.cli", "analyze", str(tmp_path / "ds"), "--segment",
           "2", "--json"]  # fmt: skip
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as child:
        child.stdout.close()  # the reader is gone before anything is written
        err = child.stderr.read().decode()
        assert child.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err
