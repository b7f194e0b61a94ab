"""A small Levenberg–Marquardt least-squares solver in NumPy, for a handful of parameters.

The release finder (module ``_release``) fits one or two damped sinusoids by variable
projection: two or four nonlinear parameters (frequencies and decay rates), each residual a
small linear least-squares solve. ``scipy.optimize.least_squares(method="lm")`` (MINPACK's
``lmdif``) did that, but importing ``scipy.optimize`` takes longer than a warm calibration's
whole fit. This is the same method, with MINPACK's choices where they matter for the answer:

* the Jacobian by forward differences, step ``√ε·|x_j|`` (``√ε`` at zero);
* Marquardt's scaling: the diagonal ``D`` holds the largest column norms of the Jacobian met
  so far, and a step solves ``min ‖r + Jδ‖² + λ‖Dδ‖²`` (as the least-squares problem
  ``[J; √λ D] δ ≈ [−r; 0]``, never through ``JᵀJ``, whose condition is the square);
* ``λ`` adapted by the ratio ``ρ`` of the actual to the predicted reduction of ``‖r‖²``
  (Nielsen's rule: ``λ·max(1/3, 1 − (2ρ − 1)³)`` after a good step, doubling factors after a
  bad one);
* MINPACK's tests, with SciPy's default tolerances 1e-8: the relative reduction of
  ``‖r‖²``, actual and predicted, below ``ftol``; the scaled step below ``xtol`` times the
  scaled parameters; the largest cosine between ``r`` and a column of ``J`` below ``gtol``;
  or ``max_nfev`` evaluations (Jacobian columns included) spent.

Two solvers that stop within 1e-8 of the same minimum give the same decays: the release
finder compares misfits with a few residual scales, far coarser than that.
"""

from collections.abc import Callable

import numpy as np

_EPS = np.finfo(float).eps
FTOL = XTOL = GTOL = 1e-8


def lm_least_squares(fun: Callable[[np.ndarray], np.ndarray], x0, *, max_nfev: int):
    """Minimise ``‖fun(x)‖²`` from ``x0`` (see the module docstring).

    Args:
        fun: Residuals, a vector, of the parameters ``x``.
        x0: Start parameters.
        max_nfev: Most evaluations of ``fun`` (the Jacobian's included).

    Returns:
        ``(x, r)``: the parameters found and their residuals.
    """
    x = np.array(x0, dtype=float)
    r = np.asarray(fun(x), dtype=float)
    nfev = 1
    cost = float(r @ r)
    diag = np.zeros(x.size)
    lam, nu = None, 2.0
    while nfev + x.size <= max_nfev and cost > 0.0:
        jac = _jacobian(fun, x, r)
        nfev += x.size
        norms = np.linalg.norm(jac, axis=0)
        diag = np.maximum(diag, np.where(norms > 0, norms, 1.0))
        if _gradient_cosine(jac, r, norms) <= GTOL:
            break
        if lam is None:  # a small fraction of the largest curvature
            lam = 1e-3 * float(np.max(norms / diag) ** 2)
        while nfev < max_nfev:
            step = _step(jac, r, diag, lam)
            x_new = x + step
            r_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            cost_new = float(r_new @ r_new) if np.all(np.isfinite(r_new)) else np.inf
            predicted = cost - float(np.sum((r + jac @ step) ** 2))
            actual = cost - cost_new
            rho = actual / predicted if predicted > 0 else -1.0
            small_step = np.linalg.norm(diag * step) <= XTOL * np.linalg.norm(diag * x)
            if rho > 0:  # accepted
                x, r = x_new, r_new
                small_cost = actual <= FTOL * cost and predicted <= FTOL * cost and rho <= 2
                cost = cost_new
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if small_step or small_cost:
                    return x, r
                break
            lam *= nu
            nu *= 2.0
            if small_step:  # no step the model trusts changes anything
                return x, r
        else:
            break
    return x, r


def _jacobian(fun, x, r):
    """Forward differences, MINPACK's step ``√ε·|x_j|`` (``√ε`` where ``x_j = 0``)."""
    jac = np.empty((r.size, x.size))
    for j in range(x.size):
        h = np.sqrt(_EPS) * (abs(x[j]) if x[j] != 0 else 1.0)
        xh = x.copy()
        xh[j] += h
        h = xh[j] - x[j]  # the step actually taken, after rounding
        jac[:, j] = (np.asarray(fun(xh), dtype=float) - r) / h
    return jac


def _gradient_cosine(jac, r, norms):
    """The largest ``|J_jᵀ r| / (‖J_j‖ ‖r‖)`` (MINPACK's gradient test)."""
    rn = float(np.linalg.norm(r))
    if rn == 0.0:
        return 0.0
    ok = norms > 0
    if not np.any(ok):
        return 0.0
    return float(np.max(np.abs(jac[:, ok].T @ r) / (norms[ok] * rn)))


def _step(jac, r, diag, lam):
    """``δ`` minimising ``‖r + Jδ‖² + λ‖Dδ‖²``."""
    a = np.concatenate([jac, np.sqrt(lam) * np.diag(diag)], axis=0)
    b = np.concatenate([-r, np.zeros(diag.size)])
    step, *_ = np.linalg.lstsq(a, b, rcond=None)
    return step
