"""The log-polynomial backbone: its polynomial, its linear limit, and the recovery of a
backbone no parametric term describes (a power-law stiffness, SciPy-integrated pluck, the
exact frequency by energy quadrature)."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from whiskerid.fit import Observation, calibrate, nominal_gain
from whiskerid.fit._nonlinear import backbone_at, calibrate_logpoly_backbone, tip_per_sensor
from whiskerid.fit._nonlinear._logpoly import LogPolyBackbone, knot_polynomial, lagrange_matrix
from whiskerid.model import paper_record, slow_flow


@pytest.mark.parametrize("k", [2, 3, 5])
def test_knot_polynomial_interpolates_and_continues_as_its_tangent(k):
    rng = np.random.default_rng(k)
    y, x0, h = rng.normal(size=k), -1.3, 0.7
    xk = x0 + h * np.arange(k)
    ref = np.polynomial.Polynomial.fit(xk, y, k - 1)
    C = jnp.asarray(lagrange_matrix(k))

    def s(x):
        return np.asarray(knot_polynomial(jnp.asarray(x), x0, h, jnp.asarray(y), C))

    x = np.linspace(xk[0], xk[-1], 41)
    np.testing.assert_allclose(s(x), ref(x), atol=1e-10)
    slope = ref.deriv()
    for end, d in ((xk[0], -0.5), (xk[-1], 0.5)):
        assert s(np.array([end + d]))[0] == pytest.approx(ref(end) + d * slope(end), abs=1e-10)


def test_flat_backbone_is_the_linear_decay():
    f, z = 40.0, 0.03
    m = LogPolyBackbone(ln_a_lo=jnp.log(1e-5), h=1.5, f_lo_hz=f, zeta_lo=z, s_f=jnp.zeros(3),
                       s_z=jnp.zeros(3), C=jnp.asarray(lagrange_matrix(3)))  # fmt: skip
    t = np.arange(0, 0.5, 1 / 500)
    a, phi = slow_flow(m, t, 1e-3)
    w = 2 * np.pi * f
    np.testing.assert_allclose(a, 1e-3 * np.exp(-z * w * t), rtol=1e-7)  # RK4 per sample
    np.testing.assert_allclose(phi, w * np.sqrt(1 - z**2) * t, rtol=1e-7)  # RK4 per sample


def _power_law_pluck(seed=0, rise=0.01, p=0.5, zeta0=0.02, rate=860.0):
    """``u'' + 2ζ₀ω₀u' + ω₀²(u + q sgn(u)|u|^{1+p}) = 0`` by SciPy, read as volts (40 dB):
    a backbone ``∝ a^p`` that neither κ (``∝ a``) nor γ (``∝ a²``) follows."""
    record = paper_record()
    w = record.whisker().with_modes(1)
    f0 = float(w.natural_frequencies_hz[0])
    w0 = 2 * np.pi * f0
    ratio = float(tip_per_sensor(w, record.sensor_position_m))
    a_s = 2e-3 / ratio
    # harmonic balance: ω² = ω₀²(1 + q a^p c_p), c_p = (4/π)∫₀^{π/2} cos^{2+p}
    c_p = 4 / np.pi * quad(lambda s: np.cos(s) ** (2 + p), 0, np.pi / 2)[0]
    q = ((1 + rise) ** 2 - 1) / (c_p * a_s**p)

    def rhs(s, y):
        u, v = y
        return [v, -(2 * zeta0 * w0 * v + w0**2 * (u + q * np.sign(u) * abs(u) ** (1 + p)))]

    rng = np.random.default_rng(seed)
    t = np.arange(0, 4.6 / (w0 * zeta0), 1 / rate) + rng.uniform(0, 1 / rate)

    def turn(s, y):  # the velocity's zeros: the turning points |u| = peak amplitude
        return y[1]

    sol = solve_ivp(rhs, (0, t[-1]), [a_s, 0.0], t_eval=t, rtol=1e-11, atol=1e-16,
                    method="DOP853", events=turn)  # fmt: skip
    t_k = np.concatenate([[0.0], sol.t_events[0]])
    a_k = np.abs(np.concatenate([[a_s], sol.y_events[0][:, 0]])) * ratio  # at the tip
    new = np.concatenate([[True], np.diff(t_k) > 1e-9])  # the release itself may be an event
    t_k, a_k = t_k[new], a_k[new]
    gain = nominal_gain(record, "voltage")
    y = 1.65 + gain * sol.y[0]
    y = y + rng.normal(0, np.std(gain * sol.y[0]) / 100, t.size)

    def exact_f(a_tip):  # undamped frequency at tip amplitude, by energy quadrature
        a = a_tip / ratio

        def energy(u):
            return w0**2 * (u**2 / 2 + q * u ** (2 + p) / (2 + p))

        def integrand(s):  # u = a sin s removes the endpoint singularity
            return a * np.cos(s) / np.sqrt(2 * (energy(a) - energy(a * np.sin(s))))

        return 1 / (4 * quad(integrand, 0, np.pi / 2, epsabs=0, epsrel=1e-12)[0])

    def exact_zeta(a_tip):
        """ζ(a) as the fit defines it, ``−(d ln a/dt)/ω(a)``, from the exact solution's
        turning points (log-midpoint of each half cycle), not from averaging theory."""
        rate_k = np.log(a_k[:-1] / a_k[1:]) / np.diff(t_k)
        mid = np.sqrt(a_k[:-1] * a_k[1:])
        r = np.interp(np.log(a_tip), np.log(mid[::-1]), rate_k[::-1])
        return r / (2 * np.pi * exact_f(a_tip))

    obs = Observation(t, y, observable="voltage", gain=gain)
    return record, obs, exact_f, exact_zeta


@pytest.mark.slow
def test_logpoly_backbone_recovers_a_power_law_backbone():
    """f(a) of a power-law stiffness (1 % rise at release) within 3σ of the exact
    frequency (energy quadrature) at amplitudes across the decay; ζ(a) against the exact
    solution's decay rate per half cycle within 4σ: measured, its pull reaches −3 in the
    upper middle of the range, where the fitted polynomial's bias is of the order of its 1σ
    (the pointwise 1σ of a curve whose order BIC chose does not carry that choice)."""
    record, obs, exact_f, exact_zeta = _power_law_pluck()
    lin = calibrate(record, obs, n_modes=1)
    # 2 knots is far behind here (ΔBIC 172 against 4: it cannot bend, and fails the bounds
    # below); the choice is among 3, 4 and 5 (ΔBIC 3.0, 0, 11.3 measured)
    cal = calibrate_logpoly_backbone(lin, [obs], knots=(3, 4, 5))
    assert cal.ok
    a_lo, a_hi = cal.diagnostics["a_lo_m"], cal.diagnostics["a_ref_m"]
    pulls_f, pulls_z = [], []
    for a in np.geomspace(a_lo, a_hi * 0.8, 5):
        b = backbone_at(cal, a)
        truth = exact_f(a)
        pulls_f.append((b["f_hz"] - truth) / b["f_std"])
        pulls_z.append((b["zeta"] - exact_zeta(a)) / b["zeta_std"])
    info = (cal.diagnostics["knot_selection"], pulls_f, pulls_z)
    assert np.max(np.abs(pulls_f)) < 3, info
    assert np.max(np.abs(pulls_z)) < 4, info
    # the curve is identified, not a constant: the rise over the range is seen at > 5σ
    lo, hi = backbone_at(cal, a_lo), backbone_at(cal, a_hi * 0.8)
    assert (hi["f_hz"] - lo["f_hz"]) > 5 * np.hypot(hi["f_std"], lo["f_std"])


def test_simulate_refuses_a_log_polynomial_record():
    from whiskerid.model import nonlinear_coefficients

    nl = {"backbone_model": "log-polynomial", "f_lo_hz": 46.0, "zeta_lo": 0.03}
    record = paper_record().replace(extra={"fit": {"model": "nonlinear", "nonlinear": nl}})
    with pytest.raises(ValueError, match="identified curve"):
        nonlinear_coefficients(record)


def test_posterior_refuses_a_log_polynomial_record():
    from whiskerid.fit import Observation
    from whiskerid.posterior import PosteriorError, setup_posterior

    nl = {"backbone_model": "log-polynomial", "f_lo_hz": 46.0, "zeta_lo": 0.03}
    record = paper_record().replace(extra={"fit": {"model": "nonlinear", "nonlinear": nl}})
    t = np.arange(200) / 860.0
    obs = Observation(t, np.exp(-9 * t) * np.cos(2 * np.pi * 46 * t), observable="deflection")
    with pytest.raises(PosteriorError, match="identified log-polynomial curve"):
        setup_posterior(record, obs)
