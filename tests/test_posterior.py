"""Posteriors with emcee: log-probability, support, seeding, recovery, convergence flag,
HDF5 resume, CLI round trip, and (slow) interval coverage."""

import json
import math

import numpy as np
import pytest
from helpers import decay_recording

import whiskerid as wi
from whiskerid import posterior as P
from whiskerid.fit import recording_design
from whiskerid.posterior import _likelihood as L

F1, ZETA, NOISE, N = 48.0, 0.02, 0.05, 500


def decay(seed=0, n=N, f1=F1, zeta=ZETA, noise=NOISE):
    """A one-mode free decay at 1 kHz with slightly jittered timestamps."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0 + rng.uniform(0, 2e-4, n)
    w = 2 * np.pi * f1
    phase = rng.uniform(0, 2 * np.pi)
    y = 0.3 + np.exp(-zeta * w * t) * np.cos(w * math.sqrt(1 - zeta**2) * t + phase)
    return wi.Observation(t, y + noise * rng.standard_normal(n), name=f"decay-{seed}")


@pytest.fixture(scope="module")
def prob():
    return P.setup_posterior(wi.paper_record(), decay(0), n_modes=1)


def test_log_prob_matches_direct_computation(prob):
    """Marginal likelihood (QR in JAX) vs NumPy lstsq + slogdet, plus priors by hand."""
    z = prob.z0 + np.array([1e-4, 0.01, 0.02])
    m = prob.model
    problem = prob.args["problem"]
    theta = L._unravel(problem, m.marginal)(z[: m.n_theta])
    w = problem.whisker(theta)
    rec = problem.recordings[0]
    D, g = recording_design(rec, w, theta["recs"][0])
    D, y = np.asarray(D), np.asarray(rec.y) - np.asarray(g)
    n, k = D.shape
    coef = np.linalg.lstsq(D, y, rcond=None)[0]
    rss = np.sum((y - D @ coef) ** 2)
    ls = z[-1]
    loglik = (
        -(n - k) * ls
        - 0.5 * np.linalg.slogdet(D.T @ D)[1]
        - 0.5 * rss / np.exp(2 * ls)
        - 0.5 * (n - k) * np.log(2 * np.pi)
    )
    zeta = 0.95 / (1 + np.exp(-z[1]))
    f1 = float(w.natural_frequencies_hz[0])
    pr = prob.priors
    lp_zeta = -np.log(0.95) + np.log(zeta * (0.95 - zeta) / 0.95)
    lp_f1 = -np.log(f1) - np.log(np.log(pr["f1_hz"]["b"] / pr["f1_hz"]["a"])) + np.log(f1 / 2)
    lp_sig = -ls - np.log(np.log(10 / 1e-6)) + ls
    expected = loglik + lp_zeta + lp_f1 + lp_sig
    assert prob.log_prob(z)[0] == pytest.approx(expected, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("span", [10.0, 2e3, 1e6])
def test_sincos_equals_sin_and_cos(span):
    """The vectorisable sin/cos (posterior's decay columns) vs NumPy to rounding, grad exact."""
    import jax

    from whiskerid.fit._numerics._trig import sincos

    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-span, span, 20000), np.arange(-8, 9) * np.pi / 4, [0.0]])
    s, c = (np.asarray(v) for v in jax.jit(sincos)(x))
    np.testing.assert_allclose(s, np.sin(x), rtol=0, atol=4e-16 + 3e-16 * span * 2**-26)
    np.testing.assert_allclose(c, np.cos(x), rtol=0, atol=4e-16 + 3e-16 * span * 2**-26)
    ds = jax.vmap(jax.grad(lambda v: sincos(v)[0]))(x[:50])
    np.testing.assert_allclose(ds, np.cos(x[:50]), rtol=0, atol=4e-16)
    assert np.all(np.isnan(np.asarray(sincos(np.array([np.nan, np.inf]))[1])))


@pytest.mark.parametrize(("modes", "offsets"), [(1, None), (3, None), (2, (0.0, -4e-4, -8e-4))])
def test_fast_decay_columns_equal_the_calibration_design(modes, offsets):
    """The posterior's own free-decay design equals the calibration's (to rounding)."""
    w = wi.paper_record().whisker().with_modes(modes)
    t = np.sort(np.random.default_rng(1).uniform(0, 2.0, 700))
    rec = decay_recording(t, modes, offsets)
    D, g = recording_design(rec, w, {})
    cols, g2 = L._columns(rec, w, {})
    np.testing.assert_allclose(np.stack(cols, axis=1), D, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(g2, g)


def test_log_prob_support():
    p = P.setup_posterior(
        wi.paper_record(),
        decay(0),
        n_modes=1,
        prior={
            "zeta": {"dist": "uniform", "low": 0.0, "high": 0.05},
            "f1_hz": {"dist": "lognormal", "mu": math.log(48.0), "sigma": 0.1},
        },
    )
    z = np.tile(p.z0, (4, 1))
    z[1, 1] = float(np.log(0.1 / 0.85))  # zeta = 0.1 > 0.05
    z[2, -1] = np.log(100.0)  # sigma_rel = 100 > 10
    z[3, 0] = np.nan
    lp = p.log_prob(z)
    assert np.isfinite(lp[0])
    assert np.all(lp[1:] == -np.inf)
    with pytest.raises(P.PosteriorError):
        P.parse_prior({"zeta": {"dist": "uniform", "low": 1, "high": 0}})
    with pytest.raises(P.PosteriorError):
        P.parse_prior({"damping": {"dist": "normal", "mu": 0, "sigma": 1}})


def test_reproducible_by_seed(prob):
    a = P.run_sampler(prob, walkers=16, steps=60, seed=3).get_chain()
    b = P.run_sampler(prob, walkers=16, steps=60, seed=3).get_chain()
    c = P.run_sampler(prob, walkers=16, steps=60, seed=4).get_chain()
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_recovers_truth_and_reports_convergence(prob):
    post = P.summarize(prob, P.run_sampler(prob, walkers=32, steps=1800, seed=0), seed=0)
    for name, truth in (("zeta", ZETA), ("f1_hz", F1)):
        q = post.params[name]
        assert q["q2.5"] < truth < q["q97.5"], (name, q)
        assert q["ess"] > 100
    # this dataset's noise has a sample std of 0.0467 (the generator's 0.05 by chance -2.1 sd)
    assert post.params["sigma_1"]["q2.5"] < 0.0467 < post.params["sigma_1"]["q97.5"]
    d = post.diagnostics
    assert 0.2 < d["acceptance"] < 0.9
    assert d["converged"] == (d["steps"] >= d["steps_needed"])
    assert set(post.params["zeta"]) >= {"median", "q16", "q84", "q2.5", "q97.5", "tau", "ess"}
    table = post.record.extra["posterior"]
    assert table["params"]["zeta"]["median"] == post.params["zeta"]["median"]
    assert table["provenance"]["seed"] == 0
    import tomllib

    from whiskerid.model._record import record_from_dict

    again = record_from_dict(tomllib.loads(post.record.to_toml()))
    assert again.extra["posterior"]["converged"] == d["converged"]


@pytest.mark.slow  # two chains of 1500 steps, for a statistical comparison
def test_moves_sample_the_same_posterior_and_de_mixes_faster(prob):
    """DE (the default) and the stretch move (lmfit's) agree on ζ's mean and sd (Monte
    Carlo error ≈ 0.03 sd at these lengths); DE's τ is about a third of the stretch move's
    here (≈ 11 vs 36 steps), asserted below 0.6 of it."""
    posts = {
        m: P.summarize(prob, P.run_sampler(prob, walkers=32, steps=1500, seed=5, move=m), seed=5)
        for m in ("de", "stretch")
    }
    de, st = posts["de"].params["zeta"], posts["stretch"].params["zeta"]
    assert abs(de["mean"] - st["mean"]) < 0.2 * st["std"]
    assert de["std"] == pytest.approx(st["std"], rel=0.15)
    assert posts["de"].diagnostics["max_tau"] < 0.6 * posts["stretch"].diagnostics["max_tau"]
    assert posts["de"].provenance["move"] == "de"
    assert posts["stretch"].provenance["move"] == "stretch"
    with pytest.raises(P.PosteriorError, match="move must be one of"):
        P.run_sampler(prob, walkers=16, steps=5, move="hmc")


def test_short_run_is_not_converged(prob):
    post = P.summarize(prob, P.run_sampler(prob, walkers=16, steps=80, seed=1), seed=1)
    d = post.diagnostics
    assert d["converged"] is False
    assert "not converged" in d["message"]
    if d["steps_needed"] is not None:
        assert d["steps_needed"] > 80
        assert str(d["steps_needed"]) in d["message"]


def test_hdf5_resume_extends_chain(prob, tmp_path):
    path = tmp_path / "chain.h5"
    first = P.run_sampler(prob, walkers=16, steps=50, seed=2, backend=path).get_chain()
    more = P.run_sampler(prob, walkers=16, steps=30, seed=2, backend=path, resume=True)
    chain = more.get_chain()
    assert chain.shape == (80, 16, 3)
    np.testing.assert_array_equal(chain[:50], first)
    with pytest.raises(P.PosteriorError):
        P.run_sampler(prob, walkers=8, steps=5, seed=2, backend=path, resume=True)


def test_student_t_samples_the_nuisances():
    p = P.setup_posterior(wi.paper_record(), decay(0), n_modes=1, likelihood="student", nu=4)
    assert p.z0.size == 3 + 4  # log kappa, logit zeta, 4 linear coefficients, log sigma
    lp = p.log_prob(np.stack([p.z0, p.z0 + 1e-3]))
    assert np.all(np.isfinite(lp))
    with pytest.raises(P.PosteriorError):
        P.setup_posterior(wi.paper_record(), decay(0), likelihood="student", marginalize=True)


def test_cli_calibrate_then_posterior(tmp_path, capsys):
    from whiskerid.cli._main import main

    o = decay(5)
    csv = tmp_path / "decay.csv"
    wi.write_csv(csv, wi.Recording(o.t, {"deflection": o.y}))
    fit = tmp_path / "fit.toml"
    paper = str(wi.paper_record().save(tmp_path / "paper.toml"))
    argv = ["--t-start", "0", "--modes", "1"]
    assert main(["calibrate", str(csv), "--whisker", paper, "--out", str(fit), *argv]) == 0
    capsys.readouterr()
    out = tmp_path / "post"
    rc = main(
        [
            "posterior",
            str(csv),
            "--fit",
            str(fit),
            "--out",
            str(out),
            "--steps",
            "300",
            "--walkers",
            "16",
            "--seed",
            "1",
            "--t-start",
            "0",
            "--json",
        ]
    )
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    for name in ("zeta", "f1_hz", "kappa", "EI"):
        assert set(res["params"][name]) >= {"median", "q16", "q84", "q2.5", "q97.5", "tau"}
    assert {"tau", "acceptance", "ess", "converged"} <= set(res)
    assert res["converged"] is False
    assert res["provenance"]["move"] == "de"  # the default
    for f in ("posterior.toml", "chain.h5", "corner.png", "trace.png"):
        assert (out / f).stat().st_size > 0
    resume = ["--walkers", "16", "--steps", "50", "--resume", "--no-plots", "--t-start", "0"]
    assert (
        main(["posterior", str(csv), "--fit", str(fit), "--out", str(out), *resume, "--json"]) == 0
    )
    assert json.loads(capsys.readouterr().out)["diagnostics"]["steps"] == 350
    assert main(["posterior", str(csv), "--fit", str(fit), "--out", str(out), "--resume"]) == 2
    assert (
        main(["posterior", str(csv), "--fit", str(tmp_path / "nope.toml"), "--out", str(out)]) == 2
    )


@pytest.mark.slow
def test_coverage_small():
    """20 datasets: the 68 % and 90 % intervals of ζ cover the truth at roughly their rates."""
    hits68 = hits90 = 0
    n = 20
    for seed in range(n):
        post = P.sample_posterior(
            wi.paper_record(), decay(100 + seed), n_modes=1, walkers=24, steps=800, seed=seed
        )
        x = post.samples[:, post.names.index("zeta")]
        lo68, hi68, lo90, hi90 = np.percentile(x, [16, 84, 5, 95])
        hits68 += lo68 < ZETA < hi68
        hits90 += lo90 < ZETA < hi90
    assert 0.4 <= hits68 / n <= 0.95
    assert 0.7 <= hits90 / n <= 1.0


@pytest.mark.slow
def test_static_test_pins_ei():
    """A static test (tip force vs deflection) in the log-probability pins EI: the posterior
    of EI covers the truth and its width is the static fit's own uncertainty."""
    rec = wi.paper_record()
    l, ei = rec.structure.length_m, float(rec.whisker().EI)
    rng = np.random.default_rng(7)
    force = np.linspace(0.0, 2e-3, 12)  # N
    compliance = l**3 / (3 * ei)  # tip deflection per tip force
    noise = 0.01 * compliance * force.max()  # 1 % of the largest deflection
    defl = 1e-5 + compliance * force + noise * rng.standard_normal(force.size)
    static = wi.StaticTest(force, defl)
    post = P.sample_posterior(rec, decay(0), static=static, n_modes=1, walkers=32, steps=1000)
    q = post.params["EI"]
    # Expected 1σ of EI from least squares of δ on F (σ estimated from the residuals, as the
    # calibration does): σ_EI/EI = σ_slope/slope.
    A = np.stack([np.ones_like(force), force], axis=1)
    coef, rss, *_ = np.linalg.lstsq(A, defl, rcond=None)
    s2 = rss[0] / (force.size - 2)
    sd_slope = math.sqrt(s2 / np.sum((force - force.mean()) ** 2))
    sd_ei = ei * sd_slope / coef[1]
    assert q["q2.5"] < ei < q["q97.5"], (q, ei)
    assert abs(q["median"] - ei) < 3 * sd_ei
    assert 0.7 < q["std"] / sd_ei < 1.4, (q["std"], sd_ei)
    assert "log_EI" in post.chain_names
