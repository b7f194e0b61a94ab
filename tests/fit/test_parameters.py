"""Parameters a user fixes or bounds: ``--fix``, ``--bounds``, :class:`whiskerid.fit.Parameters`."""

import json

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.cli import main
from whiskerid.fit import CalibrationError, Parameters, observations_from_file

PAPER = "fits/paper-whisker.toml"


@pytest.fixture(autouse=True)
def _repo_root(monkeypatch, request):
    monkeypatch.chdir(request.config.rootpath)


@pytest.fixture(scope="module")
def pluck(tmp_path_factory, request):
    """A simulated 5 s pluck of the paper whisker (ζ = 0.04, f_1 ≈ 46 Hz), ADC codes."""
    path = tmp_path_factory.mktemp("pluck") / "sim.csv"
    argv = ["simulate", "--whisker", str(request.config.rootpath / PAPER), "--model", "exact",
            "--excitation", "decay", "--tip-deflection", "2e-3", "--rate", "200",
            "--duration", "5", "--observable", "adc", "--noise-db", "30", "--seed", "5",
            "--out", str(path)]  # fmt: skip
    assert main(argv) == 0
    return path


def _truth_f1():
    return float(wi.paper_whisker().natural_frequencies_hz[0])


def test_a_fixed_zeta_stays_exactly_at_its_value_and_f1_is_still_recovered(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    cal = wi.calibrate(record, obs, parameters=Parameters().fix("zeta", 0.035))
    assert cal.ok
    assert cal.params["zeta"]["value"] == 0.035  # exactly: the model reads the value
    assert cal.params["zeta"]["std"] == 0.0 and cal.params["zeta"]["source"].startswith("fixed")
    # a ζ 12 % off the truth (0.04) moves f_1 by far less than 0.1 %
    assert cal.params["f1_hz"]["value"] == pytest.approx(_truth_f1(), rel=1e-3)
    assert 0 < cal.params["f1_hz"]["std"] < 0.1
    assert cal.diagnostics["parameters"] == {"zeta": {"fixed": 0.035, "value": 0.035}}


def test_a_bound_that_excludes_the_truth_ends_at_the_bound_and_its_1sigma_is_refused(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    f1 = _truth_f1()  # about 46 Hz: the interval below stops 1 Hz short of it
    cal = wi.calibrate(record, obs, parameters=Parameters().bound("f1_hz", f1 - 6, f1 - 1))
    got = cal.params["f1_hz"]
    assert got["value"] == pytest.approx(f1 - 1, abs=0.01)
    assert got["std"] is None and "upper bound" in got["source"]
    assert cal.params["kappa"]["std"] is None  # what follows from f_1 is refused with it
    assert cal.params["zeta"]["std"] > 0  # ζ is still fitted
    entry = cal.diagnostics["parameters"]["f1_hz"]
    assert entry["at_bound"] and "refused" in entry["std_refused"]
    assert any("upper bound" in w for w in cal.warnings)


def test_a_bound_that_holds_the_truth_changes_nothing_that_matters(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    free = wi.calibrate(record, obs)
    cal = wi.calibrate(record, obs, parameters=Parameters().bound("zeta", 0.01, 0.1))
    assert not cal.diagnostics["parameters"]["zeta"]["at_bound"]
    for k in ("f1_hz", "zeta"):
        assert cal.params[k]["value"] == pytest.approx(free.params[k]["value"], rel=1e-6)
        assert cal.params[k]["std"] == pytest.approx(free.params[k]["std"], rel=1e-3)
    assert "parameters" not in free.diagnostics and free.problem.limits == ()


@pytest.mark.slow
def test_cli_fix_and_bounds_round_trip_into_json_and_the_record(pluck, tmp_path, capsys):
    out = tmp_path / "cal.toml"
    argv = ["calibrate", str(pluck), "--whisker", PAPER, "--out", str(out), "--json",
            "--fix", "zeta=0.04", "--bounds", "f1_hz=40:50"]  # fmt: skip
    assert main(argv) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["params"]["zeta"] == {"value": 0.04, "std": 0.0}
    assert js["diagnostics"]["parameters"]["zeta"] == {"fixed": 0.04, "value": 0.04}
    f1 = js["diagnostics"]["parameters"]["f1_hz"]
    assert f1["bounds"] == [40.0, 50.0] and f1["at_bound"] is False
    assert np.isfinite(js["params"]["f1_hz"]["std"]) and js["params"]["f1_hz"]["std"] > 0
    fit = wi.load_record(out).extra["fit"]
    assert fit["parameters"]["zeta"]["fixed"] == 0.04
    assert fit["params"]["zeta"]["std"] == 0.0


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--fix", "zeta=abc"], "--fix zeta: 'abc' is not a number"),
        (["--fix", "zeta"], "--fix 'zeta': give NAME=VALUE"),
        (["--fix", "zeta=nan"], "--fix zeta: 'nan' is not a finite number"),
        (["--fix", "kappa=3"], "'kappa' is not a parameter one can fix"),
        (["--fix", "zeta=2"], "--fix zeta: 2 is outside the plausible range"),
        (["--fix", "f1_hz=-5"], "--fix f1_hz: -5 is outside the plausible range"),
        (["--bounds", "f1_hz=50:40"], "--bounds f1_hz: the lower 50 must be below the upper 40"),
        (["--bounds", "f1_hz=40:40"], "--bounds f1_hz: the lower 40 must be below"),
        (["--bounds", "f1_hz=40"], "--bounds 'f1_hz=40': give NAME=LO:HI"),
        (["--bounds", "zeta=0:0.1"], "--bounds zeta: 0:0.1 is outside the plausible range"),
        (["--fix", "zeta=0.03", "--bounds", "zeta=0.01:0.1"], "zeta is fixed or bounded twice"),
        (["--fix", "zeta=0.03", "--model", "nonlinear"], "--fix/--bounds apply to the linear"),
    ],
)
def test_bad_fix_or_bounds_exit_2_naming_the_flag_and_value(flags, needle, tmp_path, capsys):
    rec = tmp_path / "rec.csv"
    rec.write_text("t,deflection\n0,0\n")  # refused before the recording is read
    argv = ["calibrate", str(rec), "--whisker", PAPER, "--out", str(tmp_path / "o.toml"), *flags]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_parameters_chain_replace_and_describe():
    p = Parameters().fix("zeta", 0.03).bound("f1_hz", 40, 50).bound("zeta", 0.01, 0.1)
    assert p.describe() == {"f1_hz": {"bounds": [40.0, 50.0]}, "zeta": {"bounds": [0.01, 0.1]}}
    with pytest.raises(CalibrationError, match="lower 5 must be below the upper 4"):
        Parameters().bound("zeta", 5, 4)
    with pytest.raises(CalibrationError, match="not a parameter"):
        Parameters().fix("EI", 1.0)


def test_limits_are_refused_with_the_nonlinear_model(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    with pytest.raises(CalibrationError, match="linear model"):
        wi.calibrate(record, obs, model="nonlinear", parameters=Parameters().fix("zeta", 0.03))


def test_the_profile_interval_matches_the_1sigma_on_a_clean_pluck(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    prof = wi.fit.profile_interval(record, obs, "zeta", points=11, span=3.0)
    v, s = prof["value"], prof["std"]
    assert prof["lower"] < v < prof["upper"]
    # nearly linear in ζ here: each half-width within 15 % of the covariance's 1σ
    for half in (v - prof["lower"], prof["upper"] - v):
        assert half == pytest.approx(s, rel=0.15)
    assert min(prof["delta_chi2"]) == pytest.approx(0.0, abs=1e-6)
    assert max(prof["delta_chi2"]) > 4  # ± 3σ reaches well past Δχ² = 1


@pytest.mark.slow
def test_cli_profile_writes_json_and_a_figure(pluck, tmp_path, capsys):
    png = tmp_path / "profile.png"
    argv = ["calibrate", str(pluck), "--whisker", PAPER, "--out", str(tmp_path / "c.toml"),
            "--json", "--profile", "f1_hz", "--profile-plot", str(png)]  # fmt: skip
    assert main(argv) == 0
    js = json.loads(capsys.readouterr().out)
    prof = js["profile"]
    assert prof["name"] == "f1_hz" and prof["lower"] < prof["value"] < prof["upper"]
    assert png.read_bytes()[:4] == b"\x89PNG" and js["profile_plot"] == str(png)


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--profile", "EI"], "--profile 'EI': give one of f1_hz, zeta"),
        (["--profile-plot", "p.png"], "--profile-plot p.png: give --profile NAME too"),
        (["--profile", "zeta", "--fix", "f1_hz=46"], "--profile zeta: profiles the plain"),
    ],
)
def test_bad_profile_flags_exit_2(flags, needle, tmp_path, capsys):
    rec = tmp_path / "rec.csv"
    rec.write_text("t,deflection\n0,0\n")
    argv = ["calibrate", str(rec), "--whisker", PAPER, "--out", str(tmp_path / "o.toml"), *flags]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1


def test_limits_are_refused_with_added_masses(pluck):
    record = wi.load_record(PAPER)
    obs = observations_from_file(pluck, record)
    with pytest.raises(CalibrationError, match="without added masses"):
        wi.calibrate(record, obs, added_mass=[None] * len(obs),
                     parameters=Parameters().fix("zeta", 0.03))  # fmt: skip
