"""Contact parameters fitted to a Hall signal's statistics through the contact simulator:
the forward-mode derivatives against finite differences, and the recovery of known
parameters from a simulated recording whose ground profile the fit never sees."""

import equinox as eqx
import jax
import numpy as np
import pytest

from whiskerid.model import paper_record
from whiskerid.terrain import (
    PARAM_NAMES,
    STAT_NAMES,
    amplified_hall,
    contact_twin,
    fit_contact,
    recording_stats,
)

#: ln k (N/m), ln d₀ (m), ln μ, ln ρ (m), slope: a compliant ground (k ≈ 4 × the tip's)
TRUTH = np.array([np.log(200.0), np.log(1.2e-3), np.log(0.5), np.log(2e-4), 2.3])


def test_statistics_see_the_clipping_and_the_band():
    """A 50 Hz tone puts its power in the 45–60 Hz band and is symmetric; the same tone
    with its lower half clipped (a tip that loses the ground) is skewed and its quantiles
    asymmetric, and neither changes the band that holds the power."""
    hall = amplified_hall(paper_record())
    t = np.arange(20 * 200) / 200
    tone = 1e-6 * np.sin(2 * np.pi * 50.3 * t + 0.3)
    bands = [i for i, n in enumerate(STAT_NAMES) if n.startswith("lnP")]
    for x, sign in ((tone, 0), (np.maximum(tone, -0.2e-6), 1)):
        mean, cov = recording_stats(hall.voltage(x), hall)
        assert STAT_NAMES[bands[int(np.argmax(mean[bands]))]] == "lnP_45_60"
        skew, asym = mean[STAT_NAMES.index("skewness")], mean[-1]
        if sign == 0:
            assert abs(skew) < 0.05 and abs(asym) < 0.05
        else:
            assert skew > 0.3 and asym > 0.3
        assert np.all(np.linalg.eigvalsh(cov) > -1e-12)
    with pytest.raises(ValueError, match="windows"):
        recording_stats(hall.voltage(tone[:1000]), hall)


@pytest.mark.slow
def test_stats_derivatives_match_finite_differences():
    """``jacfwd`` through diffrax (forward mode) equals central differences of the
    expected statistics (common random numbers: the statistics are smooth in the
    parameters) to 1 % of each parameter's largest derivative; not better, because each
    lift-off and the quantiles put kinks in the fixed-step map that a finite difference
    straddles (the mean's roughness derivative: 0.080 against 0.090)."""
    twin = contact_twin(0.2, draws=1, duration_s=2.0, seed=3)
    stats = eqx.filter_jit(lambda tw, p: tw.stats(p))
    jac = np.asarray(eqx.filter_jit(lambda tw, p: jax.jacfwd(tw.stats)(p))(twin, TRUTH))
    h = 1e-4
    for j in range(len(PARAM_NAMES)):
        e = h * np.eye(len(PARAM_NAMES))[j]
        fd = (np.asarray(stats(twin, TRUTH + e)) - np.asarray(stats(twin, TRUTH - e))) / (2 * h)
        scale = np.abs(fd).max() + 1e-3
        assert np.abs(jac[:, j] - fd).max() < 1e-2 * scale + 1e-6, (PARAM_NAMES[j], jac[:, j], fd)


@pytest.mark.slow
def test_fit_recovers_known_parameters_without_the_profile():
    """A 20 s recording simulated on a ground profile drawn with other random numbers than
    the fit's: the preload, the roughness and the slope come back within 0.3 in ln (0.3
    for the slope), far inside their priors (1, 2.5 and 1); the friction is set by its
    prior, not by the data (the signal carries little of it)."""
    truth_twin = contact_twin(0.2, draws=1, duration_s=20.0, seed=11)
    volts = np.asarray(eqx.filter_jit(lambda tw, p: tw.volts(p))(truth_twin, TRUTH))
    fit = fit_contact(volts, 0.2, draws=2, duration_s=4.0, seed=0)
    assert fit.converged
    err = fit.params - TRUTH
    for j in (1, 3, 4):  # preload, roughness, slope
        assert abs(err[j]) < 0.3, (PARAM_NAMES[j], fit.params[j], TRUTH[j], fit.sd[j])
    prior_information = 1 / 0.5**2
    assert fit.data_information[2] < 2 * prior_information
    assert fit.data_information[3] > 100 * 1 / 2.5**2  # roughness: the data, not the prior
    assert fit.chi2 < 3 * (10 - len(fit.params)) + 10
