"""The linear Jacobian factored once: each Gauss–Newton step along [J, Z] and each Z⊥ must be
the joint least-squares solve's, which the score tests used to compute one by one."""

import numpy as np
import pytest

from whiskerid.fit._checks._checks import lag_below
from whiskerid.fit._choice._model_error import step_map
from whiskerid.fit._choice._scores import test_lags as lags_of
from whiskerid.fit._data._signal import fast_length
from whiskerid.fit._numerics._projector import ColumnSubsets, LinearPart, pinv_columns


def _problem(seed=0, n=400, p=6, k=3):
    rng = np.random.default_rng(seed)
    # columns of very different scales, as a fit's Jacobian has (log-stiffness beside
    # amplitudes), and extra columns partly in J's span
    jac = rng.standard_normal((n, p)) * np.logspace(-3, 3, p)
    z = rng.standard_normal((n, k)) + jac[:, :k] @ rng.standard_normal((k, k)) * 1e-2
    return jac, z, rng.standard_normal(n)


def test_the_split_step_is_the_joint_least_squares_step():
    jac, z, r = _problem()
    a = np.concatenate([jac, z], axis=1)
    scale = np.linalg.norm(a, axis=0)
    joint = np.linalg.lstsq(a / scale, -r, rcond=None)[0] / scale
    d_j, d_z, r_alt = LinearPart(jac).gauss_newton(r, z)
    np.testing.assert_allclose(np.concatenate([d_j, d_z]), joint, rtol=1e-9, atol=0)
    np.testing.assert_allclose(r_alt, r + a @ joint, rtol=0, atol=1e-10 * np.abs(r).max())


def test_the_projection_is_orthogonal_to_J_and_leaves_what_J_cannot_fit():
    jac, z, _ = _problem(1)
    zp = LinearPart(jac).project(z)
    assert np.abs(jac.T @ zp).max() < 1e-9 * np.abs(jac).max() * np.abs(z).max() * z.shape[0]
    coef = np.linalg.lstsq(jac, z - zp, rcond=None)[0]
    np.testing.assert_allclose(jac @ coef, z - zp, atol=1e-9 * np.abs(z).max())


def test_step_map_gives_the_joint_step_of_chosen_parameters_for_residuals_off_J():
    jac, z, r = _problem(2)
    r = LinearPart(jac).project(r[:, None])[:, 0]  # at J's own optimum: Jᵀr = 0
    idx = [1, 4]
    a = np.concatenate([jac, z], axis=1)
    joint = np.linalg.lstsq(a, -r, rcond=None)[0]
    np.testing.assert_allclose(step_map(jac, z, idx).T @ r, joint[idx], rtol=1e-8)


def test_each_subsets_step_from_one_qr_is_its_own_least_squares_step():
    jac, z, r = _problem(3)
    # a fourth column nearly the sum of two others: a badly conditioned subset
    z = np.concatenate([z, (z[:, :1] + z[:, 1:2]) * (1 + 1e-7)], axis=1)
    zp = LinearPart(jac).project(z)
    subsets = ColumnSubsets(zp)
    for idx in [(0,), (2,), (0, 1), (1, 2), (0, 1, 2), (0, 1, 3), (0, 1, 2, 3)]:
        own = pinv_columns(zp[:, idx]) @ r
        np.testing.assert_allclose(subsets.step(idx, r), own, rtol=1e-7, atol=0)
        scale = np.linalg.norm(zp[:, idx], axis=0)
        lstsq = np.linalg.lstsq(zp[:, idx] / scale, r, rcond=None)[0] / scale
        np.testing.assert_allclose(subsets.step(idx, r), lstsq, rtol=1e-7, atol=0)


def test_the_lags_of_many_residual_vectors_are_each_ones_own():
    rng = np.random.default_rng(4)
    for n in (78, 2048):
        rows = [rng.standard_normal(n)]  # white: no lag
        rows += [np.convolve(rng.standard_normal(n), np.ones(w), "same") for w in (2, 5, 9)]
        rs = np.stack(rows)
        limit = max(0.1, float(np.sqrt(2.0 * np.log(n) / n)))
        own = [lag_below(row, limit) for row in rs]
        want = [0 if lag <= 1 else min(lag, n // 4) for lag in own]
        assert lags_of(rs) == want
        assert want[0] == 0 and max(want[1:]) > 1  # both kinds are in the test


def test_every_subsets_step_at_once_is_each_subsets_own_step():
    jac, z, r = _problem(5)
    z = np.concatenate([z, (z[:, :1] + z[:, 1:2]) * (1 + 1e-7)], axis=1)
    subsets = ColumnSubsets(LinearPart(jac).project(z))
    todo = [(0,), (2,), (0, 1), (1, 2), (0, 1, 2), (0, 1, 3), (0, 1, 2, 3)]
    batch = subsets.steps(todo, r)
    for row, idx in zip(batch, todo, strict=True):
        np.testing.assert_allclose(row[list(idx)], subsets.step(idx, r), rtol=1e-7, atol=0)
        assert np.all(np.delete(row, list(idx)) == 0)


def test_white_statistics_are_the_score_tests_statistics_without_lags():
    from whiskerid.fit._choice._scores import score_statistic, white_statistics

    jac, z, r = _problem(6)
    zp = LinearPart(jac).project(z)
    zp[:, 1] *= 1e3  # a subset's columns keep their own scales
    rng = np.random.default_rng(6)
    todo = [(0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]
    r_alts = r + 0.3 * rng.standard_normal((len(todo), r.size))
    r_alts[1, :] = 0.0  # a variance of zero: its column is left out, T = 0
    stats, dof = white_statistics(zp, r, r_alts, todo, dof=True)
    for k, idx in enumerate(todo):
        own = score_statistic(zp[:, list(idx)], r, r_alts[k], [r.size], [0])
        assert dof[k] == own["dof"]
        np.testing.assert_allclose(stats[k], own["statistic"], rtol=1e-10, atol=1e-300)
    assert stats[1] == 0.0 and dof[1] == 0
    assert min(stats[k] for k in (0, 2, 3)) > 0


@pytest.mark.parametrize("n", [300, 1009])
def test_lag_below_is_where_the_tail_of_the_autocorrelation_stays_below_the_limit(n):
    """Against the autocorrelation summed lag by lag; at 1009 samples (prime) the
    transform's length is not 2n but the next length of small prime factors (2025)."""
    rng = np.random.default_rng(7)
    rows = [rng.standard_normal(n), np.cumsum(rng.standard_normal(n)),
            np.sin(0.3 * np.arange(n)) + 0.05 * rng.standard_normal(n)]  # fmt: skip
    for row in rows:
        rc = row - row.mean()
        acf = np.correlate(rc, rc, "full")[row.size - 1 :] / (rc @ rc)
        for limit in (0.1, 0.3):
            tail = np.maximum.accumulate(np.abs(acf)[::-1])[::-1]
            want = int(np.argmax(tail < limit)) if np.any(tail < limit) else row.size
            assert lag_below(row, limit) == want
    assert lag_below(rows[1], 0.1) > 10 and lag_below(rows[0], 0.3) == 1


def test_the_fast_length_is_the_next_length_of_factors_2_3_and_5():
    def smooth(m):
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        return m == 1

    for n in range(1, 3000):
        want = next(m for m in range(n, 2 * n + 1) if smooth(m))
        assert fast_length(n) == want, n
    assert fast_length(2 * 158_988) == 320_000  # 2n = 2³·3·13 249
