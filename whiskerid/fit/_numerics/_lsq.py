"""Least-squares plumbing shared by calibration and per-window features (optimistix).

Residual functions have the optimistix signature ``fn(params, args) -> residuals``. Fits
never raise on a failed solve (``throw=False``): each returns a status, so one bad fit in a
``vmap``-ed batch does not spoil the others. optimistix has no bounds: positive or
bounded parameters are fitted through the transforms below.
"""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ..._choices import SOLVERS


def make_solver(name: str = "levenberg-marquardt", *, rtol: float = 1e-10, atol: float = 1e-12):
    """An optimistix least-squares solver by name (Levenberg–Marquardt by default).

    Gauss–Newton is offered but diverged on five-mode fits where the other two converged.
    """
    solvers = {
        "levenberg-marquardt": optx.LevenbergMarquardt,
        "dogleg": optx.Dogleg,
        "gauss-newton": optx.GaussNewton,
    }
    if name not in solvers:
        raise ValueError(f"solver must be one of {', '.join(SOLVERS)}; got {name!r}")
    return solvers[name](rtol=rtol, atol=atol)


class FitResult(eqx.Module):
    """Outcome of one fit (or a batch of fits, with a leading batch axis everywhere).

    Attributes:
        value: Parameters at the optimum (same pytree as the start values).
        ok: True where the solver reported success.
        steps: Solver steps taken.
        cost: Half the sum of squared residuals at the optimum.
        n_residuals: Number of residuals (static).
    """

    value: Any
    ok: jax.Array
    steps: jax.Array
    cost: jax.Array
    n_residuals: int = eqx.field(static=True)


def least_squares(
    fn, y0, args=None, *, solver=None, max_steps: int = 256, options: dict | None = None
) -> FitResult:
    """Minimise ``½‖fn(y, args)‖²`` from ``y0``; never raises on failure (see ``ok``)."""
    solver = make_solver() if solver is None else solver
    sol = optx.least_squares(fn, solver, y0, args=args, throw=False, max_steps=max_steps,
                             options=options)  # fmt: skip
    r = fn(sol.value, args)
    n = sum(x.size for x in jax.tree_util.tree_leaves(r))
    cost = 0.5 * sum(jnp.sum(x**2) for x in jax.tree_util.tree_leaves(r))
    ok = (sol.result == optx.RESULTS.successful) & jnp.isfinite(cost)
    return FitResult(sol.value, ok, jnp.asarray(sol.stats["num_steps"]), cost, n)


def batch_least_squares(fn, y0, args, *, solver=None, max_steps: int = 256) -> FitResult:
    """Many independent fits at once: ``y0`` and ``args`` carry a leading batch axis.

    Compiled once per shape with ``eqx.filter_jit(eqx.filter_vmap(...))``; a failed fit only
    sets its own ``ok`` to False.
    """

    solver = make_solver() if solver is None else solver
    return _batch(fn, y0, args, solver, max_steps)


@eqx.filter_jit
def _batch(fn, y0, args, solver, max_steps):
    # A module-level jitted function: compiled once per residual function, solver and
    # shapes, and reused by later calls (a closure jitted per call would compile every time).
    return eqx.filter_vmap(
        lambda y, a: least_squares(fn, y, a, solver=solver, max_steps=max_steps)
    )(y0, args)


def residual_covariance(fn, y, args=None) -> tuple[jax.Array, jax.Array]:
    """Parameter covariance from the Jacobian at the optimum, scaled by the residual variance.

    ``Σ = s² (JᵀJ)⁻¹`` with ``s² = ‖r‖²/(n − p)``; ``y`` must be a flat 1-D array.

    ``JᵀJ`` is never formed: its condition number is the square of ``J``'s, and the
    parameters of a whisker fit span many orders of magnitude (a log-stiffness next to a
    damping ratio and amplitudes), so a pseudo-inverse of ``JᵀJ`` would drop well-determined
    directions as if they were rounding noise. Instead ``J``'s columns are scaled to unit
    norm, ``J D⁻¹ = U S Vᵀ`` (SVD), and ``Σ = s² D⁻¹ V S⁻² Vᵀ D⁻¹``; only directions whose
    singular value is below ``max(n, p)·eps`` of the largest (truly undetermined) are left
    out, as a pseudo-inverse does.

    Returns:
        ``(covariance, s²)``.
    """
    r = fn(y, args)
    jac = jax.jacfwd(lambda p: fn(p, args))(y)
    s2 = residual_variance(r, y.size)
    return s2 * scaled_inverse_gram(jac), s2


def residual_variance(r, n_params: int):
    """``s² = ‖r‖²/(n − p)``: the residual variance left after fitting ``n_params``."""
    return (r**2).sum() / max(r.size - n_params, 1)


# Jitted: called on concrete Jacobians (reports, checks) each is one compiled program, not one
# per operation; inside a traced function it is inlined.
@jax.jit
def scaled_inverse_gram(jac: jax.Array) -> jax.Array:
    """``(JᵀJ)⁺`` through the SVD of ``J`` with unit-norm columns (see :func:`covariance`)."""
    return scaled_inverse_gram_svd(jac)[0]


def scaled_inverse_gram_svd(jac: jax.Array):
    """:func:`scaled_inverse_gram` and the SVD it took: ``(bread, (d, U, S, Vᵀ))`` with
    ``J = U S Vᵀ diag(d)`` (the score tests project on ``U``: module ``_projector``)."""
    norms = jnp.linalg.norm(jac, axis=0)
    d = jnp.where(norms > 0, norms, 1.0)
    u, s, vt = jnp.linalg.svd(jac / d, full_matrices=False)
    cut = s[0] * max(jac.shape) * jnp.finfo(jac.dtype).eps
    inv_s2 = jnp.where(s > cut, 1.0 / jnp.where(s > cut, s, 1.0) ** 2, 0.0)
    w = vt.T / d[:, None]
    return (w * inv_s2) @ w.T, (d, u, s, vt)


def gradient_cosine(fn, y, args=None) -> jax.Array:
    """MINPACK's ``gtol`` measure at ``y``: the largest ``|cos|`` between the residual
    vector and a column of the Jacobian (0 at a stationary point, whatever the scales of
    the parameters and residuals); ``y`` must be a flat 1-D array."""
    r = fn(y, args)
    return gradient_cosine_from(jax.jacfwd(lambda p: fn(p, args))(y), r)


@jax.jit
def gradient_cosine_from(jac: jax.Array, r: jax.Array) -> jax.Array:
    """:func:`gradient_cosine` from the Jacobian ``(n, p)`` and the residuals ``(n,)``."""
    norms = jnp.linalg.norm(jac, axis=0) * jnp.linalg.norm(r)
    return jnp.max(jnp.abs(jac.T @ r) / jnp.maximum(norms, jnp.finfo(r.dtype).tiny))


@jax.jit
def correlation(cov: jax.Array) -> jax.Array:
    """Correlation matrix of a covariance matrix."""
    sd = jnp.sqrt(jnp.diag(cov))
    return cov / jnp.outer(sd, sd)


# Transforms: unconstrained u ↔ constrained value.
def to_positive(u):
    """``exp(u)``: strictly positive values."""
    return jnp.exp(u)


def from_positive(x):
    """Inverse of :func:`to_positive`."""
    return jnp.log(x)


def to_interval(u, lo, hi):
    """``lo + (hi − lo) sigmoid(u)``: values strictly inside ``(lo, hi)``."""
    return lo + (hi - lo) * jax.nn.sigmoid(u)


def from_interval(x, lo, hi):
    """Inverse of :func:`to_interval`."""
    p = (x - lo) / (hi - lo)
    return jnp.log(p) - jnp.log1p(-p)


# Small dense solves written element by element.
def cholesky_small(a) -> list[list[Any]]:
    """Cholesky factor ``L`` (``a = L Lᵀ``) of a small symmetric matrix, unrolled.

    ``a`` is a ``k × k`` nested sequence (only the lower triangle is read) whose entries are
    arrays of one shape, e.g. one value per window of a batch. Every operation is then an
    element-wise vector operation across the batch: XLA's CPU ``cholesky``/``solve`` under
    ``vmap`` loops over the batch one small LAPACK call at a time, which costs far more than
    the arithmetic for 2×2…5×5 systems. A matrix that is not positive definite gives NaN.

    Returns:
        ``L`` as a nested list (entries above the diagonal are None).
    """
    k = len(a)
    L = [[None] * k for _ in range(k)]
    for j in range(k):
        L[j][j] = jnp.sqrt(a[j][j] - sum(L[j][m] ** 2 for m in range(j)))
        for i in range(j + 1, k):
            L[i][j] = (a[i][j] - sum(L[i][m] * L[j][m] for m in range(j))) / L[j][j]
    return L


def cho_solve_small(L, b) -> list[Any]:
    """``(L Lᵀ)⁻¹ b`` for ``L`` from :func:`cholesky_small`; ``b`` is a list of ``k`` arrays."""
    k = len(b)
    u = []
    for i in range(k):
        u.append((b[i] - sum(L[i][m] * u[m] for m in range(i))) / L[i][i])
    x = [None] * k
    for i in reversed(range(k)):
        x[i] = (u[i] - sum(L[m][i] * x[m] for m in range(i + 1, k))) / L[i][i]
    return x
