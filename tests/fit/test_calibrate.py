"""Calibration: recovery of known parameters from simulated recordings, identifiability,
batched window fits, and the real aluminium cantilever (skipped when its data is absent)."""

from dataclasses import replace
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ALU

import whiskerid as wi
from whiskerid.fit import GTOL, gradient_cosine, release_time

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "cantilever"


def _off_by_30_percent(rec: wi.WhiskerRecord) -> wi.WhiskerRecord:
    """The nominal record a user starts from: f_1 30 % high, ζ 30 % high."""
    s = rec.structure
    return rec.replace(
        structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * 1.3**2), zeta=0.052
    )


def _pluck(record, observable, *, gain_known=False, **simulate_kwargs) -> wi.Observation:
    """A free decay of ``record`` simulated by :func:`whiskerid.simulate`, as calibrate gets it:
    same observable, sensor gain unknown (``gain=None``) unless ``gain_known``."""
    sim = wi.simulate(record, excitation="decay", observable=observable, **simulate_kwargs)
    gain = {} if gain_known else {"gain": None}
    return wi.Observation(sim.t, sim.signal(), excitation="decay", observable=observable, **gain)


@pytest.fixture(scope="module")
def paper():
    rec = wi.paper_record()
    w = rec.whisker()
    return rec, float(w.natural_frequencies_hz[0]), float(w.zeta[0])


@pytest.fixture(scope="module")
def decay_fit(paper):
    rec, _, _ = paper
    obs = _pluck(rec, "adc", rate_hz=200, duration_s=10, noise_db=30, seed=11,
                 tip_deflection_m=2e-3)  # fmt: skip
    return wi.calibrate(_off_by_30_percent(rec), obs)


def test_decay_adc_200hz_recovers_f1_and_zeta_from_30_percent_off(paper, decay_fit):
    _, f1, zeta = paper
    p = decay_fit.params
    assert decay_fit.ok and decay_fit.status == "ok"
    assert abs(p["f1_hz"]["value"] / f1 - 1) < 1e-3
    assert abs(p["zeta"]["value"] / zeta - 1) < 0.03
    # the 1-sigma is honest in size: the error is within a few sigma, and sigma is not huge
    assert abs(p["f1_hz"]["value"] - f1) < 5 * p["f1_hz"]["std"] < 0.01 * f1
    assert 0.5 < decay_fit.diagnostics["reduced_chi2"] < 2


def test_convergence_is_judged_by_the_gradient_too(paper, decay_fit):
    """Converged means stationary: the solver's step test, or no parameter direction with
    a cosine to the residuals above GTOL (it can stall at rounding level on long real
    recordings). One step from 30 % off is neither."""
    rec, _, _ = paper
    assert decay_fit.diagnostics["gradient_cosine"] < GTOL
    obs = _pluck(rec, "adc", rate_hz=200, duration_s=10, noise_db=30, seed=11,
                 tip_deflection_m=2e-3)  # fmt: skip
    early = wi.calibrate(_off_by_30_percent(rec), obs, max_steps=1)
    assert early.diagnostics["gradient_cosine"] > 1e3 * GTOL
    assert early.status == "not converged" and not early.ok


def test_gradient_cosine_is_zero_at_a_least_squares_solution():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((50, 3)) * [1.0, 1e3, 1e-3], rng.standard_normal(50)
    x = np.linalg.lstsq(a, b, rcond=None)[0]
    fn = lambda p, args: args[0] @ p - args[1]
    assert float(gradient_cosine(fn, jnp.asarray(x), (a, b))) < 1e-9
    assert float(gradient_cosine(fn, jnp.asarray(x * 1.01), (a, b))) > 1e-4


def test_vibrations_alone_never_report_both_EI_and_C(decay_fit):
    p = decay_fit.params
    assert "EI" in p and "C" not in p and decay_fit.fixed["C"] == pytest.approx(6.207, rel=1e-3)
    assert "kappa" in p and "not both identified" in decay_fit.note
    # EI (via the geometry's rho*a) carries kappa's relative uncertainty
    rel = p["EI"]["std"] / p["EI"]["value"]
    assert rel == pytest.approx(p["kappa"]["std"] / p["kappa"]["value"], rel=1e-6)
    # the [fit] table records status, sigma, correlations and what was fixed
    fit = decay_fit.record.extra["fit"]
    assert fit["status"] == "ok" and fit["params"]["zeta"]["std"] > 0
    names = fit["correlations"]["names"]
    assert np.allclose(np.diag(fit["correlations"]["matrix"]), 1.0) and "zeta" in names
    # the written record reproduces the fitted f_1
    f1_rec = float(decay_fit.record.whisker().natural_frequencies_hz[0])
    assert f1_rec == pytest.approx(p["f1_hz"]["value"], rel=1e-9)


@pytest.mark.slow
def test_material_pin_reports_C_not_EI(paper):
    rec, _, _ = paper
    obs = _pluck(rec, "deflection", gain_known=True, rate_hz=400, duration_s=2, noise_db=40,
                 seed=2)  # fmt: skip
    cal = wi.calibrate(rec, obs, pin="material", n_modes=1)
    assert "C" in cal.params and "EI" not in cal.params and "EI" in cal.fixed
    assert cal.params["C"]["value"] == pytest.approx(6.207, rel=2e-3)


@pytest.mark.slow
def test_static_test_pins_EI_so_C_follows(paper):
    rec, _, _ = paper
    ei = rec.structure.EI
    rng = np.random.default_rng(4)
    force = np.linspace(0.0, 0.05, 8)
    defl = force * 0.06**3 / (3 * ei) + 2e-7 * rng.standard_normal(8)
    static = wi.StaticTest(force, defl)
    obs = _pluck(rec, "voltage", rate_hz=200, duration_s=4, noise_db=35, seed=5,
                 tip_deflection_m=2e-3)  # fmt: skip
    cal = wi.calibrate(_off_by_30_percent(rec), obs, static=static, n_modes=1)
    p = cal.params
    assert cal.ok and "EI" in p and "C" in p and "static" in p["C"]["source"]
    assert p["EI"]["value"] == pytest.approx(ei, rel=0.01)
    assert p["C"]["value"] == pytest.approx(6.207, rel=0.01)
    assert abs(p["C"]["value"] - 6.207) < 4 * p["C"]["std"]


@pytest.mark.slow
def test_nonuniform_timestamps(paper):
    rec, f1, zeta = paper
    obs = _pluck(rec, "adc", rate_hz=200, duration_s=5, noise_db=30, seed=7, jitter_s=1e-3,
                 tip_deflection_m=2e-3)  # fmt: skip
    assert np.std(np.diff(obs.t)) > 3e-4
    cal = wi.calibrate(_off_by_30_percent(rec), obs)
    assert cal.params["f1_hz"]["value"] == pytest.approx(f1, rel=1e-3)
    assert cal.params["zeta"]["value"] == pytest.approx(zeta, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("hb_known", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_sine_with_known_and_unknown_amplitude(paper, hb_known):
    rec, f1, zeta = paper
    sim = wi.simulate(
        rec,
        excitation="sine",
        fb_hz=30.0,
        hb_m=2e-4,
        observable="deflection",
        rate_hz=1000,
        duration_s=1.5,
        noise_db=40,
        seed=3,
    )
    obs = wi.Observation(
        sim.t,
        sim.signal(),
        excitation="sine",
        observable="deflection",
        fb_hz=30.0,
        hb_m=2e-4 if hb_known else None,
    )
    cal = wi.calibrate(_off_by_30_percent(rec), obs, n_modes=2)
    assert cal.ok
    assert cal.params["f1_hz"]["value"] == pytest.approx(f1, rel=0.005)
    assert cal.params["zeta"]["value"] == pytest.approx(zeta, rel=0.1)
    if not hb_known:
        assert "product" in cal.per_recording[0]["note"]


@pytest.mark.slow
def test_measured_base_motion(paper):
    rec, f1, zeta = paper
    tb = np.arange(0, 2.0, 1e-3)
    acc = sum(
        a * np.sin(2 * np.pi * f * tb + p) for a, f, p in ((3, 21, 0.3), (2, 44, 1), (2, 67, 2))
    )
    acc = acc * np.minimum(tb / 0.05, 1)
    sim = wi.simulate(
        rec,
        excitation="base",
        base=wi.BaseMotion(tb, acc),
        observable="deflection",
        rate_hz=1000,
        duration_s=1.9,
        noise_db=40,
        seed=8,
    )
    obs = wi.Observation(
        sim.t,
        sim.signal(),
        excitation="base",
        observable="deflection",
        base_acc=np.interp(sim.t, tb, acc),
    )
    cal = wi.calibrate(_off_by_30_percent(rec), obs, n_modes=2)
    assert cal.ok
    assert cal.params["f1_hz"]["value"] == pytest.approx(f1, rel=0.005)
    assert cal.params["zeta"]["value"] == pytest.approx(zeta, rel=0.1)


def test_fit_windows_batch_survives_bad_windows():
    rate, m = 200.0, 200
    t = np.arange(m) / rate
    rng = np.random.default_rng(0)
    fd = rng.uniform(20, 60, 12)
    zeta = rng.uniform(0.01, 0.05, 12)
    wd = 2 * np.pi * fd[:, None]
    windows = 1.5 + np.exp(-zeta[:, None] * wd * t) * np.cos(wd * t + 0.4)
    windows += 0.01 * rng.standard_normal(windows.shape)
    windows[3] = np.nan
    windows[7, 50] = np.inf
    fits = wi.fit_windows(windows, rate_hz=rate)
    ok = np.asarray(fits.ok)
    assert not ok[3] and not ok[7] and ok.sum() == 10
    good = ok.nonzero()[0]
    assert np.allclose(np.asarray(fits.damped_frequency_hz)[good], fd[good], rtol=1e-3)
    assert np.allclose(np.asarray(fits.zeta)[good], zeta[good], rtol=0.1)
    assert np.isnan(float(fits.zeta[3]))
    assert np.allclose(np.asarray(fits.offset)[good], 1.5, atol=0.01)


def test_fit_windows_agrees_with_scipy_and_sees_fast_decays():
    """Variable projection reaches SciPy's optimum of the same five-parameter model, also
    for decays over within a tenth of the window (a Hann-window spectrum misses them)."""
    import scipy.optimize

    from whiskerid.fit import ZETA_MAX, window_start

    rate, m = 200.0, 200
    t = np.arange(m) / rate
    rng = np.random.default_rng(3)
    fd = np.array([23.0, 41.0, 67.0, 78.0, 35.0, 59.0])
    zeta = np.array([0.01, 0.03, 0.055, 0.06, 0.02, 0.05])  # the last four: sigma > 10 /s
    wd = 2 * np.pi * fd[:, None]
    clean = np.exp(-zeta[:, None] * wd * t) * np.cos(wd * t + rng.uniform(0, 6, (6, 1)))
    y = clean + 0.03 * clean.std(axis=1, keepdims=True) * rng.standard_normal(clean.shape)
    fits = wi.fit_windows(y, rate_hz=rate)
    assert np.all(np.asarray(fits.ok))

    def resid(u, yi):
        z = ZETA_MAX / (1 + np.exp(-u[1]))
        w = 2 * np.pi * np.exp(u[0])
        e = np.exp(-z * w / np.sqrt(1 - z**2) * t)
        return u[4] + e * (u[2] * np.cos(w * t) + u[3] * np.sin(w * t)) - yi

    u0 = window_start(t, y)
    for i in range(len(fd)):
        ref = scipy.optimize.least_squares(resid, u0[i], args=(y[i],), method="lm", xtol=1e-12)
        assert float(fits.damped_frequency_hz[i]) == pytest.approx(np.exp(ref.x[0]), rel=1e-7)
        z_ref = ZETA_MAX / (1 + np.exp(-ref.x[1]))
        assert float(fits.zeta[i]) == pytest.approx(z_ref, rel=1e-5)
        assert float(fits.damped_frequency_hz[i]) == pytest.approx(fd[i], abs=0.1)
    # the optimistix path (five parameters, vmapped) lands on the same optimum
    slow = wi.fit_windows(y[:2], rate_hz=rate, solver="optimistix-lm")
    fast = np.asarray(fits.damped_frequency_hz[:2])
    assert np.allclose(np.asarray(slow.damped_frequency_hz), fast, rtol=1e-7)
    with pytest.raises(wi.CalibrationError, match="solver"):
        wi.fit_windows(y, rate_hz=rate, solver="newton")


def test_closed_form_adc_average_of_free_columns_equals_the_sampled_average():
    from whiskerid.fit import decay_rates, free_decay_columns

    w = wi.paper_record().whisker().with_modes(3)
    sigma, wd = decay_rates(w.omega_rad_s, w.zeta)
    t = jnp.sort(jnp.asarray(np.random.default_rng(1).uniform(0, 2, 500)))
    offsets = wi.paper_record().adc.averaging_offsets()
    point = lambda tt: jnp.concatenate(free_decay_columns(tt[:, None], sigma, wd), axis=1)
    tt = t[:, None] + offsets[None, :]
    sampled = point(tt.reshape(-1)).reshape(t.size, offsets.size, -1).mean(axis=1)
    closed = jnp.concatenate(free_decay_columns(t[:, None], sigma, wd, offsets), axis=1)
    assert float(jnp.max(jnp.abs(closed - sampled))) < 1e-12
    # and the average matters: it differs from the unaveraged columns
    assert float(jnp.max(jnp.abs(closed - point(t)))) > 1e-3


def test_bad_observation_is_refused():
    t = np.arange(100) / 200.0
    with pytest.raises(wi.RecordingError, match="non-finite"):
        wi.Observation(t, np.where(t > 0.2, np.nan, 1.0))
    with pytest.raises(wi.CalibrationError, match="--fb"):
        wi.Observation(t, np.sin(t), excitation="sine")


@pytest.mark.slow
@pytest.mark.skipif(not DATA.exists(), reason="shared cantilever data not present")
def test_real_cantilever_30cm():
    rec = wi.WhiskerRecord(
        name="alu-30cm",
        structure=wi.UniformBeam(
            length_m=0.30,
            youngs_modulus_pa=ALU["E"],
            density_kg_m3=ALU["rho"],
            width_m=ALU["width"],
            thickness_m=ALU["thickness"],
        ),
        zeta=0.01,
        n_modes=2,
        tip_mass_kg=ALU["tip_mass"],
        sensor_position_m=0.24,
    )
    path = sorted((DATA / "30cm").glob("*.npy"))[0]
    a = np.load(path)
    obs = wi.Observation(a[0], a[1] * 9.80665, observable="acceleration", name=path.name)
    obs = obs.window(release_time(obs.t, obs.y), None)
    cal = wi.calibrate(rec, obs, n_modes=1)
    p = cal.params
    assert cal.ok
    assert p["f1_hz"]["value"] == pytest.approx(16.49, rel=0.01)
    assert p["EI"]["value"] == pytest.approx(rec.structure.EI, rel=0.05)
    assert 1e-3 < p["zeta"]["value"] < 1e-2


def test_window_model_matches_jax_free_decay():
    """The window model is the one-mode free decay of the exact model."""
    w = wi.paper_whisker(1)
    t = jnp.linspace(0, 0.2, 300)
    y = wi.observe(w, wi.free_decay(w, t, q0=jnp.array([1e-3])))
    fits = wi.fit_windows(np.asarray(y)[None, :] * 1e3, t=np.asarray(t))
    assert float(fits.damped_frequency_hz[0]) == pytest.approx(
        float(w.damped_frequencies_hz[0]), rel=1e-6
    )
    assert float(fits.zeta[0]) == pytest.approx(0.04, rel=1e-5)


@pytest.mark.slow
def test_reported_sigma_covers_the_truth_about_68_percent(paper):
    """30 seeded trials (examples/calibrate_coverage.py runs 200): loose bounds."""
    rec, f1, zeta = paper
    start = _off_by_30_percent(rec)
    hits_f, hits_z = [], []
    for seed in range(30):
        obs = _pluck(rec, "adc", rate_hz=200, duration_s=10, noise_db=30, seed=500 + seed,
                     tip_deflection_m=2e-3)  # fmt: skip
        p = wi.calibrate(start, obs).params
        assert abs(p["f1_hz"]["value"] / f1 - 1) < 1e-3
        hits_f.append(abs(p["f1_hz"]["value"] - f1) <= p["f1_hz"]["std"])
        hits_z.append(abs(p["zeta"]["value"] - zeta) <= p["zeta"]["std"])
    assert 0.4 <= np.mean(hits_f) <= 0.95 and 0.4 <= np.mean(hits_z) <= 0.95
