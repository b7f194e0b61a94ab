"""Levenberg–Marquardt by variable projection: the calibration's least squares, traceable.

A recording's model is linear in its coefficients ``c`` (offset, drift, the modal terms, a
free forced response), ``y = D(φ) c + g(φ)``, and nonlinear in a few parameters ``φ``
(``log κ``, ζ, a sine's ``τ``, a static test's ``log EI`` and offset). For any ``φ`` the best
``c`` is a linear least-squares solve, so the fit needs to search ``φ`` only (Golub and
Pereyra's variable projection): with the weighted design ``A = w·D`` and data
``b = w·(y − g)``, the projected residual is ``r(φ) = A c*(φ) − b = −(I − QQᵀ) b`` where
``A = QR``. Its Jacobian is Golub and Pereyra's closed form from the QR factors and the
design's derivative (:func:`projection`), which is exact, not Kaufman's approximation.

Why: with ``c`` in the solver's vector, a start whose f_1 is a few tenths of a percent off
leaves the modal terms' phases wrong by a good part of a cycle at the end of a 10 s
recording, and the linearised step cannot rotate ``c`` far enough; optimistix's LM took 9–34
steps from such starts (and up to a dozen at the optimum itself: its test asks every residual
to stop changing at 1e-10, which rounding keeps from happening). Over ``φ`` alone, with
``c`` re-solved at every point, the same fits take a handful of steps.

The minimum is the full problem's: at a stationary point of ``½‖r(φ)‖²`` the gradient in
``c`` is zero by construction and in ``φ`` by the projection's own stationarity, so the
covariance, the gradient test and the reported Jacobian are computed over all parameters at
the point found, as before.

The LM iteration is MINPACK's (as module ``_lm``, here in JAX over an exact Jacobian):
Marquardt's scaling by the largest column norms met so far, the damped step through the SVD
of the scaled Jacobian, ``λ`` adapted by the ratio ``ρ`` of actual to predicted reduction
(Nielsen's rule), a step accepted when ``ρ > 1e-4``, and MINPACK's three tests (relative
reduction of ``‖r‖²``, scaled step, gradient cosine), with tolerances far below any 1σ.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import lsq
from ._problem import FitProblem

#: MINPACK's tests: relative reduction of ‖r‖² (actual and predicted), scaled step relative
#: to the scaled parameters, largest cosine between r and a column of J. At a cost of ~n/2
#: (weighted residuals of unit scale), ftol 1e-12 leaves parameter errors below 1e-4σ.
FTOL, XTOL, GTOL = 1e-12, 1e-10, 1e-10
_ACCEPT = 1e-4


def linear_layout(problem: FitProblem) -> tuple[np.ndarray, list[np.ndarray]]:
    """Positions in the flat parameter vector of the nonlinear parameters, and of each
    recording's linear coefficients ``c`` (from the structure alone, in NumPy)."""
    params = problem.zero_params()
    for i, rec in enumerate(params["recs"]):
        rec["c"] = np.full(np.shape(rec["c"]), float(i + 1))
    flat = np.concatenate([np.ravel(x) for x in jax.tree_util.tree_leaves(params)])
    lin = [np.flatnonzero(flat == i + 1) for i in range(len(params["recs"]))]
    return np.flatnonzero(flat == 0), lin


def projection(problem: FitProblem, masks, size: int):
    """``fn(φ) -> (J, (r, cs))``: the projected weighted residuals (padding rows zero) at the
    nonlinear parameters ``φ``, their Jacobian in ``φ``, and each recording's best linear
    coefficients.

    The Jacobian is Golub and Pereyra's, from the QR factors of the weighted design and the
    design's own derivative (forward mode through the columns only, one tangent per
    nonlinear parameter). With ``A = QR``, ``P⊥ = I − QQᵀ``, ``c = A⁺b`` and ``r = Ac − b``,
    differentiating ``r = −P⊥b`` gives

        ``∂r = P⊥(∂A c − ∂b) − (A⁺)ᵀ ∂Aᵀ r``,   ``(A⁺)ᵀ = Q R⁻ᵀ``,

    exact (not Kaufman's approximation, which drops the second term): the same Jacobian as
    forward mode through the QR factorisation, to rounding, without differentiating the
    factorisation (that took about a third of a warm calibration's program: triangular
    solves of the whole ``Q`` per tangent).
    """
    nl_idx, lin_idx = linear_layout(problem)

    def design(phi):
        params = problem.unflatten(jnp.zeros(size, phi.dtype).at[nl_idx].set(phi))
        static = () if problem.static_test is None else (problem.static_residuals(params),)
        return problem.design(params), static

    def fn(phi):
        # the design and its derivative in φ (columns, fixed part, static residuals)
        (designs, static), (d_designs, d_static) = _design_jacobian(design, phi)
        res, jacs, cs = [], [], []
        for (D, g), (dD, dg), r, m in zip(designs, d_designs, problem.recordings, masks,
                                          strict=True):  # fmt: skip
            wm = r.weight * m
            A, b = D * wm[:, None], (r.y - g) * wm
            dA, db = dD * wm[:, None, None], -dg * wm[:, None]  # (n, q, φ) and (n, φ)
            norms = jnp.linalg.norm(A, axis=0)
            s = jnp.where(norms > 0, norms, 1.0)  # unit columns: R's condition is D's own
            q, rr = jnp.linalg.qr(A / s)
            # A column that vanished (norms 0) adds no direction: its Q column and R row
            # are arbitrary, so they are set to nothing and its coefficient to 0 (and its
            # derivative to nothing: the column stays out of the projection).
            live = norms > 0
            q = q * live
            rr = jnp.where(live[:, None], rr, jnp.eye(rr.shape[0]))
            qb = q.T @ b
            resid = q @ qb - b
            c = jax.scipy.linalg.solve_triangular(rr, qb) / s
            dA = dA * live[None, :, None]
            u = jnp.einsum("nqk,q->nk", dA, c) - db  # ∂A c − ∂b, per parameter
            u = u - q @ (q.T @ u)  # P⊥
            v = jnp.einsum("nqk,n->qk", dA, resid) / s[:, None]  # (∂A diag(1/s))ᵀ r
            v = jax.scipy.linalg.solve_triangular(rr, v, trans="T")  # R⁻ᵀ
            res.append(resid)
            jacs.append(u - q @ v)
            cs.append(c)
        res.extend(static)
        jacs.extend(d_static)
        return jnp.concatenate(jacs), (jnp.concatenate(res), cs)

    return fn, nl_idx, lin_idx


def _design_jacobian(design, phi):
    """``design(φ)`` and its derivative in ``φ``: every leaf gains a trailing axis, one entry
    per nonlinear parameter (forward mode, a tangent per parameter)."""
    basis = jnp.eye(phi.shape[0], dtype=phi.dtype)
    # the primal does not depend on the tangent: computed once, not once per parameter
    return jax.vmap(lambda e: jax.jvp(design, (phi,), (e,)), out_axes=(None, -1))(basis)


def varpro_least_squares(problem: FitProblem, masks, flat0, *, max_steps: int):
    """Minimise the problem's weighted residuals from ``flat0`` by variable projection.

    Args:
        problem: The (padded, weighted) fit problem.
        masks: Per recording, 1 for a sample and 0 for padding.
        flat0: Start parameters, flat (its linear coefficients are not used: they are
            solved at every point).
        max_steps: Most LM iterations (accepted and rejected steps).

    Returns:
        ``(flat, ok, steps)``: the parameters found (linear coefficients solved there),
        whether one of MINPACK's tests was met with a finite cost, and the iterations.
    """
    jac, nl_idx, lin_idx = projection(problem, masks, flat0.size)

    def factor(J, diag):  # the SVD of the scaled Jacobian serves every λ at this point
        return jnp.linalg.svd(J / diag, full_matrices=False)

    # The start is the loop's first pass (no step, always taken), so that the projection
    # and its Jacobian are traced and compiled once, not once more for the start.
    phi0 = flat0[nl_idx]
    J0, (r0, cs0) = jax.eval_shape(jac, phi0)
    zeros = functools.partial(jax.tree_util.tree_map, lambda x: jnp.zeros(x.shape, x.dtype))
    J0, r0, cs0 = zeros(J0), zeros(r0), zeros(cs0)
    state = dict(
        phi=phi0, r=r0, J=J0, cs=cs0, svd=factor(J0, jnp.ones(phi0.shape)), cost=jnp.inf,
        lam=jnp.asarray(1e-3), nu=jnp.asarray(2.0), diag=jnp.ones(phi0.shape),
        steps=jnp.asarray(0), first=jnp.asarray(True), done=jnp.asarray(False),
        ok=jnp.asarray(False),
    )  # fmt: skip

    def body(st):
        first = st["first"]
        u, s, vt = st["svd"]
        ur = u.T @ st["r"]
        scaled = -vt.T @ (s / (s**2 + st["lam"]) * ur)  # D·δ, the damped scaled step
        scaled = jnp.where(first, 0.0, scaled)
        step = scaled / st["diag"]
        linear = st["r"] + (st["J"] / st["diag"]) @ scaled
        predicted = st["cost"] - linear @ linear
        phi_new = st["phi"] + step
        # the trial point's Jacobian with its residuals: one pass, and a step is rarely
        # rejected (an evaluation, then the Jacobian again on acceptance, cost ~20 % more)
        J_new, (r_new, cs_new) = jac(phi_new)
        cost_new = jnp.where(jnp.all(jnp.isfinite(r_new)), r_new @ r_new, jnp.inf)
        actual = st["cost"] - cost_new
        rho = jnp.where(predicted > 0, actual / jnp.where(predicted > 0, predicted, 1.0), -1.0)
        small_step = jnp.linalg.norm(scaled) <= XTOL * jnp.linalg.norm(st["diag"] * st["phi"])
        accept = first | (rho > _ACCEPT)
        ftol = FTOL * st["cost"]
        small_cost = (actual <= ftol) & (predicted <= ftol) & (rho <= 2)

        def accepted(_):
            norms = jnp.linalg.norm(J_new, axis=0)
            diag = jnp.where(first, jnp.where(norms > 0, norms, 1.0),
                             jnp.maximum(st["diag"], norms))  # fmt: skip
            gtest = lsq.gradient_cosine_from(J_new, r_new) <= GTOL
            return phi_new, r_new, J_new, cs_new, factor(J_new, diag), diag, gtest

        def rejected(_):
            return (st["phi"], st["r"], st["J"], st["cs"], st["svd"], st["diag"],
                    jnp.asarray(False))  # fmt: skip

        phi, r, J, cs, svd, diag, gtest = jax.lax.cond(accept, accepted, rejected, None)
        converged = jnp.where(
            first, gtest, jnp.where(accept, small_step | small_cost | gtest, small_step)
        )
        steps = st["steps"] + jnp.where(first, 0, 1)
        cost = jnp.where(accept, cost_new, st["cost"])
        grow = jnp.where(first, 1.0, st["nu"])
        return dict(
            phi=phi, r=r, J=J, cs=cs, svd=svd, diag=diag, steps=steps, cost=cost,
            lam=jnp.where(accept & ~first,
                          st["lam"] * jnp.maximum(1 / 3, 1 - (2 * rho - 1) ** 3),
                          st["lam"] * grow),
            nu=jnp.where(accept, 2.0, 2.0 * st["nu"]), first=jnp.asarray(False),
            done=converged | (steps >= max_steps) | ~jnp.isfinite(cost),
            ok=converged & jnp.isfinite(cost),
        )  # fmt: skip

    st = jax.lax.while_loop(lambda st: ~st["done"], body, state)
    flat = jnp.zeros_like(flat0).at[nl_idx].set(st["phi"])
    for idx, c in zip(lin_idx, st["cs"], strict=True):
        flat = flat.at[idx].set(c)
    return flat, st["ok"], st["steps"]
