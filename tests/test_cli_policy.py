"""The command line's policies: one output policy, atomic writes, interrupts, help text."""

import argparse
import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import start_child

import whiskerid as wi
from whiskerid.cli import build_parser, main
from whiskerid.io import Recording, WriteError, atomic_folder, timestamp_rate, write_csv

PAPER = "fits/paper-whisker.toml"


@pytest.fixture(autouse=True)
def _repo_root(monkeypatch, request):
    monkeypatch.chdir(request.config.rootpath)


@pytest.fixture
def tree(tmp_path):
    """A recording, a model folder, a dataset tree and a posterior folder holding a chain."""
    t = np.arange(400) / 200.0
    rec = Recording(t, {"deflection": 1e-3 * np.exp(-t) * np.sin(2 * np.pi * 46 * t)})
    write_csv(tmp_path / "rec.csv", rec)
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "model.json").write_text("{}\n")
    (tmp_path / "model" / "weights.npz").write_bytes(b"weights")
    (tmp_path / "data" / "brick").mkdir(parents=True)
    write_csv(tmp_path / "data" / "brick" / "r1.csv", rec)
    (tmp_path / "post").mkdir()
    (tmp_path / "post" / "chain.h5").write_bytes(b"chain")
    (tmp_path / "old.csv").write_text("old\n")
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "x.csv").write_text("old\n")
    return tmp_path


# Each row: a command that must be refused before any work, and the words that say why.
REFUSED = [
    ("simulate --out {d}/old.csv", "already exists; pass --force"),
    ("calibrate {d}/rec.csv --whisker " + PAPER + " --out {d}/old.csv", "already exists"),
    ("simulate --out {d}/old.csv --plot {d}/old.csv --force", "same path"),
    ("classify {d}/model {d}/rec.csv --plot {d}/model/model.json --force",
     "lies inside the input MODEL"),
    ("classify {d}/model {d}/rec.csv --plot {d}/rec.csv --force", "is also the input REC"),
    ("evaluate {d}/model {d}/data --plot {d}/data/brick/r1.csv --force",
     "lies inside the input DATASET"),
    ("evaluate {d}/model {d}/data --plot {d}/data/brick/confusion.png",
     "lies inside the input DATASET"),
    ("train {d}/data --out {d}/data/brick --force", "lies inside the input DATASET"),
    ("train {d}/data --out {d}/model", "already exists and is not empty; pass --force"),
    ("train {d}/data --out {d} --force", "lies inside the output folder"),
    ("posterior {d}/rec.csv --fit " + PAPER + " --out {d}/post", "pass --resume"),
    ("posterior {d}/rec.csv --fit " + PAPER + " --out {d}/post --resume --force", "give one"),
    ("demo --out {d}/demo", "already exists and is not empty"),
    ("stream --model {d}/model --simulate brick --record {d}/model/s.csv",
     "lies inside the input --model"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "why"), REFUSED, ids=[f"{r[0].split()[0]}{i}" for i, r in
                                                        enumerate(REFUSED)])  # fmt: skip
def test_outputs_over_inputs_or_existing_ones_are_refused_before_any_work(tree, capsys, argv, why):
    before = {p: p.read_bytes() for p in tree.rglob("*") if p.is_file()}
    assert main(argv.format(d=tree).split()) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and why in err, err
    assert {p: p.read_bytes() for p in tree.rglob("*") if p.is_file()} == before


def test_force_replaces_an_existing_output(tree, capsys):
    assert main(["simulate", "--duration", "0.5", "--out", str(tree / "old.csv"), "--force"]) == 0
    assert "t,deflection" in tree.joinpath("old.csv").read_text()


# ------------------------------------------------------------------------ atomic writes
def _no_space(fd):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


WRITERS = {
    "csv": lambda p: write_csv(p, Recording(np.arange(4.0), {"x": np.ones(4)})),
    "toml": lambda p: wi.paper_record().save(p),
    "png": lambda p: __import__("whiskerid.plot").plot.plot_signal_and_spectrum(
        p, np.arange(64) / 200, np.sin(np.arange(64.0)), label="x"
    ),
}


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_a_full_disk_names_the_file_and_leaves_the_old_one_whole(tmp_path, monkeypatch, kind):
    path = tmp_path / f"out.{kind}"
    path.write_bytes(b"the old, complete file\n")
    monkeypatch.setattr(os, "fsync", _no_space)
    with pytest.raises(WriteError, match=f"could not write {path}: No space left"):
        WRITERS[kind](path)
    assert path.read_bytes() == b"the old, complete file\n"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_a_model_folder_appears_whole_or_not_at_all(tmp_path):
    model = tmp_path / "model"
    model.mkdir()
    (model / "model.json").write_text("old header")
    (model / "weights.npz").write_text("old weights")
    (model / "notes.txt").write_text("the user's")
    with pytest.raises(RuntimeError), atomic_folder(model) as tmp:
        (tmp / "weights.npz").write_text("new weights")
        raise RuntimeError("cut off before the header")
    assert (model / "model.json").read_text() == "old header"
    assert (model / "weights.npz").read_text() == "old weights"
    with atomic_folder(model) as tmp:
        (tmp / "weights.npz").write_text("new weights")
        (tmp / "model.json").write_text("new header")
    assert (model / "model.json").read_text() == "new header"
    assert (model / "weights.npz").read_text() == "new weights"
    assert (model / "notes.txt").read_text() == "the user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model"]


def test_a_write_error_is_one_line_naming_the_file(tree, capsys, monkeypatch):
    monkeypatch.setattr(os, "fsync", _no_space)
    out = tree / "old.csv"
    assert main(["simulate", "--duration", "0.5", "--out", str(out), "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(out) in err and "No space left" in err
    assert out.read_text() == "old\n"


# ------------------------------------------------------------------------ interrupts
# calibrate in a child process, with one stage replaced by a wait the parent interrupts.
_CHILD = """
import sys, time
import whiskerid.{module} as m

def wait(*args, **kwargs):
    print("READY", file=sys.stderr, flush=True)
    time.sleep(60)

m.{name} = wait
from whiskerid.cli import main
sys.exit(main(sys.argv[1:]))
"""


# (signal, command, the stage that waits, status, what the one line says, output kept)
SIGNALS = [
    (signal.SIGTERM, "calibrate", "fit.calibrate", 143, "nothing was written", False),
    (signal.SIGINT, "simulate", "plot.plot_signal_and_spectrum", 130, "kept (complete)", True),
]


@pytest.mark.parametrize(("sig", "command", "stage", "status", "said", "kept"), SIGNALS,
                         ids=["sigterm-before-writing", "sigint-after-the-csv"])  # fmt: skip
def test_a_signal_stops_a_command_with_one_line(tree, sig, command, stage, status, said, kept):
    module, name = stage.split(".")
    out, png = tree / "out.x", tree / "out.png"
    argv = {
        "calibrate": ["calibrate", str(tree / "rec.csv"), "--whisker", PAPER],
        "simulate": ["simulate", "--duration", "0.5", "--plot", str(png)],
    }[command] + ["--out", str(out), "--json"]
    script = textwrap.dedent(_CHILD.format(module=module, name=name))
    child, lines, reached = start_child(script, argv, "READY")
    if not reached:
        pytest.fail("the child never got to the stage: " + "".join(lines))
    child.send_signal(sig)
    stdout, rest = child.communicate(timeout=60)
    assert child.returncode == status
    assert stdout == "" and "Traceback" not in rest
    name = signal.Signals(sig).name
    assert len(rest.strip().splitlines()) == 1
    assert rest.startswith(f"whiskerid {command}: interrupted ({name}); {said}")
    assert out.exists() == kept and not png.exists()
    assert not [p for p in tree.iterdir() if p.name.startswith(".")]  # no temporary file


# ------------------------------------------------------------------------ help text
def _commands(parser, prefix=""):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, f"{prefix} {name}".strip())
    if prefix:
        yield prefix, parser


COMMANDS = dict(_commands(build_parser()))
WRITERS_CMDS = ["simulate", "calibrate", "posterior", "dataset synth", "train", "evaluate",
                "classify", "demo"]  # fmt: skip


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_option_of_every_command_has_help(name):
    parser = COMMANDS[name]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            continue
        assert action.help and action.help.strip(), f"{name} {action.option_strings or action.dest}"
    text = parser.format_help()
    assert "(default: None)" not in text and "(default: False)" not in text
    for action in parser._actions:
        if action.required and action.option_strings:
            assert "default" not in parser._get_formatter()._get_help_string(action)
    if name in WRITERS_CMDS:
        force = next(a for a in parser._actions if "--force" in a.option_strings)
        assert "refused" in force.help


def test_the_writing_commands_are_all_known():
    assert set(WRITERS_CMDS) <= set(COMMANDS)


# ------------------------------------------------------------------------ records
@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("length_m = 0.06", "length_m = 1e9", "structure.length_m = 1000000000.0 is outside"),
        ("wire_density_kg_m3 = 8050.0", "wire_density_kg_m3 = 0.0", "100 .. 25000 kg/m^3"),
        ("tip_mass_kg = 0.0", "tip_mass_kg = 1e30", "tip_mass_kg = 1e+30 is outside"),
        ("wire_radius_m = 0.0005", "wire_radius_m = 0.005", "must be smaller than"),
        ("length_m = 0.06", "length_m = nan", "structure.length_m = nan"),
        ("shear_modulus_pa = 70000000000.0", "shear_modulus_pa = inf", "(a finite number)"),
    ],
    ids=["length-1e9", "density-0", "tip-mass-1e30", "wire-thicker-than-coil", "nan", "inf"],
)
def test_absurd_record_values_are_refused_naming_key_and_range(tmp_path, old, new, words):
    text = Path(PAPER).read_text()
    assert old in text
    path = tmp_path / "w.toml"
    path.write_text(text.replace(old, new))
    with pytest.raises(wi.RecordError, match=re.escape(words)):
        wi.load_record(path)


def test_a_record_needs_no_hall_table_when_nothing_reads_one(tmp_path):
    text = Path("fits/cantilever-aluminium-30cm.toml").read_text()
    head, rest = text.split("[sensor]")
    rest = rest[rest.index("\n[") :]  # the tables after [sensor]
    path = tmp_path / "accelerometer.toml"
    path.write_text(head + rest)
    rec = wi.load_record(path)
    assert rec.sensor_position_m == rec.structure.length_m  # read at the tip


# ------------------------------------------------------------------------ sample rates
def _stamped(tmp_path, t):
    y = 1e-3 * np.exp(-np.arange(t.size) / 200) * np.sin(np.arange(t.size) * 1.4)
    lines = ["t,deflection"] + [f"{a!r},{b!r}" for a, b in zip(t.tolist(), y.tolist(), strict=True)]
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


TIMES = {
    "all-zero": (np.zeros(400), "the time column holds no time"),
    "rounded-to-0.1-s": (np.round(np.arange(400) / 200, 1), "rounded to about 0.1 s"),
}


@pytest.mark.parametrize("command", ["calibrate", "posterior"])
@pytest.mark.parametrize("case", sorted(TIMES))
def test_timestamps_without_a_rate_are_one_line_errors(tmp_path, capsys, command, case):
    t, words = TIMES[case]
    rec = _stamped(tmp_path, t)
    extra = ["--whisker", PAPER, "--out", str(tmp_path / "c.toml")]
    if command == "posterior":
        extra = ["--fit", PAPER, "--out", str(tmp_path / "post")]
    assert main([command, str(rec), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and words in err and str(rec) in err


@pytest.mark.parametrize("case", sorted(TIMES))
def test_the_rate_finder_says_what_to_do(case):
    t, words = TIMES[case]
    with pytest.raises(wi.RecordingError, match=words):
        timestamp_rate(t, where="r.csv")


# ------------------------------------------------------------------------ posterior, end to end
def _read_until(stream, marker: str, limit_s: float = 240.0) -> str:
    """What a child's stderr holds up to ``marker`` (read in bytes: progress bars use '\\r')."""
    import select
    import time

    seen, end = b"", time.monotonic() + limit_s
    while marker.encode() not in seen and time.monotonic() < end:
        ready, _, _ = select.select([stream], [], [], 1.0)
        if ready:
            chunk = os.read(stream.fileno(), 4096)
            if not chunk:
                break
            seen += chunk
    return seen.decode(errors="replace")


@pytest.mark.slow  # a posterior in a child process: compiles, samples, is stopped, resumes
def test_posterior_stops_between_steps_and_resumes_only_on_the_same_data(tmp_path, capsys):
    for seed in (1, 2):
        sim = wi.simulate(wi.paper_record(), excitation="decay", tip_deflection_m=2e-3,
                          rate_hz=200.0, duration_s=2.0, noise_db=30.0, seed=seed)  # fmt: skip
        write_csv(tmp_path / f"rec{seed}.csv", sim)
    fit = tmp_path / "cal.toml"
    rec = str(tmp_path / "rec1.csv")
    assert main(["calibrate", rec, "--whisker", PAPER, "--out", str(fit), "--t-end", "1.8"]) == 0
    assert wi.load_record(fit).extra["fit"]["options"] == {"t_end": 1.8}
    capsys.readouterr()
    out = tmp_path / "post"
    argv = ["posterior", rec, "--fit", str(fit), "--out", str(out), "--walkers", "16"]
    cmd = [sys.executable, "-m", "whiskerid.cli", *argv, "--steps", "100000", "--json"]
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = _read_until(child.stderr, "it/s]")  # the progress bar, on stderr despite --json
    assert "data options from the fit record: --t-end 1.8" in seen
    child.send_signal(signal.SIGINT)
    stdout, rest = (b.decode() for b in child.communicate(timeout=120))
    assert child.returncode == 130
    assert stdout == "" and "Traceback" not in rest and "emcee" not in rest
    last = rest.strip().splitlines()[-1]
    assert last.startswith("whiskerid posterior: interrupted (SIGINT); kept")
    assert "continue it with --resume" in last
    # Another recording cannot continue this chain; the same one can.
    other = str(tmp_path / "rec2.csv")
    assert main(["posterior", other, *argv[2:], "--steps", "5", "--resume", "--quiet"]) == 2
    assert "run with other recordings" in capsys.readouterr().err
    assert main([*argv, "--steps", "5", "--resume", "--quiet", "--no-plots", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["diagnostics"]["steps"] > 5


def test_posterior_refuses_a_disk_too_full_for_its_chain(tree, capsys, monkeypatch):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 1000, 1000))
    argv = ["posterior", str(tree / "rec.csv"), "--fit", PAPER, "--out", str(tree / "new")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "MB free" in err and not (tree / "new").exists()


def test_posterior_resume_refuses_a_chain_that_does_not_say_its_data(tree, capsys):
    h5py = pytest.importorskip("h5py")
    chain = tree / "post" / "chain.h5"
    with h5py.File(chain, "w") as f:
        f.create_group("whiskerid")
    argv = ["posterior", str(tree / "rec.csv"), "--fit", PAPER, "--out", str(tree / "post")]
    assert main([*argv, "--resume"]) == 2
    assert "does not say which data" in capsys.readouterr().err


# ------------------------------------------------------------------------ progress, --quiet
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_has_quiet(name):
    parser = COMMANDS[name]
    if any(isinstance(a, argparse._SubParsersAction) for a in parser._actions):
        return  # a group (dataset, fleet): its commands are checked one by one
    assert "--quiet" in parser.format_help(), name


@pytest.mark.parametrize("quiet", [False, True])
def test_a_long_command_says_what_it_is_doing_unless_quiet(tmp_path, monkeypatch, capsys, quiet):
    import time

    import whiskerid.cli._calibrate as c
    from whiskerid.cli import _common, _progress

    def slow(args, *rest):
        _common.progress_step("fitting")
        time.sleep(0.1)
        _common.say("done")
        return {}

    monkeypatch.setattr(c, "_cmd_calibrate", slow)
    monkeypatch.setattr(_progress, "STATUS_DELAY_S", 0.0)  # where start_progress reads it
    argv = ["calibrate", "x.csv", "--whisker", PAPER, "--out", str(tmp_path / "o.toml")]
    assert main(argv + ["--quiet"] * quiet) == 0
    err = capsys.readouterr().err
    if quiet:
        assert err.strip() == "done"
    else:
        assert "whiskerid calibrate: fitting … 0 s" in err and err.strip().endswith("done")


def test_the_ticker_shows_steps_on_a_log_and_nothing_when_off(capsys):
    from whiskerid.cli._common import Ticker

    with Ticker("whiskerid demo", show=True, delay_s=0.0) as t:
        t.step("[4] calibration")
        t.say("a result")
    err = capsys.readouterr().err
    assert "whiskerid demo: [4] calibration … 0 s" in err and "a result" in err
    with Ticker("whiskerid demo", show=False, delay_s=0.0) as t:
        t.step("[4] calibration")
    assert capsys.readouterr().err == ""


def test_the_demo_ends_with_a_summary_of_its_results():
    from whiskerid.cli._demo_stages import summary_lines

    summary = {
        "whisker": "paper-whisker",
        "natural_frequencies_hz": [46.0, 288.2, 807.1],
        "calibration": {"status": "ok", "f1_hz": {"value": 45.99, "std": 0.004},
                        "zeta": {"value": 0.0399, "std": 0.0001}},
        "posterior": {"zeta": {"median": 0.04, "q16": 0.0399, "q84": 0.0401}, "converged": True},
        "classification": {"accuracy": 0.964},
        "stream": {"fraction_correct": 0.89, "windows": 18},
    }  # fmt: skip
    text = "\n".join(summary_lines(summary, Path("demo")))
    for expected in ("f1 = 45.990 ± 0.004 Hz", "calibration (ok)", "accuracy 0.964",
                     "89% of 18 windows", "converged"):  # fmt: skip
        assert expected in text, text
