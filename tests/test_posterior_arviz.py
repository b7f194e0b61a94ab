"""ArviZ: InferenceData written by ``posterior --netcdf``, R-hat and ESS across ``--chains``,
the posterior-predictive draws, and the posterior beside its calibration (warnings repeated,
width ratios)."""

import json
import math

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.posterior import calibration_agreement

az = pytest.importorskip("arviz")

F1, ZETA, NOISE, N = 48.0, 0.02, 0.05, 400


def decay_csv(path, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 1000.0 + rng.uniform(0, 2e-4, N)
    w = 2 * np.pi * F1
    y = 0.3 + np.exp(-ZETA * w * t) * np.cos(w * math.sqrt(1 - ZETA**2) * t + 0.7)
    y = y + NOISE * rng.standard_normal(N)
    wi.write_csv(path, wi.Recording(t, {"deflection": y}))
    return path


@pytest.mark.slow
def test_netcdf_with_chains_opens_in_arviz(tmp_path, capsys):
    from whiskerid.cli._main import main

    csv = decay_csv(tmp_path / "decay.csv")
    fit = tmp_path / "fit.toml"
    paper = str(wi.paper_record().save(tmp_path / "paper.toml"))
    argv = ["--t-start", "0", "--modes", "1"]
    assert main(["calibrate", str(csv), "--whisker", paper, "--out", str(fit), *argv]) == 0
    capsys.readouterr()
    nc = tmp_path / "run.nc"
    run = ["posterior", str(csv), "--fit", str(fit), "--out", str(tmp_path / "post"),
           "--steps", "250", "--walkers", "8", "--chains", "3", "--seed", "2",
           "--t-start", "0", "--netcdf", str(nc), "--json"]  # fmt: skip
    assert main(run) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["netcdf"] == str(nc)
    assert (tmp_path / "post" / "predictive.png").stat().st_size > 0

    idata = az.from_netcdf(nc)
    assert {"posterior", "sample_stats", "observed_data", "posterior_predictive"} <= set(
        idata.groups()
    )
    post = idata.posterior
    assert post.sizes["chain"] == 3 and post.sizes["draw"] > 100
    assert {"f1_hz", "zeta", "kappa", "sigma_1"} <= set(post.data_vars)
    assert set(idata.sample_stats.data_vars) >= {"lp", "acceptance_rate"}
    assert idata.sample_stats["lp"].shape == post["f1_hz"].shape
    acc = idata.sample_stats["acceptance_rate"].values
    assert np.all((acc > 0) & (acc < 1))
    assert idata.observed_data["y_1"].shape == (N,)
    pp = idata.posterior_predictive["y_1"]
    assert pp.shape[0] == 3 and pp.shape[2] == N
    # the data sit inside the predictive band about as often as the band says
    lo, hi = np.percentile(pp.values.reshape(-1, N), [5, 95], axis=0)
    y = idata.observed_data["y_1"].values
    assert 0.8 < np.mean((y >= lo) & (y <= hi)) < 0.97
    assert abs(float(post["f1_hz"].median()) - F1) < 0.05

    # R-hat and ESS: ArviZ's on the file equal what the run reported
    rhat = az.rhat(idata)
    ess = az.ess(idata, method="bulk")
    for name in ("f1_hz", "zeta"):
        assert rhat[name].shape == ()
        assert 0.99 < float(rhat[name]) < 1.1
        assert float(ess[name]) > 50
        assert res["rhat"][name] == pytest.approx(float(rhat[name]), rel=1e-9)
        assert res["ess_bulk"][name] == pytest.approx(float(ess[name]), rel=1e-9)
        assert res["params"][name]["ess_tail"] > 50
    assert res["diagnostics"]["chains"] == 3
    assert set(res["width_ratio"]) >= {"f1_hz", "zeta"}
    assert all(r > 0 for r in res["width_ratio"].values())
    # a linear decay in white noise: the posterior is as wide as calibrate's white-noise 1σ
    for name, r in res["calibration"]["width_ratio_white"].items():
        assert 0.7 < r < 1.4, (name, r)

    # --resume continues every chain (and replaces the NetCDF); other --chains are refused
    more = [*run[:6], "--steps", "20", *run[8:], "--resume", "--no-plots"]
    assert main(more) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["diagnostics"]["steps"] == 270 and res["diagnostics"]["chains"] == 3
    assert az.from_netcdf(nc).posterior.sizes["chain"] == 3
    more[more.index("--chains") + 1] = "2"
    assert main(more) == 2
    assert "chains: then 3, now 2" in capsys.readouterr().err

    # an existing NetCDF is refused without --force
    run[run.index("--out") + 1] = str(tmp_path / "post2")
    assert main(run) == 2
    assert "--netcdf" in capsys.readouterr().err


def test_calibration_warnings_repeated_and_narrow_widths_flagged():
    rec = wi.paper_record()
    fit = {
        "status": "check",
        "warnings": ["residual-correlated: the residuals are not white"],
        "params": {"f1_hz": {"value": 46.0, "std": 0.01}, "zeta": {"value": 0.04, "std": 1e-4}},
    }
    rec = rec.replace(extra={**rec.extra, "fit": fit})
    params = {
        "f1_hz": {"q16": 45.999, "q84": 46.001},  # half-width 0.001: 10x narrower
        "zeta": {"q16": 0.0399, "q84": 0.0401},  # half-width 1e-4: the same
    }
    out = calibration_agreement(rec, params)
    assert out["status"] == "check"
    assert out["width_ratio"]["f1_hz"] == pytest.approx(0.1)
    assert out["width_ratio"]["zeta"] == pytest.approx(1.0)
    assert out["warnings"][0] == "calibration: status check"
    assert out["warnings"][1] == "calibration: residual-correlated: the residuals are not white"
    narrow = [w for w in out["warnings"] if "narrower" in w]
    assert len(narrow) == 1 and "(f1_hz 0.1x)" in narrow[0] and "--t-end" not in narrow[0]
    # a record without a calibration: nothing to repeat or compare
    assert calibration_agreement(wi.paper_record(), params)["warnings"] == []
    # the layers of the 1-sigma, from the calibration the posterior ran
    layers = {"f1_hz": {"std": 0.01, "std_white": 0.001, "std_without_model_error": 0.004}}
    out = calibration_agreement(wi.paper_record(), params, layers)
    assert out["width_ratio"]["f1_hz"] == pytest.approx(0.1)
    assert out["width_ratio_white"]["f1_hz"] == pytest.approx(1.0)
    assert out["width_ratio_sandwich"]["f1_hz"] == pytest.approx(0.25)
    assert "--t-end" in out["warnings"][-1]  # narrower than the sandwich too: the hint
