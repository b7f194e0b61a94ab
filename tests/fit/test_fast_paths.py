"""The calibration's light replacements give what they replace.

The warm command line avoids SciPy (its import costs more than the fit) and JAX calls outside
the compiled program (each costs a lowering and a cache read): the χ² and F survival functions
against ``scipy.stats``, the release finder's Levenberg–Marquardt against
``scipy.optimize.least_squares(method="lm")`` on the finder's own fits, and the amplitude test
on what the compiled program returns against the same test computed with JAX afterwards.
"""

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.fit._data import _release as _release
from whiskerid.fit._numerics._chi2 import chi2_sf
from whiskerid.fit._numerics._fdist import f_sf
from whiskerid.fit._numerics._lm import lm_least_squares


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5, 8, 11])
def test_chi2_survival_matches_scipy(k):
    from scipy.stats import chi2

    x = np.concatenate([np.geomspace(1e-6, 900.0, 60), [k - 1.0, k, k + 1.0]])
    ours = np.array([chi2_sf(v, k) for v in x])
    theirs = chi2.sf(x, k)
    assert np.all(np.abs(ours - theirs) <= 1e-12 * theirs + 1e-300)
    assert chi2_sf(0.0, k) == 1.0 and chi2_sf(np.inf, k) == 0.0
    with pytest.raises(ValueError, match="whole number"):
        chi2_sf(1.0, 1.5)


@pytest.mark.parametrize(
    ("d1", "d2"), [(1.0, 1.0), (5.0, 2.5), (40.0, 12.7), (900.0, 300.5), (2e4, 51.0)]
)
def test_f_survival_matches_scipy(d1, d2):
    from scipy.stats import f

    x = np.concatenate([np.geomspace(1e-4, 1e3, 60), [0.5, 1.0, 2.0]])
    ours = np.array([f_sf(v, d1, d2) for v in x])
    theirs = f.sf(x, d1, d2)
    assert np.all(np.abs(ours - theirs) <= 1e-9 * theirs + 1e-14)
    assert f_sf(0.0, d1, d2) == 1.0 and f_sf(np.inf, d1, d2) == 0.0
    with pytest.raises(ValueError, match="positive"):
        f_sf(1.0, 0.0, 2.0)


def _two_lines(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(600) / 200.0
    f = rng.uniform(15.0, 35.0)  # the second line at 1.7 f stays below 100 Hz
    y = 3.0 + 0.2 * t + np.exp(-rng.uniform(0.5, 3.0) * t) * np.cos(2 * np.pi * f * t + 0.3)
    y += 0.3 * np.exp(-5.0 * t) * np.sin(2 * np.pi * 1.7 * f * t)
    return t, y + 0.01 * rng.standard_normal(t.size), f


@pytest.mark.parametrize("seed", range(4))
def test_levenberg_marquardt_finds_scipys_optimum_of_the_decay_fit(seed):
    """The release finder's variable-projection fit (one and two damped lines, started
    3 % off), solved by ours and by MINPACK's: the same frequencies to 1e-7, the rates (the
    flattest directions) to 1e-5, the same sum of squares to 1e-9."""
    from scipy.optimize import least_squares as scipy_lsq

    t, y, f = _two_lines(seed)
    for x0 in ([1.03 * f, 1.0], [1.03 * f, 1.7 * f, 1.0, 4.0]):
        x0 = np.array(x0)
        n = x0.size // 2

        def resid(x, n=n):
            return _release._linear_fit(t, y, t[0], x[:n], np.abs(x[n:]))

        ours, r = lm_least_squares(resid, x0, max_nfev=200 * x0.size)
        ref = scipy_lsq(resid, x0, method="lm", max_nfev=200 * x0.size)
        assert np.allclose(np.abs(ours[:n]), np.abs(ref.x[:n]), rtol=1e-7), (ours, ref.x)
        assert np.allclose(np.abs(ours[n:]), np.abs(ref.x[n:]), rtol=1e-5), (ours, ref.x)
        assert r @ r <= (ref.fun @ ref.fun) * (1 + 1e-9)


def test_levenberg_marquardt_stops_within_its_budget():
    calls = []

    def fun(x):
        calls.append(1)
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])  # Rosenbrock

    x, _ = lm_least_squares(fun, np.array([-1.2, 1.0]), max_nfev=400)
    assert np.allclose(x, [1.0, 1.0], atol=1e-6)
    calls.clear()
    lm_least_squares(fun, np.array([-1.2, 1.0]), max_nfev=10)
    assert len(calls) <= 10


@pytest.mark.slow  # a calibration compiled (about 20 s on a loaded machine)
def test_amplitude_test_reads_from_the_program_what_jax_computes_afterwards(monkeypatch):
    """The score tests read mode 1's columns, w0, ζ0, the tip factor and the fitted linear
    part from the compiled calibration; computed again with JAX at the fit's optimum they
    are the same, and so is the test on them."""
    from whiskerid.fit._choice import _amplitude as _amplitude

    seen = {}
    real = _amplitude.amplitude_test

    def spy(cal, **kw):
        seen.update(kw)
        return real(cal, **kw)

    monkeypatch.setattr(_amplitude, "amplitude_test", spy)
    record = wi.paper_record()
    sim = wi.simulate(record, excitation="decay", observable="adc", rate_hz=200.0,
                      duration_s=5.0, noise_db=30.0, seed=4, tip_deflection_m=2e-3)  # fmt: skip
    obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
    cal = wi.calibrate(record, obs)
    program = seen["core"]
    again = _amplitude._whisker_terms(cal.problem, cal.optimum)
    assert program["w0"] == pytest.approx(again["w0"], rel=1e-12)
    assert program["zeta0"] == pytest.approx(again["zeta0"], rel=1e-12)
    assert np.allclose(program["tip"], again["tip"], rtol=1e-12)
    for key in ("mode1", "dc"):
        for a, b in zip(program[key], again[key], strict=True):
            assert a.shape == b.shape
            assert np.allclose(a, b, rtol=1e-9, atol=1e-9 * np.max(np.abs(b)))
    test = real(cal, resid=seen["resid"], jac=seen["jac"], core=again)
    for name in ("nonlinear", "split"):
        ours = cal.diagnostics["amplitude_test"][name]
        assert ours["statistic"] == pytest.approx(test[name]["statistic"], rel=1e-8)
        assert ours["p_value"] == pytest.approx(test[name]["p_value"], rel=1e-6, abs=1e-300)


def test_blas_is_held_to_one_thread_while_a_release_is_searched_and_restored_after():
    from threadpoolctl import threadpool_info

    from whiskerid.fit._numerics import _threads as _threads

    seen = []
    real = _release._decay_in

    def spy(*args, **kwargs):
        seen.append({i["filepath"]: i["num_threads"] for i in threadpool_info()
                     if i["user_api"] == "blas"})  # fmt: skip
        return real(*args, **kwargs)

    before = {i["filepath"]: i["num_threads"] for i in threadpool_info()}
    t, y, _ = _two_lines(0)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_release, "_decay_in", spy)
        _release.find_decays(t, y)
    assert seen and all(n == 1 for s in seen for n in s.values())
    assert {i["filepath"]: i["num_threads"] for i in threadpool_info()} == before
    with _threads.one_blas_thread(jax_lapack=True):
        assert all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")


def test_replaced_module_is_the_pytree_tree_at_builds_and_shares_the_layout():
    """The set-up's field replacement (no ``__init__`` again) against ``eqx.tree_at``: the
    same tree structure (static fields included, so the same compiled program) and the same
    leaves; an unknown field is refused; a reweighted problem finds the parameter positions
    of the problem it was made from."""
    import equinox as eqx
    import jax

    from whiskerid.fit._linear import _program as _core
    from whiskerid.fit._linear._problem import FitProblem

    record = wi.paper_record()
    t = np.arange(500) / 200.0
    y = np.exp(-0.5 * t) * np.sin(2 * np.pi * 23.0 * t)
    obs = [wi.Observation(t, y, excitation="decay", observable="deflection", gain=1.0)] * 2
    problem = FitProblem.from_observations(record, obs, n_modes=2)
    padded, masks = _core.padded_problem(problem)
    r = problem.recordings[0]
    size = _core.bucket(r.t.shape[0])
    t_pad = np.concatenate([np.asarray(r.t), np.full(size - r.t.shape[0], r.t[-1])])
    y_pad = np.concatenate([np.asarray(r.y), np.zeros(size - r.t.shape[0])])
    expected = eqx.tree_at(lambda q: (q.t, q.y), r, (t_pad, y_pad))
    expected = eqx.tree_at(lambda q: q.recordings, problem, (expected, expected))
    leaves, treedef = jax.tree_util.tree_flatten(padded)
    leaves_exp, treedef_exp = jax.tree_util.tree_flatten(expected)
    assert treedef == treedef_exp and len(leaves) == len(leaves_exp)
    for a, b in zip(leaves, leaves_exp, strict=True):
        np.testing.assert_array_equal(a, b)
    assert problem.recordings[0].t.shape[0] == 500  # the original is left as it was
    assert [float(m.sum()) for m in masks] == [500.0, 500.0] and masks[0].size == size
    with pytest.raises(AttributeError, match="no field wieght"):
        _core.replaced(r, wieght=2.0)

    weighted = _core.replaced(problem, recordings=tuple(
        _core.replaced(q, weight=np.asarray(3.0)) for q in problem.recordings))  # fmt: skip
    _core.share_layout(problem, weighted)
    for name in ("log_kappa", "zeta_u"):
        np.testing.assert_array_equal(
            _core.positions(weighted, name), _core.positions(problem, name)
        )
    flat = np.arange(problem.flatten(problem.zero_params()).size, dtype=float)
    assert jax.tree_util.tree_all(jax.tree_util.tree_map(
        np.array_equal, _core.unflatten_numpy(weighted, flat),
        problem.unflatten(flat)))  # fmt: skip
