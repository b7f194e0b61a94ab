"""Cantilever eigenvalues, mode shapes and participation factors against independent math."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.integrate import simpson
from scipy.optimize import brentq

import whiskerid as wi
from whiskerid.model._modes import modal_mass_ratio


def _roots_by_scan(mu, n):
    """Independent: sign changes of the unscaled equation on a dense grid, then brentq."""
    f = lambda b: (
        1 + np.cos(b) * np.cosh(b) + mu * b * (np.cos(b) * np.sinh(b) - np.sin(b) * np.cosh(b))
    )
    grid = np.linspace(1e-6, (n + 1) * np.pi, 200_000)
    vals = f(grid)
    idx = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))[:n]
    return np.array([brentq(f, grid[i], grid[i + 1], xtol=1e-14) for i in idx])


def test_no_tip_mass_gives_the_papers_constants():
    beta = np.asarray(wi.cantilever_roots(0.0, 5))
    # The paper prints four decimals (three for the fifth): compare after the same rounding.
    np.testing.assert_array_equal(np.round(beta[:4], 4), wi.PAPER_D[:4])
    assert round(float(beta[4]), 3) == wi.PAPER_D[4]
    np.testing.assert_allclose(beta, _roots_by_scan(0.0, 5), rtol=1e-10)


@pytest.mark.parametrize("mu", [0.0, 0.0617, 0.5, 1.0, 10.0, 200.0])
def test_tip_mass_roots_match_a_grid_scan(mu):
    np.testing.assert_allclose(wi.cantilever_roots(mu, 8), _roots_by_scan(mu, 8), rtol=1e-9)


def test_known_tip_mass_value():
    # mu = 1: beta_1 = 1.24792 (e.g. Blevins, Formulas for natural frequency, table 8-8).
    assert float(wi.cantilever_roots(1.0, 1)[0]) == pytest.approx(1.24792, abs=2e-5)


def test_root_gradient_is_exact():
    # First derivatives come from the implicit function theorem (documented as first-order).
    check_grads(lambda m: wi.cantilever_roots(m, 4), (0.3,), order=1, modes=("fwd", "rev"))


@pytest.mark.parametrize("mu", [0.0, 0.4])
def test_mode_shapes_satisfy_the_boundary_conditions(mu):
    beta = wi.cantilever_roots(mu, 6)
    np.testing.assert_allclose(wi.mode_shape(beta, 0.0), 0.0, atol=1e-10)
    np.testing.assert_allclose(wi.mode_shape(beta, 0.0, 1), 0.0, atol=1e-9)
    scale = beta**2 * np.abs(wi.mode_shape(beta, 1.0))
    np.testing.assert_allclose(wi.mode_shape(beta, 1.0, 2) / scale, 0.0, atol=1e-9)
    shear = wi.mode_shape(beta, 1.0, 3) + mu * beta**4 * wi.mode_shape(beta, 1.0)
    np.testing.assert_allclose(shear / (beta**3 * scale), 0.0, atol=1e-9)


@pytest.mark.parametrize("mu", [0.0, 0.4])
def test_modes_are_mass_orthogonal_including_the_tip_mass(mu):
    beta = np.asarray(wi.cantilever_roots(mu, 5))
    # Independent: the textbook form of the shapes, integrated by Simpson's rule.
    sigma = (np.cosh(beta) + np.cos(beta)) / (np.sinh(beta) + np.sin(beta))
    xi = np.linspace(0, 1, 20_001)[:, None]
    z = beta * xi
    phi = np.cosh(z) - np.cos(z) - sigma * (np.sinh(z) - np.sin(z))
    np.testing.assert_allclose(
        wi.mode_shape(jnp.asarray(beta), xi[::500, 0]), phi[::500], atol=1e-9
    )
    gram = simpson(phi[:, :, None] * phi[:, None, :], x=xi[:, 0], axis=0)
    gram += mu * np.outer(phi[-1], phi[-1])
    off = gram - np.diag(np.diag(gram))
    assert np.max(np.abs(off)) < 1e-8 * np.max(np.diag(gram))
    np.testing.assert_allclose(np.diag(gram), modal_mass_ratio(jnp.asarray(beta), mu), rtol=1e-9)


def test_participation_factors_without_tip_mass_are_2_sigma_over_beta():
    beta = wi.cantilever_roots(0.0, 6)
    sigma = (np.cosh(beta) + np.cos(beta)) / (np.sinh(beta) + np.sin(beta))
    np.testing.assert_allclose(wi.participation_factors(beta, 0.0), 2 * sigma / beta, rtol=1e-10)
    np.testing.assert_allclose(modal_mass_ratio(beta, 0.0), 1.0, rtol=1e-10)  # ∫φ² = 1


def test_participation_sum_rule_converges_to_one():
    # Rigid-body completeness: Σ Γ_i φ_i(ξ) → 1 away from the clamp.
    beta = wi.cantilever_roots(0.3, 40)
    total = wi.participation_factors(beta, 0.3) @ wi.mode_shape(beta, jnp.array([0.5, 1.0])).T
    np.testing.assert_allclose(total, 1.0, atol=0.01)


def test_high_modes_stay_finite_and_precise():
    beta = wi.cantilever_roots(0.0, 30)
    phi = wi.mode_shape(beta, jnp.linspace(0, 1, 101))
    assert np.all(np.isfinite(phi))
    np.testing.assert_allclose(np.abs(phi[-1]), 2.0, rtol=1e-8)  # |φ_i(1)| = 2 for μ = 0


@pytest.mark.parametrize("mu", [0.0, 0.06, 1.0, 200.0])
def test_concrete_mu_roots_equal_the_traced_ones(mu):
    """A concrete μ takes the cached host path (Newton steps in the bracket); a traced μ the
    JAX bisection: the same roots to rounding."""
    concrete = np.asarray(wi.cantilever_roots(mu, 6))
    traced = np.asarray(jax.jit(lambda m: wi.cantilever_roots(m, 6))(mu))
    np.testing.assert_allclose(concrete, traced, rtol=4e-16, atol=0)


@pytest.mark.parametrize("n_modes", [1, 2, 5, 10])
def test_host_newton_roots_equal_the_traced_bisection_over_tip_masses(n_modes):
    """The host's safeguarded Newton search against the traced path's 80 halvings (another
    algorithm on the same bracket), for tip masses from a speck to a thousand beams."""
    from whiskerid.model._modes import host_roots

    mus = np.concatenate([[0.0], np.geomspace(1e-6, 1e3, 49)])
    traced = np.asarray(jax.jit(jax.vmap(lambda m: wi.cantilever_roots(m, n_modes)))(mus))
    host = np.array([host_roots(m, n_modes) for m in mus])
    np.testing.assert_allclose(host, traced, rtol=2e-15, atol=0)
    assert np.all(np.diff(host, axis=1) > 0)  # β_1 < β_2 < …, each root found once
