"""Levenberg–Marquardt by variable projection (the default solver) finds the optimum that
optimistix's dogleg over every parameter finds, with far fewer steps."""

from dataclasses import replace

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.fit._problem import FitProblem
from whiskerid.fit._varpro import linear_layout


def test_the_layout_separates_each_recordings_coefficients_from_the_nonlinear_parameters():
    rec = wi.paper_record()
    sims = [
        wi.simulate(rec, excitation="decay", observable="adc", rate_hz=200, duration_s=d, seed=s)
        for d, s in ((2.0, 0), (3.0, 1))
    ]
    obs = [wi.Observation(s.t, s.signal(), excitation="decay", observable="adc") for s in sims]
    problem = FitProblem.from_observations(rec, obs, n_modes=2)
    nl, lin = linear_layout(problem)
    size = problem.flatten(problem.zero_params()).size
    # every position once: the nonlinear ones, then each recording's c, in flatten's order
    assert sorted(np.concatenate([nl, *lin]).tolist()) == list(range(size))
    params = problem.unflatten(np.arange(size, dtype=float))
    for i, idx in enumerate(lin):
        np.testing.assert_array_equal(np.asarray(params["recs"][i]["c"]), idx)
    assert int(params["log_kappa"]) in nl and int(np.ravel(params["zeta_u"])[0]) in nl


@pytest.mark.slow
def test_variable_projection_lands_where_dogleg_does_in_fewer_steps():
    rec = wi.paper_record()
    s = rec.structure  # the nominal record 5 % high in f_1
    nominal = rec.replace(structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * 1.05**2))
    sim = wi.simulate(rec, excitation="decay", observable="adc", rate_hz=200, duration_s=10,
                      noise_db=30, seed=3, tip_deflection_m=2e-3)  # fmt: skip
    obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
    lm = wi.calibrate(nominal, obs)
    dog = wi.calibrate(nominal, obs, solver="dogleg")
    assert lm.status == dog.status == "ok"
    for k in ("f1_hz", "zeta"):
        a, b = lm.params[k], dog.params[k]
        assert abs(a["value"] - b["value"]) < 1e-4 * a["std"]
        assert a["std"] == pytest.approx(b["std"], rel=1e-6)
    assert lm.diagnostics["steps"] < dog.diagnostics["steps"]
