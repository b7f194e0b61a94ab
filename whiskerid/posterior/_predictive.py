"""Posterior-predictive recordings: each recording simulated at posterior draws, noise included.

At a draw ``z`` of the sampled space the model's design ``(D, g)`` of recording ``j`` is built
as the likelihood builds it; its linear coefficients are the draw's own where they are sampled
(Student-t, the nonlinear model) and, where they are marginalised, a draw from their
conditional posterior ``N(ĉ, σ_j² (DᵀD)⁻¹)`` (flat prior on ``c``); the simulated recording is
``D c + g + σ_j ε`` with ``ε`` standard normal (the Gaussian likelihood's noise; Student-t draws
under ``likelihood = "student"``). Values are returned in the recording's observed units
(the normalisation undone) at its own timestamps.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..fit import recording_design
from ._likelihood import _unravel
from ._problem import Problem


@eqx.filter_jit
def _linear_designs(problem, marginal, flat):
    """Designs ``(D, g)`` of every recording, and the parameter pytrees, at each row of
    ``flat`` (one compiled call for all the draws: called draw by draw, the dispatch of the
    problem's pytree cost 60 ms a draw)."""

    def one(v):
        theta = _unravel(problem, marginal)(v)
        recs = theta.get("recs") or [{}] * len(problem.recordings)
        designs = [
            recording_design(r, problem.whisker_of(theta, j), rp)
            for j, (r, rp) in enumerate(zip(problem.recordings, recs, strict=True))
        ]
        return designs, theta

    return jax.vmap(one)(flat)


@eqx.filter_jit
def _nonlinear_designs(problem, flat):
    def one(v):
        theta = problem.unflatten(v)
        return [(D, g) for D, g, _ in problem.design(theta)], theta

    return jax.vmap(one)(flat)


def recordings_of(prob: Problem):
    """The fit's recordings (normalised), with each observation's mean, σ and start time."""
    problem = prob.args["problem"]
    recs = getattr(problem, "base", problem).recordings
    out = []
    for rec, o in zip(recs, prob.observations, strict=True):
        y = np.asarray(o.y, float)
        out.append((rec, float(np.mean(y)), float(np.std(y)), float(o.t[0])))
    return out


def observed(prob: Problem) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each recording's ``(t, y)`` as the fit saw it, in observed units."""
    return [
        (np.asarray(rec.t) + t0, np.asarray(rec.y) * std + mean)
        for rec, mean, std, t0 in recordings_of(prob)
    ]


def predictive_draws(prob: Problem, z: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    """Simulated recordings at the sampled-space points ``z`` ``(m, ndim)``.

    Returns:
        One array ``(m, n_j)`` per recording, in observed units.
    """
    m = prob.model
    problem = prob.args["problem"]
    nonlinear = getattr(problem, "base", None) is not None
    recs = recordings_of(prob)
    z = np.asarray(z, float)
    out = [np.empty((len(z), np.size(rec.t))) for rec, *_ in recs]
    flat = jnp.asarray(z[:, : m.n_theta])
    if nonlinear:
        designs, theta = _nonlinear_designs(problem, flat)
    else:
        designs, theta = _linear_designs(problem, m.marginal, flat)
    designs = [(np.asarray(D), np.asarray(g)) for D, g in designs]
    coefs = None if m.marginal else [np.asarray(r["c"]) for r in theta["recs"]]
    for i, v in enumerate(z):
        sigma = np.exp(v[m.n_theta :])
        for j, ((D_all, g_all), (rec, mean, std, _)) in enumerate(zip(designs, recs, strict=True)):
            D, g, y = D_all[i], g_all[i], np.asarray(rec.y)
            if m.marginal:
                c_hat, *_ = np.linalg.lstsq(D, y - g, rcond=None)
                # c | θ, σ, y ~ N(ĉ, σ² (DᵀD)⁻¹): through the QR factor of D
                r = np.linalg.qr(D, mode="r")
                c = c_hat + sigma[j] * np.linalg.solve(r, rng.standard_normal(D.shape[1]))
            else:
                c = coefs[j][i]
            if m.likelihood == "student":
                eps = rng.standard_t(prob.nu, size=y.size)
            else:
                eps = rng.standard_normal(y.size)
            out[j][i] = (D @ c + g + sigma[j] * eps) * std + mean
    return out
