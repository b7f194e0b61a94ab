"""The residual-against-noise spectral ratio: white means indistinguishable from the sensor."""

import numpy as np
import pytest

from whiskerid.fit._checks._spectral_floor import spectral_whiteness


def _ar1(rng, n, phi):
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = e[0]
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    return x


def test_coloured_noise_is_white_against_its_own_spectrum_and_a_missed_line_is_not():
    rng = np.random.default_rng(3)
    fs, f1, n = 500.0, 16.4, 10_000
    t = np.arange(n) / fs
    ratios = []
    for _ in range(3):
        # noise with lag-1 0.5 (a sensor's filter): lag-1 of the residual says "correlated"
        r = _ar1(rng, n, 0.5)
        for quiet in (None, _ar1(rng, 4000, 0.5)):
            out = spectral_whiteness(t, r, [f1], quiet=quiet)
            assert out["reference"] == ("flanks" if quiet is None else "quiet")
            (band,) = out["bands"]
            ratios.append(band["ratio"])
            assert abs(band["ratio"] - 1) < 4 * band["ratio_std"]
            assert band["white"]
    assert 0.8 < np.mean(ratios) < 1.2
    # a slowly swept line at f1 with 1/4 of the noise's RMS, as a backbone error leaves it
    r = _ar1(rng, n, 0.5) + 0.5 * np.cos(2 * np.pi * (f1 * t + 0.002 * t**2))
    out = spectral_whiteness(t, r, [f1], quiet=_ar1(rng, 4000, 0.5))
    assert out["bands"][0]["ratio"] > 1.5 and not out["white"]
    out = spectral_whiteness(t, r, [f1])
    assert out["bands"][0]["ratio"] > 1.5 and not out["white"]


@pytest.mark.slow
def test_a_free_second_mode_is_found_where_the_beam_does_not_put_it():
    """A SciPy nonlinear pluck plus a linear second mode 4 % above the beam's f2: tied to
    the beam's ratio (the linear fit) the second mode stays in the residuals (its band far
    above the noise); in the nonlinear fit, free (started at the data's line) it is fitted
    within 3σ, as are f0 and ζ0, and every band of the residual spectrum is
    indistinguishable from the noise."""
    from helpers import nonlinear_pluck

    from whiskerid.fit import Observation, calibrate, calibrate_nonlinear

    record, obs, truth = nonlinear_pluck(seed=2)
    w2 = record.whisker().with_modes(2)
    f2 = 1.04 * float(w2.natural_frequencies_hz[1])
    z2 = 0.003
    t = obs.t
    wd = 2 * np.pi * f2 * np.sqrt(1 - z2**2)
    y1 = obs.y - obs.y.mean()
    y = obs.y + 0.3 * np.std(y1) * np.exp(-z2 * 2 * np.pi * f2 * t) * np.cos(wd * t + 0.7)
    obs = Observation(t, y, observable="voltage", gain=obs.gain)
    lin = calibrate(record, obs, n_modes=2)
    # the linear fit reports its residual spectrum too: its tied second mode leaves the line
    assert max(b["ratio"] for b in lin.diagnostics["residual_spectrum"][0]["bands"]) > 10
    free = calibrate_nonlinear(lin, [obs], terms=("cubic", "quadratic"), free_modes=True)
    p = free.params
    assert abs(p["f2_hz"]["value"] - f2) < 3 * p["f2_hz"]["std"], p["f2_hz"]
    assert abs(p["zeta_2"]["value"] - z2) < 3 * p["zeta_2"]["std"], p["zeta_2"]
    for name in ("f1_hz", "zeta"):
        assert abs(p[name]["value"] - truth[name]) < 3 * p[name]["std"], (name, p[name])
    spec = free.diagnostics["residual_spectrum"][0]
    assert len(spec["bands"]) == 2 and spec["white"], spec
