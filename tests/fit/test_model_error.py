"""The model-error term of an amplitude-averaged linear fit (``fit._model_error``): the bias
estimate is the difference of the linear and the augmented least-squares estimates, its 1σ
matches its scatter, and the term reaches f1, ζ and what derives from κ."""

from types import SimpleNamespace

import numpy as np
import pytest

from whiskerid.fit._choice import _model_error as ME


def test_step_map_is_the_difference_of_the_two_fits_and_its_sigma_its_scatter():
    """y = Jθ + Zγ + e: the step ``Xᵀr`` from the J-only residuals equals (augmented −
    J-only) estimates exactly, and ``σ√ΣX²`` is the spread of that difference over noise
    draws (a Hausman difference: its variance is the difference of the two variances)."""
    rng = np.random.default_rng(0)
    n, sigma = 400, 0.3
    t = np.linspace(0, 1, n)
    jac = np.stack([np.ones(n), t, np.sin(7 * t)], axis=1)
    z = np.stack([t**2, np.cos(5 * t) * t], axis=1)
    a = np.concatenate([jac, z], axis=1)
    x = ME.step_map(jac, z, [1, 2])
    diffs = []
    for _ in range(1000):
        y = jac @ [1.0, -2.0, 0.5] + z @ [0.4, -0.1] + rng.normal(0, sigma, n)
        small, *_ = np.linalg.lstsq(jac, y, rcond=None)
        full, *_ = np.linalg.lstsq(a, y, rcond=None)
        r = jac @ small - y  # the residual convention of the fit (model − data)
        np.testing.assert_allclose(x.T @ r, full[[1, 2]] - small[[1, 2]], atol=1e-9)
        diffs.append(full[[1, 2]] - small[[1, 2]])
    diffs = np.array(diffs)
    predicted = sigma * np.sqrt(np.sum(x**2, axis=0))
    np.testing.assert_allclose(np.std(diffs, axis=0), predicted, rtol=0.08)
    # and it is the difference of the two fits' variances
    var_full = np.diag(np.linalg.inv(a.T @ a))[[1, 2]]
    var_small = np.diag(np.linalg.inv(jac.T @ jac))[[1, 2]]
    np.testing.assert_allclose(predicted**2, sigma**2 * (var_full - var_small), rtol=1e-8)


def _fake_cal():
    params = {
        "f1_hz": {"value": 46.0, "std": 0.002, "source": "fit"},
        "f2_hz": {"value": 288.0, "std": 0.0125, "source": "fit"},
        "kappa": {"value": 10.0, "std": 8.7e-4, "source": "fit"},
        "zeta": {"value": 0.03, "std": 1e-4, "source": "fit"},
        "EI": {"value": 2e-6, "std": 1.7e-10, "source": "derived from kappa and rho_a (geometry)"},
    }
    fit = {"params": {k: dict(v) for k, v in params.items()}, "status": "ok"}
    return SimpleNamespace(params=params, record=SimpleNamespace(extra={"fit": fit}),
                           warnings=[], diagnostics={}, status="ok")  # fmt: skip


def test_model_error_reaches_f1_zeta_and_what_derives_from_kappa():
    cal = _fake_cal()
    me = {"preferred": True, "terms": ["cubic"], "ln_n": 6.0, "bic_gain": 2.4,
          "f1_hz": {"bias": 0.008, "std": 0.006}, "zeta": {"bias": 0.0, "std": 2e-4}}  # fmt: skip
    ME.apply_model_error(cal, me)
    rel = 0.01 / 46.0  # hypot(0.008, 0.006) Hz
    p = cal.params
    assert p["f1_hz"]["std"] == pytest.approx(np.hypot(0.002, 0.01))
    assert p["f2_hz"]["std"] == pytest.approx(np.hypot(0.0125, rel * 288.0))
    assert p["kappa"]["std"] == pytest.approx(np.hypot(8.7e-4, 2 * rel * 10.0))
    assert p["EI"]["std"] == pytest.approx(np.hypot(1.7e-10, 2 * rel * 2e-6))
    assert p["zeta"]["std"] == pytest.approx(np.hypot(1e-4, 2e-4))
    assert p["f1_hz"]["std_without_model_error"] == 0.002
    assert cal.record.extra["fit"]["params"]["f1_hz"]["std"] == p["f1_hz"]["std"]
    assert cal.status == "ok" and "--model nonlinear" in cal.warnings[0]
    assert cal.diagnostics["model_error"]["terms"] == ["cubic"]


@pytest.mark.slow
def test_a_strongly_damped_linear_pluck_is_not_amplitude_dependent():
    """A held linear pluck (the project's simulator: all modes, ADS1115 codes; 73 Hz, ζ 0.073,
    200 Hz, a 78-sample decay) with white residuals: the fit's HAC rule took 19 lags of
    them and the score test rejected it (p = 2e-5); the test's own lag rule takes none."""
    from dataclasses import replace

    from whiskerid.fit import calibrate, observations_from_recording
    from whiskerid.model import paper_record, simulate_pluck

    base = paper_record()
    s = base.structure
    zeta = 0.07271259494356865
    stiffer = replace(s, shear_modulus_pa=s.shear_modulus_pa * 1.5858851506994818**2)
    truth = base.replace(structure=stiffer, zeta=zeta)
    f1 = float(truth.whisker().natural_frequencies_hz[0])
    decay_s = float(np.clip(4.6 / (2 * np.pi * f1 * zeta), 0.3, 5.0))
    rng = np.random.default_rng(206)
    hold = float(rng.uniform(0.1, 1.0))
    opts = dict(drift=float(rng.uniform(-0.05, 0.05)), tremor=float(rng.uniform(0.0, 0.02)),
                noise_db=float(rng.uniform(30, 45)))  # fmt: skip
    rec, _ = simulate_pluck(truth, kind="held", observable="adc", rate_hz=200.0, hold_s=hold,
                            seed=206, duration_s=0.6 + hold + decay_s, release_s=0.5 + hold,
                            **opts)  # fmt: skip
    cal = calibrate(base, observations_from_recording(rec, base, observable="adc"))
    test = cal.diagnostics["amplitude_test"]
    assert "amplitude-dependent" not in cal.checks, test
    assert test["nonlinear"]["hac_lag"] == 0 and test["nonlinear"]["p_value"] > 1e-2
    assert abs(cal.params["zeta"]["value"] - zeta) < 3 * cal.params["zeta"]["std"]


def test_a_score_column_the_fit_spans_is_left_out_not_a_singular_variance():
    """A fit to noise can leave an amplitude column that the fit's Jacobian spans (zero once
    projected): the score test is the one of the other columns (it raised LinAlgError)."""
    from whiskerid.fit._choice._scores import score_statistic

    rng = np.random.default_rng(0)
    n = 200
    zp = np.stack([rng.normal(size=n), np.zeros(n), rng.normal(size=n)], axis=1)
    r = rng.normal(size=n) + 0.2 * zp[:, 0]
    out, ref = score_statistic(zp, r, r, [n]), score_statistic(zp[:, [0, 2]], r, r, [n])
    assert out["dof"] == ref["dof"] == 2
    assert out["statistic"] == pytest.approx(ref["statistic"], rel=1e-12) and ref["statistic"] > 0
    none = score_statistic(np.zeros((n, 2)), r, r, [n])
    assert (none["dof"], none["statistic"], none["p_value"]) == (0, 0.0, 1.0)
