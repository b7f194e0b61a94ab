"""What a new user types wrong is refused where it enters (exit 2, one line naming the flag
and the value), units are SI, and a clipped simulation says so."""

import json
from pathlib import Path

import numpy as np
import pytest

from whiskerid.cli import main
from whiskerid.io import Recording, parse_mass, write_csv

PAPER = "fits/paper-whisker.toml"


@pytest.fixture(autouse=True)
def _repo_root(monkeypatch, request):
    monkeypatch.chdir(request.config.rootpath)


@pytest.fixture
def tree(tmp_path):
    t = np.arange(400) / 200.0
    rec = Recording(t, {"adc": 1000 * np.exp(-t) * np.sin(2 * np.pi * 46 * t)})
    write_csv(tmp_path / "a.csv", rec)
    write_csv(tmp_path / "b.csv", rec)
    (tmp_path / "data" / "brick").mkdir(parents=True)
    write_csv(tmp_path / "data" / "brick" / "r1.csv", rec)
    acc = np.sin(2 * np.pi * 20 * t)
    acc[7] = 1e300  # a corrupt sample, finite but absurd
    write_csv(tmp_path / "base.csv", Recording(t, {"acc": acc}))
    return tmp_path


REC = "record {d}/x.csv --emulate pluck --fast --duration 1 --added-mass "
CAL = "calibrate {d}/a.csv --whisker " + PAPER + " --out {d}/o.toml "
# Each row: a command line, and the words its one-line refusal must hold.
BAD = [
    (REC + "520", ["--added-mass", "520 kg", "0.52g"]),
    (REC + "1e400g", ["--added-mass", "finite"]),
    (REC + "1kg±0.1g", ["--added-mass", "plausible"]),
    (REC + "1g", ["--added-mass", "uncertainty"]),
    (CAL.replace("a.csv", "a.csv {d}/b.csv")
     + "--added-mass {d}/b.csv=0.5g±0.01g --added-mass {d}/b.csv=0.6g±0.01g",
     ["--added-mass", "twice"]),
    (CAL + "--f1-start 1e9", ["--f1-start", "1e+09"]),
    (CAL + "--f1-start nan", ["--f1-start", "nan"]),
    ("analyze {d}/data --segment inf", ["--segment", "inf"]),
    ("analyze {d}/data --segment 0.001", ["--segment", "0.001"]),
    ("analyze {d}/data --rate 1e7", ["--rate", "1e+07"]),
    ("analyze {d}/data --rate 0", ["--rate", "0"]),
    ("analyze {d}/data --rate nan", ["--rate", "nan"]),
    ("analyze {d}/data --perturbation-hz inf", ["--perturbation-hz", "inf"]),
    ("analyze {d}/data --perturbation-hz nan", ["--perturbation-hz", "nan"]),
    ("analyze {d}/data --per-rev inf", ["--per-rev", "inf"]),
    ("analyze {d}/data --per-rev 2 --wheel-diameter 1e-300", ["--wheel-diameter", "1e-300"]),
    ("analyze {d}/data --channel nope", ["--channel", "nope", "adc"]),
    ("simulate --excitation sine --cubic 1e4 --out {d}/s.csv", ["--cubic", "--excitation decay"]),
    ("simulate --excitation decay --cubic nan --out {d}/s.csv", ["--cubic", "nan"]),
    ("fleet simulate {d}/fleet --whiskers 0", ["--whiskers", "0"]),
    ("dataset synth --out {d}/syn --contact --duration 1e9", ["--duration", "1e+09"]),
    ("dataset synth --out {d}/syn --duration nan", ["--duration", "nan"]),
    ("dataset synth --out {d}/syn --runs 0", ["--runs", "0"]),
    ("fleet simulate {d}/fleet --rate 1e6", ["--rate", "1e+06"]),
    ("fleet simulate {d}/fleet --damaged 5 --whiskers 3", ["--damaged", "5"]),
    ("simulate --excitation base --base {d}/base.csv --out {d}/s.csv",
     ["--base", "base.csv", "sample 7", "1e+300", "plausible", "m/s^2"]),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "words"), BAD, ids=[f"{b[0].split()[0]}{i}" for i, b in
                                                      enumerate(BAD)])  # fmt: skip
def test_a_bad_value_is_refused_naming_it(tree, capsys, argv, words):
    assert main([*argv.format(d=tree).split(), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    assert not (tree / "x.csv").exists() and not (tree / "fleet").exists()


@pytest.mark.parametrize(
    ("text", "kg"),
    [("520mg", 5.2e-4), ("0.52g", 5.2e-4), ("5.2e-4kg", 5.2e-4), ("0.00052", 5.2e-4),
     ("1g±0.01g", 1e-3)],
)  # fmt: skip
def test_a_bare_mass_is_kilograms_and_units_are_read(text, kg):
    assert parse_mass(text)[0] == pytest.approx(kg)


def test_a_clipped_simulation_warns_and_says_how_much_to_scale(tmp_path, capsys):
    argv = ["simulate", "--excitation", "sine", "--observable", "adc", "--duration", "1",
            "--json", "--quiet", "--out"]  # fmt: skip
    assert main([*argv, str(tmp_path / "ok.csv"), "--hb", "1e-4"]) == 0
    out = capsys.readouterr()
    assert "clipped" not in json.loads(out.out) and "warning" not in out.err
    assert main([*argv, str(tmp_path / "rails.csv"), "--hb", "0.2"]) == 0
    out = capsys.readouterr()
    clipped = json.loads(out.out)["clipped"]
    assert clipped["fraction"] > 0.3 and 0 < clipped["scale"] < 0.5
    assert "warning" in out.err and "--hb" in out.err and f"{clipped['scale']:.2g}" in out.err


def test_no_xla_banner_reaches_a_user_and_a_slow_compile_gets_a_note(tmp_path):
    """XLA's own log is off on the command line; a compile longer than the threshold (here
    1 ms, so that every compile counts) gets the project's one-line note instead."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "WHISKERID_SLOW_COMPILE_NOTE_S": "0.001"}
    env.pop("TF_CPP_MIN_LOG_LEVEL", None)
    done = subprocess.run(
        [sys.executable, "-m", "whiskerid.cli", "simulate", "--duration", "0.5", "--quiet",
         "--out", str(tmp_path / "s.csv")],
        env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "note: compiling" in done.stderr and "compilation cache" in done.stderr
    assert "Very slow compile" not in done.stderr and "E0000" not in done.stderr


def test_a_record_with_no_hall_gain_is_refused_naming_the_key(tmp_path, capsys):
    text = Path(PAPER).read_text()
    key = next(line for line in text.splitlines() if line.startswith("hall_gain_v_per_m"))
    (tmp_path / "w.toml").write_text(text.replace(key, "hall_gain_v_per_m = 0.0"))
    argv = ["simulate", "--whisker", str(tmp_path / "w.toml"), "--observable", "adc", "--out",
            str(tmp_path / "s.csv"), "--quiet"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "hall_gain_v_per_m = 0.0" in err and "ZeroDivision" not in err


def test_fleet_check_refuses_a_session_given_twice_and_bytes_that_are_not_text(tmp_path, capsys):
    from whiskerid.fleet import write_table

    fleet = tmp_path / "FLEET"
    fleet.mkdir()
    rows = [{"whisker": "w0", "session": f"2026-11-2{i}", "f1_hz": "46.0", "zeta": "0.04",
             "status": "ok"} for i in range(4)]  # fmt: skip
    write_table(fleet / "fleet.csv", [*rows, {**rows[2], "f1_hz": "47.5"}])
    assert main(["fleet", "check", str(fleet), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "fleet.csv" in err and "session 2026-11-22" in err and "lines 4 and 5" in err
    write_table(fleet / "fleet.csv", rows)
    (fleet / "health.csv").write_bytes((fleet / "fleet.csv").read_bytes() + b"w0,caf\xe9\n")
    assert main(["fleet", "check", str(fleet), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "health.csv" in err and "UTF-8" in err and "Traceback" not in err


@pytest.mark.slow
def test_calibrate_writes_neither_out_nor_plot_when_the_plot_fails(tree, capsys, monkeypatch):
    """A full disk while the figure is written leaves no --out behind (all or nothing)."""
    import errno

    from matplotlib.figure import Figure

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", full_disk)
    argv = [*CAL.format(d=tree).split(), "--plot", str(tree / "o.png"), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "o.png" in err and "No space left" in err and "Traceback" not in err, err
    assert not (tree / "o.toml").exists() and not (tree / "o.png").exists()
    assert not [p.name for p in tree.iterdir() if p.name.startswith(".")]
    monkeypatch.undo()
    monkeypatch.chdir(Path(__file__).resolve().parent.parent)
    assert main(argv) == 0
    assert (tree / "o.toml").exists() and (tree / "o.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("value", ["nan", "", "-46.0"])
def test_fleet_check_refuses_a_usable_row_without_a_positive_value(tmp_path, capsys, value):
    """A failed drive logs NaN beside its failure (flagged ``fit``); NaN, a blank or a
    negative value beside ``ok`` is a damaged file, refused naming file, line and column."""
    from whiskerid.fleet import write_table

    fleet = tmp_path / "FLEET"
    fleet.mkdir()
    rows = [{"whisker": "w0", "session": f"2026-11-2{i}", "f1_hz": "46.0", "zeta": "0.04",
             "status": "ok"} for i in range(4)]  # fmt: skip
    write_table(fleet / "fleet.csv", rows)
    failed = {**rows[3], "session": "2026-11-29", "f1_hz": "nan", "zeta": "nan",
              "status": "too short"}  # fmt: skip
    write_table(fleet / "health.csv", [*rows, failed])
    argv = ["fleet", "check", str(fleet), "--no-plots", "--quiet", "--json"]
    assert main(argv) == 0
    flags = json.loads(capsys.readouterr().out)["flags"]
    assert [(f["session"], f["parameter"]) for f in flags] == [("2026-11-29", "fit")]
    write_table(fleet / "health.csv", [*rows[:2], {**rows[2], "zeta": value}, rows[3]])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert "health.csv: line 4, column 6 (zeta)" in err and repr(value) in err, err
