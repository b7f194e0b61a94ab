"""Posteriors of a nonlinear calibration (f₀, ζ₀ and the nonlinear coefficients) on plucks
made by an independent SciPy integrator (the generator of ``test_nonlinear``)."""

import numpy as np
import pytest
from helpers import nonlinear_pluck

from whiskerid import posterior as P
from whiskerid.fit import calibrate
from whiskerid.model import paper_record


def _nonlinear_record(**coefficients):
    """The paper record marked as calibrated by the nonlinear model (no fit run)."""
    rec = paper_record()
    nl = {"gamma_per_m2": 0.0, "quadratic_per_m": 0.0, "coulomb_m_s2": 0.0, **coefficients}
    return rec.replace(extra={**rec.extra, "fit": {"model": "nonlinear", "nonlinear": nl}})


def test_nonlinear_record_refusals_and_terms():
    from whiskerid.fit import StaticTest
    from whiskerid.posterior._nonlinear import fitted_terms, is_nonlinear

    rec = _nonlinear_record(gamma_per_m2=2.0e3, quadratic_per_m=9.0)
    assert is_nonlinear(rec) and not is_nonlinear(paper_record())
    assert fitted_terms(rec) == ("cubic", "quadratic")
    _, obs, _ = nonlinear_pluck(rate=200.0, duration=0.2)
    with pytest.raises(P.PosteriorError, match="cannot be marginalised"):
        P.setup_posterior(rec, obs, marginalize=True)
    static = StaticTest(force_n=np.array([0.0, 0.01, 0.02]),
                        deflection_m=np.array([0.0, 1e-3, 2e-3]))  # fmt: skip
    with pytest.raises(P.PosteriorError, match="free decays only"):
        P.setup_posterior(rec, obs, static=static)


@pytest.mark.slow
def test_nonlinear_posterior_agrees_with_calibrate_and_covers_the_truth():
    """A SciPy pluck with 0.4 % stiffening and ζ 1.25× at the release (200 Hz, 40 dB): the
    posterior medians of f₀, ζ₀, γ and c lie within 1σ of the nonlinear calibration's values,
    and the truth lies inside the 95 % interval; the chain is long enough (50 τ)."""
    record, obs, truth = nonlinear_pluck(rate=200.0, seed=1)
    cal = calibrate(record, obs, n_modes=1, model="nonlinear", nl_terms=("cubic", "quadratic"))
    assert cal.status == "ok", cal.warnings
    post = P.sample_posterior(cal.record, obs, walkers=32, steps=2000, seed=3)
    assert post.diagnostics["converged"], post.diagnostics["message"]
    assert post.provenance["model"] == "nonlinear"
    assert "nl.cubic" in post.chain_names and "nl.coulomb" not in post.chain_names
    for name, value in truth.items():
        q, c = post.params[name], cal.params[name]
        assert abs(q["median"] - c["value"]) < c["std"], (name, q, c)
        assert q["q2.5"] < value < q["q97.5"], (name, q, value)
        assert 0.5 < q["std"] / c["std"] < 2.0, (name, q, c)
    # the backbone's damping at the largest amplitude is above the small-amplitude ζ₀
    assert post.params["zeta_at_a_max"]["q2.5"] > post.params["zeta"]["q97.5"]
