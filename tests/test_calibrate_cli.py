"""``whiskerid calibrate`` on the command line: round trip from ``simulate``, bad input."""

import json

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli import main

PAPER = "fits/paper-whisker.toml"


@pytest.fixture(autouse=True)
def _repo_root(monkeypatch, request):
    monkeypatch.chdir(request.config.rootpath)


def _csv(path, t, y, col="deflection", extra=""):
    lines = [extra + f"t,{col}"] + [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, y, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
def test_simulate_then_calibrate_recovers_the_simulated_whisker(tmp_path, capsys):
    sim = tmp_path / "sim.csv"
    assert main(["simulate", "--whisker", PAPER, "--model", "exact", "--excitation", "decay",
                 "--tip-deflection", "2e-3", "--rate", "200", "--duration", "10",
                 "--observable", "adc", "--noise-db", "30", "--seed", "5",
                 "--out", str(sim)]) == 0  # fmt: skip
    capsys.readouterr()
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(sim), "--whisker", PAPER, "--out", str(out), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    truth = wi.paper_whisker()
    assert js["status"] == "ok"
    assert {"f1_hz", "zeta", "kappa", "EI"} <= set(js["params"]) and "C" not in js["params"]
    f1 = float(truth.natural_frequencies_hz[0])
    assert js["params"]["f1_hz"]["value"] == pytest.approx(f1, rel=1e-3)
    assert js["params"]["zeta"]["value"] == pytest.approx(0.04, rel=0.03)
    assert js["params"]["EI"]["value"] == pytest.approx(float(truth.EI), rel=2e-3)
    rec = wi.load_record(out)
    fit = rec.extra["fit"]
    assert fit["status"] == "ok" and len(fit["data_files"][0]["sha256"]) == 64
    assert rec.zeta == pytest.approx(js["params"]["zeta"]["value"])
    assert float(rec.whisker().natural_frequencies_hz[0]) == pytest.approx(
        js["params"]["f1_hz"]["value"], rel=1e-9
    )


def _bad_inputs(tmp_path):
    t = np.arange(200) / 200.0
    y = np.sin(2 * np.pi * 40 * t) * np.exp(-3 * t)
    nan = y.copy()
    nan[50] = np.nan
    dup = t.copy()
    dup[20] = dup[19]
    dec = t.copy()
    dec[30] = dec[28]
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("[structure]\nkind = 'coil'\n")
    good = _csv(tmp_path / "good.csv", t, y)
    return {
        "nan": ([str(_csv(tmp_path / "nan.csv", t, nan))], "non-finite"),
        "inf": ([str(_csv(tmp_path / "inf.csv", t, np.where(t > 0.5, np.inf, y)))], "non-finite"),
        "duplicate": ([str(_csv(tmp_path / "dup.csv", dup, y))], "duplicate timestamp"),
        "decreasing": ([str(_csv(tmp_path / "dec.csv", dec, y))], "decreasing timestamp"),
        "few": ([str(_csv(tmp_path / "few.csv", t[:5], y[:5]))], "samples"),
        "missing column": ([str(good), "--signal-col", "volts"], "no column 'volts'"),
        "missing time": ([str(good), "--time-col", "time"], "no time column"),
        "missing file": ([str(tmp_path / "nope.csv")], "no such file"),
        "bad record": ([str(good), "--whisker", str(bad_toml)], "bad.toml"),
        "unknown observable": ([str(_csv(tmp_path / "sig.csv", t, y, col="s"))], "--observable"),
        "sine without fb": ([str(good), "--excitation", "sine"], "--fb"),
    }


@pytest.mark.parametrize(
    "case",
    ["nan", "inf", "duplicate", "decreasing", "few", "missing column", "missing time",
     "missing file", "bad record", "unknown observable", "sine without fb"],
)  # fmt: skip
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    argv, needle = _bad_inputs(tmp_path)[case]
    out = tmp_path / "out.toml"
    if "--whisker" not in argv:
        argv = [*argv, "--whisker", PAPER]
    assert main(["calibrate", *argv, "--out", str(out), "--json"]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert cap.out == "" and "\n" not in err and err.startswith("whiskerid calibrate: error:")
    assert needle in err
    assert not out.exists()
