"""``calibrate --free-modes``: refusals, the record's free modes, simulate and posterior."""

import contextlib
import io
import json

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli import main
from whiskerid.fit._nonlinear._free_modes import free_modes_table
from whiskerid.model import nonlinear_coefficients

PAPER = "fits/paper-whisker.toml"


@pytest.fixture(autouse=True)
def _repo_root(monkeypatch, request):
    monkeypatch.chdir(request.config.rootpath)


def _csv(path, t, y, col="voltage"):
    lines = [f"t,{col}"] + [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, y, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        ([], "--model nonlinear"),
        (["--model", "nonlinear", "--modes", "1"], "--modes 2 or more"),
        (["--model", "auto", "--excitation", "sine", "--fb", "40"], "free decays only"),
        (["--model", "nonlinear", "--signal-col", "hall_a,hall_b"], "one plane"),
    ],
)
def test_free_modes_refused_where_they_do_not_apply(tmp_path, capsys, extra, needle):
    t = np.arange(400) / 860.0
    rec = _csv(tmp_path / "p.csv", t, np.exp(-9 * t) * np.cos(2 * np.pi * 46 * t))
    out = tmp_path / "out.toml"
    argv = ["calibrate", str(rec), "--whisker", PAPER, "--out", str(out), "--free-modes"]
    assert main([*argv, *extra, "--json"]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert cap.out == "" and "\n" not in err and err.startswith("whiskerid calibrate: error:")
    assert "--free-modes" in err and needle in err, err
    assert not out.exists()


def test_the_library_refuses_free_modes_too():
    from whiskerid.fit import CalibrationError, Observation

    record = wi.load_record(PAPER)
    t = np.arange(200) / 860.0
    obs = Observation(t, np.exp(-9 * t) * np.cos(2 * np.pi * 46 * t), observable="deflection")
    with pytest.raises(CalibrationError, match="--model nonlinear"):
        wi.calibrate(record, obs, free_modes=True)
    with pytest.raises(CalibrationError, match="--modes 2 or more"):
        wi.calibrate(record, obs, model="nonlinear", n_modes=1, free_modes=True)


def _free_mode_record(tmp_path, f2_hz, zeta_2):
    """The paper record with a nonlinear fit's table holding one free mode, saved and read."""
    record = wi.load_record(PAPER)
    params = {"f2_hz": {"value": f2_hz, "std": 0.01}, "zeta_2": {"value": zeta_2, "std": 1e-4}}
    f1 = float(record.whisker().natural_frequencies_hz[0])
    nl = {"f0_hz": f1, "zeta0": 0.03, "gamma_per_m2": 10.0, "quadratic_per_m": 0.0,
          "coulomb_m_s2": 0.0, "free_modes": free_modes_table(params, 2)}  # fmt: skip
    fit = {"model": "nonlinear", "status": "ok", "n_modes": 2, "nonlinear": nl}
    path = tmp_path / "free.toml"
    record.replace(extra={**record.extra, "fit": fit}).save(path)
    return wi.load_record(path)


def test_the_record_keeps_the_free_modes_and_the_pluck_plays_them(tmp_path):
    """Saved and read back, the table gives the fitted f2, zeta_2 exactly; the pluck's mode 2
    (as ``simulate`` builds it from the record) rings at the free f2, 4 % (11 Hz) above the
    beam's, and decays at zeta_2 (the slow test simulates and refits the whole record)."""
    from whiskerid.model import pluck
    from whiskerid.model._nonlinear import _linear_modes

    record = wi.load_record(PAPER)
    f2_beam = float(record.whisker().natural_frequencies_hz[1])
    f2, z2 = 1.04 * f2_beam, 0.004
    rec = _free_mode_record(tmp_path, f2, z2)
    table = rec.extra["fit"]["nonlinear"]["free_modes"]
    assert table == {"f_hz": [f2], "f_std_hz": [0.01], "zeta": [z2], "zeta_std": [1e-4]}
    coef = nonlinear_coefficients(rec)
    assert coef["free_f_hz"] == (f2,) and coef["free_zeta"] == (z2,)
    w = rec.whisker()
    t = np.arange(4000) / 20_000.0
    q2 = np.asarray(_linear_modes(w, t, pluck(w, 1e-3), coef).q[:, 1])
    up = np.flatnonzero((q2[:-1] < 0) & (q2[1:] >= 0))  # upward zero crossings
    ti = t[up] - q2[up] / (q2[up + 1] - q2[up]) * (t[1] - t[0])
    f_seen = (ti.size - 1) / (ti[-1] - ti[0])
    assert abs(f_seen / f2 - 1) < 1e-3 < abs(f_seen / f2_beam - 1), (f_seen, f2, f2_beam)
    peaks = np.abs(q2[: 20_000 // int(f2)]).max(), np.abs(q2[-(20_000 // int(f2)) :]).max()
    rate = np.log(peaks[0] / peaks[1]) / (t[-1] - 0.5 / f2)
    assert rate == pytest.approx(2 * np.pi * f2 * z2, rel=0.05)


def test_posterior_refuses_a_free_mode_record(tmp_path):
    from whiskerid.fit import Observation
    from whiskerid.posterior import PosteriorError, setup_posterior

    rec = _free_mode_record(tmp_path, 300.0, 0.003)
    t = np.arange(200) / 860.0
    obs = Observation(t, np.exp(-9 * t) * np.cos(2 * np.pi * 46 * t), observable="deflection")
    with pytest.raises(PosteriorError, match="free higher modes"):
        setup_posterior(rec, obs)


@pytest.mark.slow
def test_calibrate_free_modes_then_simulate_the_record_and_refit(tmp_path):
    """A SciPy nonlinear pluck plus a second mode 4 % above the beam's: ``calibrate --model
    nonlinear --free-modes --json`` reports f2, zeta_2 and a white residual spectrum at both
    modes, and stores them; ``simulate`` from that record and a refit recover the record's
    f2 and zeta_2 by their 1-sigma."""
    from helpers import nonlinear_pluck

    record, obs, _ = nonlinear_pluck(seed=2)
    f2 = 1.04 * float(record.whisker().with_modes(2).natural_frequencies_hz[1])
    z2, t = 0.003, obs.t
    wd = 2 * np.pi * f2 * np.sqrt(1 - z2**2)
    y = obs.y + 0.3 * np.std(obs.y) * np.exp(-z2 * 2 * np.pi * f2 * t) * np.cos(wd * t + 0.7)
    whisker = tmp_path / "w.toml"
    record.save(whisker)

    def fit(csv, out, *start):
        argv = ["calibrate", str(csv), "--whisker", str(whisker), "--out", str(out), *start,
                "--model", "nonlinear", "--free-modes", "--json", "--quiet"]  # fmt: skip
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main(argv) == 0
        return json.loads(buf.getvalue())

    js = fit(_csv(tmp_path / "p.csv", t, y), tmp_path / "c.toml", "--t-start", str(t[0]))
    p = js["params"]
    assert js["status"] == "ok" and js["model"] == "nonlinear"
    assert abs(p["f2_hz"]["value"] - f2) < 3 * p["f2_hz"]["std"], p["f2_hz"]
    (spec,) = js["diagnostics"]["residual_spectrum"]
    assert len(spec["bands"]) == 2 and spec["white"], spec
    table = wi.load_record(tmp_path / "c.toml").extra["fit"]["nonlinear"]["free_modes"]
    assert table["f_hz"] == [p["f2_hz"]["value"]] and table["zeta"] == [p["zeta_2"]["value"]]
    sim = tmp_path / "s.csv"
    assert main(["simulate", "--whisker", str(tmp_path / "c.toml"), "--excitation", "decay",
                 "--tip-deflection", "2e-3", "--rate", "860", "--duration", "0.5",
                 "--observable", "voltage", "--noise-db", "40", "--seed", "3", "--out", str(sim),
                 "--quiet"]) == 0  # fmt: skip
    q = fit(sim, tmp_path / "c2.toml")["params"]
    for name, k in (("f2_hz", "f_hz"), ("zeta_2", "zeta")):
        assert abs(q[name]["value"] - table[k][0]) < 3 * q[name]["std"], (name, q[name], table)
