"""The numbers of a nonlinear calibration as two compiled programs, kept between runs.

Everything :func:`whiskerid.fit.calibrate_nonlinear` computes with JAX is two traced
functions, each run through :func:`whiskerid.fit._numerics.cached_call` (one program per problem
structure and shape bucket, exported on disk and loaded by later runs without tracing):

* :func:`nonlinear_core`: the least squares from the linear optimum, each recording weighted
  by its own residual scale and solved again, the residuals and Jacobian at the optimum,
  ``(JᵀJ)⁻¹``, ``s²``, MINPACK's gradient cosine, and per recording the fitted curve, each
  mode's part of it, mode 1's envelope ``a(t)`` and the observed amplitude per metre of tip
  deflection;
* :func:`nonlinear_reported`: the reported quantities and the backbone at the amplitude grid,
  with their Jacobian (the grid is read from the first program's envelopes and noise, so it
  is a second program).

Shape buckets, as the linear fit's (module ``_linear._program``): every recording is padded to its
bucket with zero-weight samples (its last instant repeated: the slow flow takes steps of
length 0 there and the design's time span is the recording's own), so that recordings of
other lengths in one bucket share both programs. The padding enters no sum: residuals and
Jacobian rows are 0 (:attr:`NonlinearProblem.masks`), each recording's weight and ``s²``
count its real samples only, dry friction's held level averages real samples only, and the
padded rows and curve samples are cut off before anything else reads them (HAC covariance,
per-recording figures, window fits).

Called eagerly, the same steps were dozens of small programs traced and looked up afresh in
every process: about 4 s of a warm command-line nonlinear calibration.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._linear import padded_problem as pad_base
from .._linear import padded_rows
from .._numerics import cached_call, lsq


def _flat_residuals(flat, problem):
    return problem.residuals(problem.unflatten(flat))


def _weights(problem, params):
    """``1/σ`` of each recording's own residuals at ``params`` (its real samples)."""
    weights = []
    for (D, g, _), r, p, m in zip(problem.design(params), problem.base.recordings,
                                  params["recs"], problem.masks, strict=True):  # fmt: skip
        res = (D @ p["c"] + g - r.y) * m
        sigma = jnp.sqrt(jnp.sum(res**2) / jnp.maximum(jnp.sum(m) - D.shape[1], 1.0))
        weights.append(1.0 / jnp.maximum(sigma, 1e-12))
    return jnp.stack(weights)


def padded(problem):
    """``problem`` with every recording padded to its shape bucket (zero-weight samples, the
    masks in :attr:`NonlinearProblem.masks`; module docstring), and the real lengths."""
    sizes = [int(r.t.shape[0]) for r in problem.base.recordings]
    base, masks = pad_base(problem.base)
    out = eqx.tree_at(lambda q: (q.base, q.masks), problem, (base, tuple(masks)),
                      is_leaf=lambda x: x is None)  # fmt: skip
    return out, sizes


def _nonlinear_weighted(problem, weights):
    n = len(problem.base.recordings)
    return eqx.tree_at(lambda q: [r.weight for r in q.base.recordings], problem,
                       [weights[i] for i in range(n)])  # fmt: skip


def nonlinear_core(problem, flat0, *, solver: str, max_steps: int, observed_per_metre) -> dict:
    """Solve, reweight, solve again, and everything read at the optimum (module docstring).

    Args:
        problem: The :class:`whiskerid.fit.NonlinearProblem` (or one with free modes), padded
            (:func:`padded`).
        flat0: Start parameters (flat), the linear optimum plus zero nonlinear terms.
        solver: Least-squares solver name.
        max_steps: Solver step limit.
        observed_per_metre: ``fn(recording, mode, whisker)``, the observed amplitude per metre
            of mode-1 tip deflection.

    Returns:
        A dict of arrays: ``value``, ``ok``, ``steps``, ``cost``, ``weights``, ``resid``,
        ``jac``, ``bread``, ``s2``, ``gcos``, and per recording ``i``: ``model_i`` (the
        normalised fitted curve), ``modal_i`` (each mode's part, ``(n, n_modes)``), ``env_i``
        (mode 1's tip amplitude, m) and ``per_m_i``.
    """
    solver_impl = lsq.make_solver(solver)

    # Two solves, the first with the linear fit's weights and the second with the weights of
    # the first's residuals, as one scanned body: a program half the size, which takes half
    # the time to load from the cache.
    def one_pass(carry, _):
        flat, weights = carry
        weighted = _nonlinear_weighted(problem, weights)
        res = lsq.least_squares(_flat_residuals, flat, weighted, solver=solver_impl,
                                 max_steps=max_steps)  # fmt: skip
        new = _weights(weighted, problem.unflatten(res.value))
        return (res.value, new), (res.ok, res.steps, res.cost, weights)

    start = jnp.stack([r.weight for r in problem.base.recordings])
    (flat, _), (ok, steps, cost, used) = jax.lax.scan(one_pass, (flat0, start), None, length=2)
    problem = _nonlinear_weighted(problem, used[-1])
    resid = _flat_residuals(flat, problem)
    jac = jax.jacfwd(_flat_residuals)(flat, problem)
    n_real = sum(jnp.sum(m) for m in problem.masks)  # the padding counts for nothing
    out = {
        "value": flat,
        "ok": ok[-1],
        "steps": steps[-1],
        "cost": cost[-1],
        "weights": used[-1],
        "resid": resid,
        "jac": jac,
        "bread": lsq.scaled_inverse_gram(jac),
        "s2": jnp.sum(resid**2) / jnp.maximum(n_real - flat.size, 1.0),
        "gcos": lsq.gradient_cosine_from(jac, resid),
    }
    params = problem.unflatten(flat)
    w, mode = problem.base.whisker(params), problem.mode(params)
    nm = problem.base.n_modes
    for i, ((D, g, a), rec, p) in enumerate(
        zip(problem.design(params), problem.base.recordings, params["recs"], strict=True)
    ):
        out[f"model_{i}"] = D @ p["c"] + g
        cols = D[:, 2 : 2 + 2 * nm] * p["c"][2 : 2 + 2 * nm]
        out[f"modal_{i}"] = cols[:, :nm] + cols[:, nm:]
        out[f"env_{i}"] = a
        out[f"per_m_{i}"] = observed_per_metre(rec, mode, w)
    return out


def nonlinear_reported(problem, flat, amplitudes) -> dict:
    """The reported quantities at ``flat`` and the backbone at ``amplitudes`` (m), stacked in
    :meth:`NonlinearProblem.reported`'s order, and their Jacobian in the flat parameters."""

    def fn(f):
        return jnp.stack(list(problem.reported(problem.unflatten(f), amplitudes).values()))

    return {"values": fn(flat), "jac": jax.jacfwd(fn)(flat)}


def solve_nonlinear(problem, flat0, *, solver: str, max_steps: int, observed_per_metre):
    """:func:`nonlinear_core` through the program cache (one per shape bucket), as NumPy with
    the padding cut off, with the (unpadded) problem carrying the weights of its last solve.

    Returns:
        ``(problem, out)``: the reweighted problem and the program's outputs (NumPy).
    """
    fn = functools.partial(nonlinear_core, solver=solver, max_steps=max_steps,
                           observed_per_metre=observed_per_metre)  # fmt: skip
    big, sizes = padded(problem)
    out = cached_call("nonlinear", fn, (big, flat0), static=(solver, max_steps))
    out = {k: np.asarray(v) for k, v in out.items()}
    rows = padded_rows(sizes, [m.size for m in big.masks], out["resid"].size)
    out["resid"], out["jac"] = out["resid"][rows], out["jac"][rows]
    for i, n in enumerate(sizes):
        for key in ("model", "modal", "env"):
            out[f"{key}_{i}"] = out[f"{key}_{i}"][:n]
    weights = [out["weights"][i] for i in range(len(problem.base.recordings))]
    problem = eqx.tree_at(lambda q: [r.weight for r in q.base.recordings], problem, weights)
    return problem, out


def nonlinear_reported_with_jacobian(problem, flat, amplitudes) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nonlinear_reported` through the program cache: ``(values, jacobian)`` (the
    problem padded to its buckets: the values do not read the samples, the program's key
    does)."""
    out = cached_call("nonlinear-reported", nonlinear_reported,
                      (padded(problem)[0], np.asarray(flat), np.asarray(amplitudes)))  # fmt: skip
    return np.asarray(out["values"]), np.asarray(out["jac"])
