"""Levenberg–Marquardt by variable projection (the default solver) finds the optimum that
optimistix's dogleg over every parameter finds, with far fewer steps; its closed-form
Jacobian is the derivative of the projected residuals."""

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import whiskerid as wi
from whiskerid.fit._linear._problem import ZETA_MAX, FitProblem
from whiskerid.fit._linear._program import padded_problem
from whiskerid.fit._linear._varpro import linear_layout, projection


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


def _problem(k: int):
    """Problem ``k`` of three, whose projected residuals depend on φ in every way the fit
    meets: two free decays of other lengths (padded to their buckets) with a ζ per mode; a
    sine of unknown delay (its fixed part moves with φ) beside a decay, with a static test
    (log EI and the static offset among φ); base motion."""
    rec = wi.paper_record()

    def obs(excitation, duration_s, seed, **kw):
        # the ADS1115's averaging for the decays only: the forced responses' designs are
        # then far smaller programs to compile, and the Jacobian does not ask how D is made
        observable = "adc" if excitation == "decay" else "deflection"
        sim = wi.simulate(rec, excitation=excitation, observable=observable, rate_hz=200,
                          duration_s=duration_s, noise_db=30, seed=seed, **kw)  # fmt: skip
        extra = {k: v for k, v in kw.items() if k in ("fb_hz", "hb_m")}
        if excitation == "base":
            extra["base_acc"] = np.interp(sim.t, kw["base"].t, kw["base"].acc)
        return wi.Observation(sim.t, sim.signal(), excitation=excitation,
                              observable=observable, gain=None, **extra)  # fmt: skip

    tb = np.arange(0, 1.5, 1e-3)
    base = wi.BaseMotion(tb, np.sin(2 * np.pi * 21 * tb) + 0.5 * np.sin(2 * np.pi * 44 * tb))
    ei = float(rec.whisker().EI)
    static = wi.StaticTest(np.linspace(0, 0.05, 5), np.linspace(0, 0.05, 5) * 0.06**3 / (3 * ei))
    if k == 0:
        return FitProblem.from_observations(rec, [obs("decay", 1.3, 0), obs("decay", 2.1, 1)],
                                            n_modes=2, zeta_per_mode=True)  # fmt: skip
    if k == 1:
        return FitProblem.from_observations(
            rec,
            [obs("sine", 1.0, 2, fb_hz=30.0, hb_m=1e-4), obs("decay", 1.0, 3)],
            n_modes=1,
            static=static,
        )
    return FitProblem.from_observations(rec, [obs("base", 1.2, 4, base=base)], n_modes=2)


def _phi(problem, nl):
    """Nonlinear parameters near the paper whisker's (f_1 0.5 % high, ζ 0.035)."""
    w = wi.paper_record().whisker()
    params = problem.zero_params()
    params["log_kappa"] = np.full_like(params["log_kappa"], np.log(w.EI / w.rho_a) + 0.01)
    zeta = np.linspace(0.035, 0.05, np.size(params["zeta_u"])).reshape(np.shape(params["zeta_u"]))
    params["zeta_u"] = np.log(zeta / (ZETA_MAX - zeta))
    for r in params["recs"]:
        if "tau" in r:
            r["tau"] = np.asarray(1e-3)
    if "log_EI" in params:
        params["log_EI"] = np.asarray(np.log(w.EI) - 0.02)
        params["static_d0"] = np.asarray(1e-5)
    return jnp.asarray(np.asarray(problem.flatten(params))[nl])


@pytest.mark.parametrize(
    "k", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)]
)
def test_the_closed_form_jacobian_is_the_derivative_of_the_projected_residuals(k):
    """Golub and Pereyra's Jacobian (from the QR factors) against forward mode through the
    projected residuals computed another way (the coefficients by an SVD least squares,
    not a QR) and against central differences of those residuals."""
    problem = _problem(k)
    padded, masks = padded_problem(problem)
    size = problem.flatten(problem.zero_params()).size
    fn, nl, _ = projection(padded, masks, size)

    def reference(phi):
        params = padded.unflatten(jnp.zeros(size).at[nl].set(phi))
        out = []
        for (D, g), r, m in zip(padded.design(params), padded.recordings, masks, strict=True):
            A, b = D * (r.weight * m)[:, None], (r.y - g) * r.weight * m
            out.append(A @ jnp.linalg.lstsq(A, b)[0] - b)
        if padded.static_test is not None:
            out.append(padded.static_residuals(params))
        return jnp.concatenate(out)

    phi = _phi(problem, nl)
    jac, (r, _) = jax.jit(fn)(phi)
    ref = jax.jit(reference)
    r_ref, forward = ref(phi), jax.jit(jax.jacfwd(reference))(phi)
    h = 1e-6
    central = np.stack([(ref(phi + h * e) - ref(phi - h * e)) / (2 * h) for e in np.eye(phi.size)],
                       axis=1)  # fmt: skip
    np.testing.assert_allclose(r, r_ref, rtol=0, atol=1e-9 * float(jnp.max(jnp.abs(r))))
    scale = float(jnp.max(jnp.abs(forward)))
    np.testing.assert_allclose(jac, forward, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(jac, central, rtol=0, atol=1e-5 * scale)
    # the padding's rows stay zero (the static test's rows come after the recordings')
    pad = np.concatenate(masks) == 0
    assert pad.any() == (k < 2) and not np.any(np.asarray(jac)[: pad.size][pad])
