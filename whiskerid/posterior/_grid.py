"""Free decays on near-uniform timestamps evaluated on a grid: ``t_n = T_j + τ_k + δ_n``, so
``e^{λ t_n}`` is two short tables of complex exponentials times a Taylor polynomial in the
small jitter ``δ_n`` (degree chosen at set-up), equal to the direct columns to rounding."""

import functools
import math

import jax.numpy as jnp
import numpy as np

from ..fit import conversion_average, decay_rates, sincos

# direct columns' own rounding, from the argument ω t, is ~|ω t| · 1e-16, larger).
_TAYLOR_TOL = 1e-15
_TAYLOR_MAX_DEGREE = 16
# The degree is chosen for this multiple of the Laplace centre's |λ| max|δ|, so walkers may
# wander that far before a batch falls back to the direct columns.
_TAYLOR_MARGIN = 1.5


@functools.cache
def _taylor_radius(degree: int) -> float:
    """Largest ``r`` with ``|e^x − Σ_{k≤p} x^k/k!| ≤ tol · |e^x|`` for all ``|x| ≤ r``.

    Bound: the tail is at most ``r^{p+1}/(p+1)! · 1/(1 − r/(p+2))`` and ``|e^x| ≥ e^{−r}``.
    """

    def bound(r):
        tail = r ** (degree + 1) / math.factorial(degree + 1) / (1 - r / (degree + 2))
        return tail * math.exp(r)

    lo, hi = 0.0, 1.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if bound(mid) <= _TAYLOR_TOL else (lo, mid)
    return lo


def _taylor_degree(r: float) -> int | None:
    """Smallest degree whose :func:`_taylor_radius` covers ``r`` (None: none up to the cap)."""
    for p in range(1, _TAYLOR_MAX_DEGREE + 1):
        if _taylor_radius(p) >= r:
            return p
    return None


def _decay_grid(t: np.ndarray, y: np.ndarray) -> dict:
    """Near-uniform timestamps as a padded ``J × K`` grid plus small offsets (NumPy, once).

    ``t_n = T_j + τ_k + δ_n`` for ``n = jK + k``, with ``τ_k = kΔ`` (``Δ`` the
    least-squares step) and ``T_j`` centring row ``j``'s offsets ``δ``. ``K`` is a multiple
    of 8 near ``√N`` (whole SIMD vectors in the inner loop, few table entries); the padding
    after the last sample has ``δ = 0``, ``mask = 0`` and ``y = drift = 0``. Also, for
    :func:`_rec_loglik`, an orthonormal basis ``q`` of the offset and drift columns,
    ``qᵀy`` and ``log det FᵀF`` of those two columns ``F``: data, so computed here.
    """
    n = t.size
    k_len = 8 * max(1, round(math.sqrt(n) / 8))
    j_len = -(-n // k_len)
    idx = np.arange(n, dtype=float)
    step = float(np.polyfit(idx, t, 1)[0]) if n > 1 else 1.0
    tau = step * np.arange(k_len)
    n_idx = np.arange(n)
    # Each row's start centres its own offsets: a clock that drifts (jitter accumulating
    # over the recording) leaves only the drift within a row.
    rows = np.full(j_len * k_len, np.nan)
    rows[:n] = t - tau[n_idx % k_len]
    rows = rows.reshape(j_len, k_len)
    T = 0.5 * (np.nanmin(rows, axis=1) + np.nanmax(rows, axis=1))

    def padded(x):
        out = np.zeros(j_len * k_len)
        out[:n] = x
        return out.reshape(j_len, k_len)

    delta = (t - T[n_idx // k_len]) - tau[n_idx % k_len]
    span = max(t[-1] - t[0], 1e-12)
    drift = (t - 0.5 * (t[0] + t[-1])) / span
    # Orthonormal basis of the offset and drift columns, for the marginal likelihood.
    q, r = np.linalg.qr(np.stack([np.ones(n), drift], axis=1))
    return {
        "x": np.concatenate([T, tau]),
        "delta": padded(delta),
        "mask": padded(np.ones(n)),
        "drift": padded(drift),
        "y": padded(y),
        "dmax": float(np.max(np.abs(delta))),
        "q": np.stack([padded(q[:, 0]), padded(q[:, 1])]),
        "qty": q.T @ y,
        "logdet_f": 2 * float(np.sum(np.log(np.abs(np.diag(r))))),
    }


def _decay_tables(rec, w, grid, weight=None):
    """The short tables of :func:`_grid_columns`: real and imaginary parts ``(modes, J + K)``
    of ``e^{λ T_j}`` times the ADC average's constant factor (see :func:`_columns`) and
    ``weight`` (complex per mode, or None), then ``e^{λ τ_k}`` (one array each, so XLA
    computes them in few loops); then ``Re λ`` and ``Im λ`` per mode."""
    sigma, lam_im = decay_rates(w.omega_rad_s, w.zeta)
    lam_re = -sigma
    x = grid["x"]
    e = jnp.exp(lam_re[:, None] * x)
    s, c = sincos(lam_im[:, None] * x)
    t_re, t_im = e * c, e * s
    f_re, f_im = jnp.ones_like(lam_re), jnp.zeros_like(lam_re)
    if rec.avg_offsets is not None:
        f_re, f_im = conversion_average(sigma, lam_im, rec.avg_offsets)
    if weight is not None:
        f_re, f_im = f_re * weight[0] - f_im * weight[1], f_re * weight[1] + f_im * weight[0]
    # The factor multiplies the T part only (the first J entries).
    first = jnp.arange(x.shape[0]) < grid["delta"].shape[0]
    f_re = jnp.where(first, f_re[:, None], 1.0)
    f_im = jnp.where(first, f_im[:, None], 0.0)
    return (t_re * f_re - t_im * f_im, t_re * f_im + t_im * f_re, lam_re, lam_im)


def _grid_columns(tables, grid, degrees, summed=False):
    """The columns of :func:`_columns` for a free decay on a :func:`_decay_grid`, ``(J, K)``.

    Each pair of free-decay columns is ``Re`` and ``Im`` of ``E_n = e^{λ t_n}``,
    ``λ = −ζω + iω_d``, which factors as ``e^{λ T_j} · e^{λ τ_k} · e^{λ δ_n}``: two short
    tables (:func:`_decay_tables`, ``J + K`` complex exponentials per mode instead of
    ``N``) and, for ``|λ| max|δ|`` within :func:`_taylor_radius` of ``degrees`` (the
    caller's check; ``|λ| = ω``), a Taylor polynomial in the real ``δ_n`` with the complex
    coefficients ``λ^k/k!``. Per sample that is a few dozen multiply-adds that XLA
    vectorises instead of an ``exp`` and a ``sincos``. The tables must come in as computed
    values (an operand of a ``lax.cond`` branch, as in :func:`_batch_fn`): traced in the
    same computation, XLA fuses their ``exp`` and ``sincos`` into the per-sample loop
    (elementwise producers are duplicated into their consumers), undoing the saving.
    Padding gives exact zeros (``δ = 0`` and the constant term is the mask).

    With ``summed=True`` the free-decay columns come as one, ``Σ_i Re(W_i E_i)`` with the
    tables' weights ``W_i = c_cos,i − i c_sin,i``, i.e. their linear combination with the
    sampled coefficients, in fewer operations per sample.
    """
    delta, mask = grid["delta"], grid["mask"]
    j_len = delta.shape[0]
    tab_re, tab_im, lam_re, lam_im = tables
    cos_cols, sin_cols, total = [], [], 0.0
    for i, degree in enumerate(degrees):
        # Coefficients λ^k/k! (scalars), then Horner in δ for the real and imaginary parts.
        coef = [(1.0, 0.0)]
        for k in range(1, degree + 1):
            cr, ci = coef[-1]
            coef.append(
                ((cr * lam_re[i] - ci * lam_im[i]) / k, (cr * lam_im[i] + ci * lam_re[i]) / k)
            )
        p_re, p_im = coef[-1]
        for cr, ci in reversed(coef[1:-1]):
            p_re, p_im = cr + delta * p_re, ci + delta * p_im
        p_re, p_im = mask + delta * p_re, delta * p_im
        a_re, a_im = tab_re[i, :j_len, None], tab_im[i, :j_len, None]
        b_re, b_im = tab_re[i, j_len:], tab_im[i, j_len:]
        x_re = a_re * b_re - a_im * b_im
        x_im = a_re * b_im + a_im * b_re
        if summed:
            total = total + (x_re * p_re - x_im * p_im)
        else:
            cos_cols.append(x_re * p_re - x_im * p_im)
            sin_cols.append(x_re * p_im + x_im * p_re)
    if summed:
        return [mask, grid["drift"], total]
    return [mask, grid["drift"], *cos_cols, *sin_cols]
