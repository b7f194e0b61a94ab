"""The linear Jacobian factored once: each Gauss–Newton step along [J, Z] and each Z⊥ must be
the joint least-squares solve's, which the score tests used to compute one by one."""

import numpy as np

from whiskerid.fit._model_error import step_map
from whiskerid.fit._projector import LinearPart


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
