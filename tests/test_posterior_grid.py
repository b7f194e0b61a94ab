"""The posterior's gridded free-decay columns (``_posterior._grid_columns``): equal to the
direct columns and log-probabilities on jittered timestamps, several modes and ADC
averaging, with the batch falling back to the direct path where the Taylor factor would not
be exact, and no grid at all for timestamps too irregular for one."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import decay_recording

import whiskerid as wi
from whiskerid import posterior as P
from whiskerid.posterior import _grid as G
from whiskerid.posterior import _likelihood as L

F1, ZETA, NOISE, N = 48.0, 0.02, 0.05, 500


def decay(seed=0, n=N, jitter=2e-4, drop=None, wander=0.0):
    """A one-mode free decay at 1 kHz, timestamps jittered by up to ``jitter`` (s) and
    wandering by up to ``wander`` (s) over the recording, the samples in ``drop`` left out."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0 + rng.uniform(0, jitter, n)
    t = t + wander * np.sin(2 * np.pi * np.arange(n) / n)
    w = 2 * np.pi * F1
    y = 0.3 + np.exp(-ZETA * w * t) * np.cos(w * math.sqrt(1 - ZETA**2) * t + 1.0)
    y = y + NOISE * rng.standard_normal(n)
    keep = np.ones(n, bool)
    if drop is not None:
        keep[list(drop)] = False
    return wi.Observation(t[keep], y[keep], name=f"decay-{seed}")


def _direct(prob, z):
    return np.asarray(jax.vmap(lambda v: L.log_prob_one(prob.model, v, prob.args))(z))


def _grid_ok(prob, z):
    return np.asarray(jax.vmap(lambda v: L._grid_tables(prob.model, v, prob.args)[1])(z))


@pytest.mark.parametrize(
    ("modes", "offsets", "n"),
    [(1, None, 500), (3, None, 437), (2, (0.0, -4e-4, -8e-4), 500)],
)
def test_grid_columns_equal_direct_columns(modes, offsets, n):
    """Gridded columns (padding included) vs ``_columns`` on jittered, non-uniform times."""
    w = wi.paper_record().whisker().with_modes(modes)
    rng = np.random.default_rng(3)
    t = 0.02 + np.arange(n) / 1000.0 + rng.uniform(-1e-4, 1e-4, n)
    y = rng.standard_normal(n)
    grid = G._decay_grid(t, y)
    assert grid["dmax"] < 1.5e-4  # centred jitter of ±1e-4 s
    omega = np.asarray(w.omega_rad_s)
    degrees = tuple(G._taylor_degree(o * grid["dmax"]) for o in omega)
    gj = {k: jnp.asarray(v) for k, v in grid.items()}
    rec = decay_recording(t, modes, offsets)
    cols = G._grid_columns(G._decay_tables(rec, w, gj), gj, degrees)
    direct, _ = L._columns(rec, w, {})
    mask = grid["mask"].ravel()
    assert mask.sum() == n and np.all(mask[n:] == 0)
    for c_grid, c_direct in zip(cols, direct, strict=True):
        flat = np.asarray(c_grid).ravel()
        np.testing.assert_allclose(flat[:n], c_direct, rtol=0, atol=1e-13)
        assert np.all(flat[n:] == 0)  # padding contributes nothing to any sum
    # The sampled coefficients folded into the tables: Σ c_cos C + c_sin S in one column.
    c = rng.standard_normal((2, modes))
    tables = G._decay_tables(rec, w, gj, (jnp.asarray(c[0]), jnp.asarray(-c[1])))
    total = np.asarray(G._grid_columns(tables, gj, degrees, summed=True)[2]).ravel()[:n]
    expected = sum(c[0, i] * direct[2 + i] + c[1, i] * direct[2 + modes + i] for i in range(modes))
    np.testing.assert_allclose(total, expected, rtol=0, atol=1e-13)


@pytest.mark.parametrize(
    ("setup", "modes"),
    [
        ({"marginalize": False}, 1),
        ({}, 1),
        ({"likelihood": "student"}, 1),
        pytest.param({"marginalize": False}, 3, marks=pytest.mark.slow),
        ({}, 3),
        pytest.param({"adc": True}, 1, marks=pytest.mark.slow),
        ({"wander": 2e-3}, 1),
    ],
)
@pytest.mark.slow
def test_log_prob_on_grid_equals_direct(setup, modes):
    """The batch (gridded path taken) equals the direct log-probability walker by walker;
    also with a clock wandering by 2 ms (two samples) over the recording, which only a grid
    with its own start per row can follow."""
    setup = dict(setup)
    obs = decay(0, wander=setup.pop("wander", 0.0))
    if setup.pop("adc", False):
        obs = wi.Observation(obs.t, 1000 * obs.y, observable="adc", gain=None, name="adc")
    prob = P.setup_posterior(wi.paper_record(), obs, n_modes=modes, **setup)
    assert prob.model.grid_degrees[0] is not None
    z = prob.z0 + 1e-4 * np.random.default_rng(1).standard_normal((16, prob.z0.size))
    assert _grid_ok(prob, z).all()
    lp, ref = prob.log_prob(z), _direct(prob, z)
    assert np.all(np.isfinite(ref))
    np.testing.assert_allclose(lp, ref, rtol=1e-12, atol=0)


@pytest.mark.slow
def test_batch_falls_back_to_direct_columns():
    """One walker whose |λ| max|δ| is beyond the Taylor radius sends the whole batch down the
    direct path: its value is the direct one, where the gridded columns would be off."""
    prob = P.setup_posterior(wi.paper_record(), decay(0), n_modes=1, marginalize=False)
    m = prob.model
    (degree,) = m.grid_degrees[0]
    dmax = float(prob.args["grids"][0]["dmax"])
    f1 = float(prob.record.whisker().natural_frequencies_hz[0])
    z = np.tile(prob.z0, (16, 1))
    # f_1 ∝ √κ: one walker at four times the f_1 the Taylor radius allows (still inside the
    # default prior, f̂/10 … 10 f̂).
    f_far = 4 * G._taylor_radius(degree) / dmax / (2 * np.pi)
    assert f_far < 10 * f1
    z[5, prob.names.index("log_kappa")] += 2 * math.log(f_far / f1)
    ok = _grid_ok(prob, z)
    assert not ok[5] and ok[np.arange(16) != 5].all()
    lp, ref = prob.log_prob(z), _direct(prob, z)
    assert np.isfinite(ref[5])
    np.testing.assert_allclose(lp, ref, rtol=1e-14, atol=0)
    forced = jax.vmap(lambda v: L.log_prob_one(m, v, prob.args, L._grid_tables(m, v, prob.args)[0]))
    assert abs(float(forced(z)[5]) - ref[5]) > 1e-9  # what the fallback avoided
    # Without that walker the batch is gridded again (and equal to direct to rounding).
    z[5] = z[4]
    assert _grid_ok(prob, z).all()
    np.testing.assert_allclose(prob.log_prob(z), _direct(prob, z), rtol=1e-12, atol=0)


@pytest.mark.slow
def test_no_grid_for_irregular_timestamps():
    """A dropped sample makes the offsets in its row of the grid half a step; three modes
    then need more than the maximum Taylor degree and the recording is evaluated directly."""
    obs = decay(0, drop=[250])
    one = P.setup_posterior(wi.paper_record(), obs, n_modes=1, marginalize=False)
    assert one.model.grid_degrees[0] is not None  # one mode: still within the cap
    three = P.setup_posterior(wi.paper_record(), obs, n_modes=3, marginalize=False)
    assert three.model.grid_degrees == (None,)
    assert three.args["grids"][0] is None
    z = three.z0 + 1e-4 * np.random.default_rng(2).standard_normal((4, three.z0.size))
    np.testing.assert_allclose(three.log_prob(z), _direct(three, z), rtol=1e-14, atol=0)


@pytest.mark.parametrize("degree", [1, 4, 7, 10, 16])
def test_taylor_radius_bounds_the_truncation(degree):
    """Within ``_taylor_radius(p)`` the degree-p Taylor polynomial of e^x is within the
    tolerance relative to |e^x| (checked in extended precision on the circle)."""
    r = G._taylor_radius(degree)
    x = r * np.exp(1j * np.linspace(0, 2 * np.pi, 64, endpoint=False)).astype(np.clongdouble)
    poly = sum(x**k / math.factorial(k) for k in range(degree + 1))
    rel = np.abs(poly - np.exp(x)) / np.abs(np.exp(x))
    assert np.max(rel) <= G._TAYLOR_TOL * 1.001
    above = None if degree == G._TAYLOR_MAX_DEGREE else degree + 1
    assert G._taylor_degree(r) == degree and G._taylor_degree(r * 1.01) == above


def test_packed_arguments_round_trip():
    args = {"a": jnp.arange(3.0), "b": [{"c": jnp.asarray(2.5)}, jnp.ones((2, 2))], "n": 7}
    layout, flat = L._pack(args)
    out = L._unpack(layout, flat)
    assert jax.tree_util.tree_structure(out) == jax.tree_util.tree_structure(args)
    for x, y in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(args), strict=True):
        assert x.dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(x, y)


@pytest.mark.slow
@pytest.mark.parametrize("marginal", [pytest.param(True, marks=pytest.mark.slow), False])
def test_log_prob_gradients_direct_and_gridded(marginal):
    """The log-density is differentiable on both paths, forward and reverse (NUTS needs
    reverse mode; the marginal model's one variadic reduction has a JVP of its own), and
    both paths give the same gradient. Finite-difference step 1e-6: the posterior is so
    narrow in log κ (sd ≈ 1e-4) that the default step's curvature error shows."""
    from jax.test_util import check_grads

    prob = P.setup_posterior(wi.paper_record(), decay(0), n_modes=1, marginalize=marginal)
    z = jnp.asarray(prob.z0) + 1e-3

    def direct(v):
        return L.log_prob_one(prob.model, v, prob.args)

    def gridded(v):
        return L.log_prob_one(prob.model, v, prob.args, L._grid_tables(prob.model, v, prob.args)[0])

    assert bool(L._grid_tables(prob.model, z, prob.args)[1])  # the gridded path is exact here
    for fn in (direct, gridded):
        check_grads(fn, (z,), order=1, modes=("fwd", "rev"), eps=1e-6)
    np.testing.assert_allclose(jax.grad(gridded)(z), jax.grad(direct)(z), rtol=1e-9, atol=1e-9)
