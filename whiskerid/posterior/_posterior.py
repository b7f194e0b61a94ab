"""Posteriors of a whisker's ζ, f_1 (κ) and EI or C with emcee (issue 4).

Model. The calibration's residual model (:mod:`whiskerid._calibrate`), jointly over one or
more recordings of one whisker: each recording is ``y = D(θ) c + g(θ) + ε`` in normalised
units (``y`` divided by its standard deviation), with shared nonlinear parameters ``θ``
(``log κ``, ``logit ζ``, a static test's ``log EI`` and offset, a sine's start time) and
per-recording linear coefficients ``c`` (offset, drift, modal amplitudes).

Likelihood. ``gaussian`` (default): ``ε ~ N(0, σ_j²)`` with an unknown σ per recording,
sampled as ``log σ_j``. The linear coefficients are *marginalised analytically*: with a
flat (improper) prior on ``c`` the integral is closed-form (variable projection),
``log L_j = −(n−k) log σ − ½ log|DᵀD| − RSS_min/(2σ²) − (n−k)/2 log 2π``, with ``RSS_min``
the least-squares residual at ``θ`` (normal equations, Jacobi-scaled Cholesky). ``student``: a
Student-t with ``ν`` (default 4) degrees of freedom and scale σ_j for outliers; there is no
closed form, so ``c`` is sampled with the other parameters (``marginalize=False`` does the
same for the Gaussian, e.g. for comparisons with samplers that cannot marginalise).

Priors. From the record's ``[prior]`` table, on physical quantities, with the Jacobian of
the sampled transform added: ``zeta``, ``f1_hz`` or ``kappa``, and ``sigma_rel`` (noise σ
relative to each recording's standard deviation). Distributions: ``uniform`` and
``loguniform`` (``low``, ``high``), ``normal`` (``mu``, ``sigma``), ``lognormal`` (``mu``,
``sigma`` of ``ln x``). Outside a bounded support the log-probability is ``−inf``.
Defaults when absent: ``zeta`` uniform on ``(0, 0.95)`` (the calibration's range),
``f1_hz`` log-uniform over ``[f̂/10, 10 f̂]`` around the calibrated ``f̂``, ``sigma_rel``
log-uniform on ``[1e-6, 10]``. A static test's ``log EI``, its offset and a sine's start
time have flat priors.

Sampler. ``emcee.EnsembleSampler(vectorize=True)`` on a jitted, vmapped log-probability
(free decays on near-uniform timestamps evaluated on a grid: two short tables of complex
exponentials and a Taylor factor for the timing jitter, equal to the direct evaluation to
rounding, which the batch falls back to where that factor would not be exact);
walkers start from the calibration's Laplace approximation (a draw from ``N(θ̂, Σ)``
in the sampled space: additive, so parameters at exactly 0 are no problem); reproducible
by seed (``emcee.State(p0, random_state=...)``); optional HDF5 backend with resume. The
proposal is emcee's differential-evolution move by default (``move="de"``; the stretch
move, emcee's and lmfit's default, on request): on these posteriors its autocorrelation
times are about a third of the stretch move's (:func:`emcee_moves`).

Diagnostics. Integrated autocorrelation time τ per sampled coordinate and per reported
quantity (``quiet=True``), burn-in ``2 max τ``, thinning ``min τ / 2``, effective sample
size ``walkers (steps − burn)/τ``; a run shorter than ``50 max τ`` is reported as
``converged = False`` with the number of steps needed.
"""

import datetime
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from .._choices import LIKELIHOODS, MOVES
from ..fit import (
    ZETA_MAX,
    FitProblem,
    Observation,
    calibrate,
    cho_solve_small,
    cholesky_small,
    conversion_average,
    decay_rates,
    free_decay_columns,
    recording_design,
    reported_names,
    sha256_of,
    to_interval,
)
from ..model._record import WhiskerRecord
from ..model._trig import sincos

#: emcee moves ``run_sampler`` accepts (see :func:`emcee_moves`).
DISTS = ("uniform", "loguniform", "normal", "lognormal")
PRIOR_KEYS = ("zeta", "f1_hz", "kappa", "sigma_rel")
_DIST_ARGS = {
    "uniform": ("low", "high"),
    "loguniform": ("low", "high"),
    "normal": ("mu", "sigma"),
    "lognormal": ("mu", "sigma"),
}


class PosteriorError(ValueError):
    """Input that cannot be sampled (message says what)."""


# --------------------------------------------------------------------------- priors
def parse_prior(table: dict | None) -> dict[str, tuple[str, float, float]]:
    """Check a ``[prior]`` table: name → ``(dist, a, b)``.

    Args:
        table: e.g. ``{"zeta": {"dist": "uniform", "low": 0, "high": 0.5}}``.

    Raises:
        PosteriorError: unknown names or distributions, missing or invalid arguments.
    """
    out = {}
    for key, spec in (table or {}).items():
        if key not in PRIOR_KEYS:
            raise PosteriorError(f"prior: unknown parameter {key!r} (known: {PRIOR_KEYS})")
        if not isinstance(spec, dict) or spec.get("dist") not in DISTS:
            raise PosteriorError(f"prior {key}: give dist = one of {DISTS}")
        dist = spec["dist"]
        names = _DIST_ARGS[dist]
        try:
            a, b = (float(spec[n]) for n in names)
        except (KeyError, TypeError, ValueError):
            raise PosteriorError(f"prior {key}: {dist} needs numbers {names}") from None
        if dist in ("uniform", "loguniform") and not a < b:
            raise PosteriorError(f"prior {key}: need low < high")
        if dist == "loguniform" and not a > 0:
            raise PosteriorError(f"prior {key}: loguniform needs low > 0")
        if dist in ("normal", "lognormal") and not b > 0:
            raise PosteriorError(f"prior {key}: sigma must be > 0")
        out[key] = (dist, a, b)
    if "f1_hz" in out and "kappa" in out:
        raise PosteriorError("prior: give f1_hz or kappa, not both")
    return out


def prior_log_norm(dist: str, a, b):
    """The constant term of :func:`prior_logpdf` (log of the normalisation)."""
    if dist == "uniform":
        return -jnp.log(b - a)
    if dist == "loguniform":
        return -jnp.log(jnp.log(b / a))
    if dist in ("normal", "lognormal"):
        return -jnp.log(b) - 0.5 * math.log(2 * math.pi)
    raise PosteriorError(f"unknown prior {dist!r}")


def prior_logpdf(dist: str, x, a, b, log_norm=None):
    """Log-density of a prior at ``x`` (−inf outside a bounded support).

    ``log_norm``: :func:`prior_log_norm` of ``(dist, a, b)`` if already known (the
    log-probability passes it in with the data: computed from ``a`` and ``b`` on every call
    it took a few small XLA kernels per call).
    """
    if log_norm is None:
        log_norm = prior_log_norm(dist, a, b)
    if dist == "uniform":
        return jnp.where((x >= a) & (x <= b), log_norm, -jnp.inf)
    if dist == "loguniform":
        inside = (x >= a) & (x <= b)
        return jnp.where(inside, -jnp.log(x) + log_norm, -jnp.inf)
    if dist == "normal":
        return -0.5 * ((x - a) / b) ** 2 + log_norm
    if dist == "lognormal":
        lx = jnp.log(jnp.where(x > 0, x, 1.0))
        val = -lx - 0.5 * ((lx - a) / b) ** 2 + log_norm
        return jnp.where(x > 0, val, -jnp.inf)
    raise PosteriorError(f"unknown prior {dist!r}")


def default_prior(f1_hz: float) -> dict[str, tuple[str, float, float]]:
    """Priors used for the names the record's ``[prior]`` does not give."""
    return {
        "zeta": ("uniform", 0.0, ZETA_MAX),
        "f1_hz": ("loguniform", f1_hz / 10, f1_hz * 10),
        "sigma_rel": ("loguniform", 1e-6, 10.0),
    }


# --------------------------------------------------------------------------- model
@dataclass(frozen=True)
class _Model:
    """Static description of the log-probability (hashable: the jit key). The fit problem,
    whose numbers are traced, travels in the arguments (``args["problem"]``)."""

    n_theta: int
    n_rec: int
    likelihood: str
    marginal: bool
    priors: tuple[tuple[str, str], ...]  # (name, dist); numbers travel in args
    # Per recording: the Taylor degree per mode of the gridded free-decay columns
    # (:func:`_grid_columns`), or None where the recording is evaluated directly only.
    grid_degrees: tuple[tuple[int, ...] | None, ...] = ()

    @property
    def ndim(self) -> int:
        return self.n_theta + self.n_rec


def _sampled_params(problem: FitProblem, marginal: bool):
    """The parameter pytree of the sampled space (zeros): the fit's, without the linear
    coefficients ``c`` when they are marginalised."""
    theta = problem.zero_params()
    return _drop_c(theta) if marginal else theta


def _unravel(problem: FitProblem, marginal: bool):
    """Flat sampled vector → parameter pytree (the layout follows from the structure)."""
    return ravel_pytree(_sampled_params(problem, marginal))[1]


def _columns(rec, w, rec_params):
    """The calibration's design of one recording as a list of columns, and its fixed part.

    Equal (to rounding) to :func:`whiskerid.fit.recording_design`'s ``(D, g)``, with ``D``
    split into its columns: the likelihood below then forms ``Dᵀ D``, ``Dᵀ y`` and ``D c``
    from elementwise products and sums, which XLA fuses into a few loops (a batched ``dot``
    over 16 walkers × 500 × 4 and the concatenation cost more than the arithmetic). Free
    decays, the common case, are built here, one mode at a time, with the shared
    :func:`whiskerid.fit.free_decay_columns` and the fast ``sincos``; sines and base motion
    come from :func:`whiskerid.fit.recording_design`.
    """
    if rec.excitation != "decay":
        D, g = recording_design(rec, w, rec_params)
        return [D[:, i] for i in range(D.shape[1])], g
    t = rec.t
    span = jnp.maximum(t[-1] - t[0], 1e-12)
    sigma, wd = decay_rates(w.omega_rad_s, w.zeta)
    cos_cols, sin_cols = [], []
    for i in range(w.n_modes):  # e^{-ζω t} cos(ω_d t) and e^{-ζω t} sin(ω_d t)
        c, s = free_decay_columns(t, sigma[i], wd[i], rec.avg_offsets, sincos=sincos)
        cos_cols.append(c)
        sin_cols.append(s)
    cols = [jnp.ones_like(t), (t - 0.5 * (t[0] + t[-1])) / span, *cos_cols, *sin_cols]
    return cols, jnp.zeros_like(t)


# Gridded free-decay columns. Relative truncation error allowed in the Taylor factor (the
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


@jax.custom_jvp
def _sum_all(arrays):
    """``[jnp.sum(a) for a in arrays]`` as one variadic reduction: XLA then sums them all in
    one loop with one accumulator each, where separate sums were one loop each, bound by
    the latency of their single accumulator (10 sums of 16 × 504 products: 67 µs instead of
    113 µs). JAX cannot differentiate a reduction with a general body, hence the JVP
    below: the tangents are summed with ``jnp.sum``, which JAX can also transpose (reverse
    mode, e.g. NUTS on this log-density)."""
    return jax.lax.reduce(
        tuple(arrays),
        (0.0,) * len(arrays),
        lambda x, y: tuple(a + b for a, b in zip(x, y, strict=True)),
        tuple(range(arrays[0].ndim)),
    )


@_sum_all.defjvp
def _sum_all_jvp(primals, tangents):
    (arrays,), (dots,) = primals, tangents
    return _sum_all(arrays), tuple(jnp.sum(t) for t in dots)


def _rec_loglik(model, rec, rec_params, grid, w, log_sigma, nu, degrees=None, tables=None):
    """One recording's log-likelihood; with ``degrees`` and ``tables`` on its gridded
    columns (exact zeros in the padding, so every sum below is over the recorded samples)."""
    known, logdet = 0, 0.0
    if degrees is not None:
        # Sampled coefficients: the free-decay ones are folded into the tables.
        summed = not model.marginal
        cols = _grid_columns(tables, grid, degrees, summed=summed)
        y = grid["y"]
        c = [rec_params["c"][0], rec_params["c"][1], 1.0] if summed else None
        if model.marginal:
            # The offset and drift columns F replaced by their orthonormal basis q (same
            # span, so the same fit; log|DᵀD| changes by the constant log det FᵀF): their
            # Gram entries and qᵀy are then known, not summed again on every call.
            cols = [grid["q"][0], grid["q"][1], *cols[2:]]
            known, logdet = 2, grid["logdet_f"]
    else:
        cols, g = _columns(rec, w, rec_params)
        y = rec.y - g
        c = None if model.marginal else rec_params["c"]
    n, k = rec.y.shape[0], len(cols)
    sigma = jnp.exp(log_sigma)
    if model.marginal:
        # Normal equations with Jacobi scaling, solved element by element (k is small; see
        # _lsq.cholesky_small); the residual is formed explicitly (no cancellation in
        # yᵀy − bᵀG⁻¹b). The first ``known`` columns are orthonormal.
        pairs = [(i, j) for i in range(known, k) for j in range(i + 1)]
        sums = _sum_all(
            [cols[i] * cols[j] for i, j in pairs] + [cols[i] * y for i in range(known, k)]
        )
        gram = [[float(i == j) for j in range(i + 1)] for i in range(k)]
        for (i, j), v in zip(pairs, sums, strict=False):
            gram[i][j] = v
        s = [1.0 if i < known else jnp.sqrt(gram[i][i]) for i in range(k)]
        L = cholesky_small([[gram[i][j] / (s[i] * s[j]) for j in range(i + 1)] for i in range(k)])
        b = [grid["qty"][i] if i < known else sums[len(pairs) + i - known] / s[i] for i in range(k)]
        coef = cho_solve_small(L, b)
        resid = y - sum(coef[i] / s[i] * cols[i] for i in range(k))
        logdet = logdet + 2 * sum(jnp.log(L[i][i]) + jnp.log(s[i]) for i in range(k))
        return (
            -(n - k) * log_sigma
            - 0.5 * logdet
            - 0.5 * jnp.sum(resid**2) / sigma**2
            - 0.5 * (n - k) * math.log(2 * math.pi)
        )
    z = (sum(c[i] * cols[i] for i in range(k)) - y) / sigma
    if model.likelihood == "gaussian":
        return -n * log_sigma - 0.5 * jnp.sum(z**2) - 0.5 * n * math.log(2 * math.pi)
    const = (
        jax.scipy.special.gammaln((nu + 1) / 2)
        - jax.scipy.special.gammaln(nu / 2)
        - 0.5 * jnp.log(nu * jnp.pi)
    )
    return n * (const - log_sigma) - 0.5 * (nu + 1) * jnp.sum(jnp.log1p(z**2 / nu))


def _log_prior(model, theta, w, log_sigma, args):
    lp = 0.0
    for name, dist in model.priors:
        a, b, norm = args["prior"][name][0], args["prior"][name][1], args["prior"][name][2]
        if name == "zeta":
            u = jnp.atleast_1d(theta["zeta_u"])
            z = to_interval(u, 0.0, ZETA_MAX)
            # dζ/du = ζ (ζmax − ζ)/ζmax
            jac = jnp.log(z) + jnp.log(ZETA_MAX - z) - math.log(ZETA_MAX)
            lp = lp + jnp.sum(prior_logpdf(dist, z, a, b, norm) + jac)
        elif name == "f1_hz":  # f_1 ∝ √κ: d f_1 / d log κ = f_1 / 2
            f1 = w.omega_rad_s[0] / (2 * jnp.pi)
            lp = lp + prior_logpdf(dist, f1, a, b, norm) + jnp.log(f1 / 2)
        elif name == "kappa":
            kappa = jnp.exp(theta["log_kappa"])
            lp = lp + prior_logpdf(dist, kappa, a, b, norm) + theta["log_kappa"]
        elif name == "sigma_rel":
            s = jnp.exp(log_sigma)
            lp = lp + jnp.sum(prior_logpdf(dist, s, a, b, norm) + log_sigma)
    return lp


def log_prob_one(model: _Model, z, args, tables=None):
    """Log-posterior (up to a constant) at one point ``z`` of the sampled space.

    ``tables``: from :func:`_grid_tables` at ``z``, where it says the gridded free-decay
    columns are exact; those recordings are then evaluated on their grids.
    """
    problem = args["problem"]
    theta = _unravel(problem, model.marginal)(z[: model.n_theta])
    log_sigma = z[model.n_theta :]
    w = problem.whisker(theta)
    lp = _log_prior(model, theta, w, log_sigma, args)
    degrees = model.grid_degrees if tables is not None else (None,) * model.n_rec
    tables = tables if tables is not None else (None,) * model.n_rec
    recs = theta.get("recs") or [{}] * model.n_rec
    for j, (rec, rp, grid) in enumerate(zip(problem.recordings, recs, args["grids"], strict=True)):
        lp = lp + _rec_loglik(
            model, rec, rp, grid, w, log_sigma[j], args["nu"], degrees[j], tables[j]
        )
    if problem.static_test is not None:
        lp = lp - 0.5 * jnp.sum(problem.static_residuals(theta) ** 2)
    return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)


_COMPILED: dict = {}

# XLA's CPU backend hands reductions to YNNPACK fusions by default; for these small
# reductions (16 walkers × a few hundred samples) that costs more than the arithmetic: the
# log-probability of a 500-sample decay took 150 µs per half-ensemble with them and 100 µs
# without (same values). Set per compiled function, so nothing else in the process changes.
_CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}
_cpu_options_ok: list = []


def _compiler_options() -> dict | None:
    """:data:`_CPU_OPTIONS` on the CPU if this XLA knows them (probed once), else None."""
    if jax.default_backend() != "cpu":
        return None
    if not _cpu_options_ok:
        try:
            jax.jit(lambda x: x + 1.0, compiler_options=_CPU_OPTIONS).lower(1.0).compile()
            _cpu_options_ok.append(True)
        except Exception:  # an XLA without the option: its defaults are fine
            _cpu_options_ok.append(False)
    return _CPU_OPTIONS if _cpu_options_ok[0] else None


def _grid_tables(model, z, args):
    """Per recording, :func:`_decay_tables` at ``z`` (None where not gridded), and whether
    the gridded columns are exact there: ``ω_i max|δ|`` within each mode's Taylor radius
    (False for a non-finite ``ω``)."""
    problem = args["problem"]
    theta = _unravel(problem, model.marginal)(z[: model.n_theta])
    w = problem.whisker(theta)
    omega = w.omega_rad_s
    tables, ok = [], jnp.array(True)
    recs = zip(problem.recordings, args["grids"], model.grid_degrees, strict=True)
    for j, (rec, grid, degrees) in enumerate(recs):
        if degrees is None:
            tables.append(None)
            continue
        weight = None
        if not model.marginal:  # W_i = c_cos,i − i c_sin,i (see _grid_columns)
            m = len(degrees)
            c = theta["recs"][j]["c"]
            weight = (c[2 : 2 + m], -c[2 + m : 2 + 2 * m])
        tables.append(_decay_tables(rec, w, grid, weight))
        radius = jnp.asarray([_taylor_radius(p) for p in degrees])
        ok = ok & jnp.all(omega * grid["dmax"] <= radius)
    return tables, ok


def _pack(args) -> tuple[Any, jax.Array]:
    """``args`` as one float64 vector and its layout (hashable: tree structure, shapes and
    dtypes). Each argument leaf costs about 0.5 µs of dispatch per call (15 leaves: 7 µs of
    a 16-walker call that now takes 70 µs in all); slicing them out again is free."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    leaves = [np.asarray(x) for x in leaves]
    layout = (treedef, tuple((x.shape, x.dtype.str) for x in leaves))
    flat = np.concatenate([x.astype(float).ravel() for x in leaves] or [np.zeros(0)])
    return layout, jnp.asarray(flat)


def _unpack(layout, flat):
    treedef, specs = layout
    leaves, start = [], 0
    for shape, dtype in specs:
        size = math.prod(shape)
        leaves.append(flat[start : start + size].reshape(shape).astype(dtype))
        start += size
    return jax.tree_util.tree_unflatten(treedef, leaves)


def _batch_fn(model, layout):
    """Jitted, vmapped log-probability ``(z, packed args) → (walkers,)``; one compiled
    function per model and argument layout (:func:`_pack`), reused across problems of the
    same structure (plain ``jax.jit`` on one packed vector: cheaper dispatch than
    ``eqx.filter_jit`` or a pytree of arguments on every emcee step).

    With gridded recordings the whole batch takes the gridded path when every walker
    passes :func:`_grid_tables`' check, else the direct one (a ``lax.cond`` outside the
    ``vmap``: under it both branches would run; the cond also keeps the tables computed
    once, see :func:`_grid_columns`).
    """
    fn = _COMPILED.get((model, layout))
    if fn is None:
        # The arguments are unpacked where they are used: as operands of the cond, their
        # slices would be copied into buffers of their own first.
        def direct(zz, f, *_):
            a = _unpack(layout, f)
            return jax.vmap(lambda v: log_prob_one(model, v, a))(zz)

        def gridded(zz, f, tables):
            a = _unpack(layout, f)
            return jax.vmap(lambda v, tb: log_prob_one(model, v, a, tb))(zz, tables)

        def call(zz, f):
            if all(deg is None for deg in model.grid_degrees):
                return direct(zz, f)
            a = _unpack(layout, f)
            tables, ok = jax.vmap(lambda v: _grid_tables(model, v, a))(zz)
            return jax.lax.cond(jnp.all(ok), gridded, direct, zz, f, tables)

        fn = jax.jit(call, compiler_options=_compiler_options())
        if len(_COMPILED) > 64:
            _COMPILED.clear()
        _COMPILED[model, layout] = fn
    return fn


# --------------------------------------------------------------------------- setup
@dataclass
class Problem:
    """A posterior problem, ready to sample (from :func:`setup_posterior`).

    Attributes:
        model: Static model description.
        args: Data and prior numbers (arrays).
        z0: Laplace centre in the sampled space.
        cov: Laplace covariance in the sampled space.
        names: Names of the sampled coordinates.
        priors: The priors used, name → ``(dist, a, b)``, and whether each was a default.
        observations: The recordings.
        record: The whisker's record.
        pin: What fixes EI or C (as in the calibration).
        y_std: Each recording's standard deviation (σ in observed units = σ_rel · y_std).
    """

    model: _Model
    args: dict
    z0: np.ndarray
    cov: np.ndarray
    names: list[str]
    priors: dict[str, dict]
    observations: list[Observation]
    record: WhiskerRecord
    pin: str
    y_std: list[float]
    nu: float = 4.0
    # (args, compiled function, packed args) of the last call: looked up and packed once,
    # not on every emcee step (hashing the model alone costs a microsecond or two).
    _compiled: Any = field(default=None, init=False, repr=False, compare=False)

    def log_prob(self, z) -> np.ndarray:
        """Log-posterior at points ``z`` of shape ``(ndim,)`` or ``(walkers, ndim)``."""
        fn, flat = self._batch()
        return np.asarray(fn(np.atleast_2d(np.asarray(z, dtype=float)), flat))

    def _batch(self):
        """The compiled batch log-probability and the packed arguments (looked up and packed
        on the first call and again only when ``args`` is replaced)."""
        if self._compiled is None or self._compiled[0] is not self.args:
            layout, flat = _pack(self.args)
            self._compiled = (self.args, _batch_fn(self.model, layout), flat)
        return self._compiled[1], self._compiled[2]

    def _emcee_log_prob(self):
        """:meth:`log_prob` for emcee's vectorised calls, ``(walkers, ndim)`` in, a list of
        floats out: emcee converts the values one by one, and Python floats convert faster
        than NumPy scalars (a few µs of the step)."""
        fn, flat = self._batch()
        return lambda z: np.asarray(fn(z, flat)).tolist()


def _drop_c(tree):
    return {**tree, "recs": [{k: v for k, v in r.items() if k != "c"} for r in tree["recs"]]}


def setup_posterior(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    static=None,
    n_modes: int | None = None,
    zeta_per_mode: bool = False,
    pin: str = "auto",
    likelihood: str = "gaussian",
    nu: float = 4.0,
    marginalize: bool | None = None,
    prior: dict | None = None,
    f1_start_hz: float | None = None,
) -> Problem:
    """Fit the calibration model (its Laplace approximation) and build the log-posterior.

    Args:
        record: The whisker's record (a calibrated one from ``whiskerid calibrate`` is a
            good start); its ``[prior]`` table is used unless ``prior`` is given.
        observations: Recordings of this whisker, sampled jointly.
        static: Optional static test (as in :func:`whiskerid.calibrate`).
        n_modes: Modes in the model; the record's ``[fit] n_modes`` (else 1) by default.
        zeta_per_mode: One ζ per mode.
        pin: What fixes EI or C (``auto``/``geometry``/``material``).
        likelihood: ``gaussian`` or ``student``.
        nu: Student-t degrees of freedom.
        marginalize: Marginalise the linear coefficients analytically (Gaussian only; the
            default there); ``False`` samples them.
        prior: A ``[prior]`` table overriding the record's.
        f1_start_hz: Centre of the calibration's start search (the record's f_1 otherwise).

    Returns:
        A :class:`Problem`.
    """
    obs = [observations] if isinstance(observations, Observation) else list(observations)
    if not obs:
        raise PosteriorError("no recordings")
    if likelihood not in LIKELIHOODS:
        raise PosteriorError(f"likelihood must be one of {LIKELIHOODS}, not {likelihood!r}")
    if marginalize is None:
        marginalize = likelihood == "gaussian"
    if marginalize and likelihood != "gaussian":
        raise PosteriorError("only the Gaussian likelihood can marginalise the linear nuisances")
    if not nu > 0:
        raise PosteriorError("nu must be > 0")
    fit = record.extra.get("fit", {})
    n_modes = int(n_modes or fit.get("n_modes", 1))
    if pin == "auto" and fit.get("pin") in ("geometry", "material"):
        pin = fit["pin"]
    pin = "geometry" if pin == "auto" else pin
    table = prior if prior is not None else record.extra.get("prior")
    user = parse_prior(table)

    problem, theta_hat, cov_full, sig = _laplace(
        record, obs, static, n_modes, zeta_per_mode, pin, f1_start_hz
    )
    # Sampled space: the calibration's flat vector (without c when marginalised) + log σ_j.
    idx_tree = problem.unflatten(jnp.arange(cov_full.shape[0], dtype=float))
    if marginalize:
        theta_s, idx_tree = _drop_c(theta_hat), _drop_c(idx_tree)
    else:
        theta_s = theta_hat
    flat_s = ravel_pytree(theta_s)[0]
    idx = np.asarray(ravel_pytree(idx_tree)[0]).astype(int)
    n_theta = int(flat_s.size)
    n_rec = len(obs)
    n_samples = np.array([o.t.size for o in obs], float)
    z0 = np.concatenate([np.asarray(flat_s), np.log(sig)])
    cov = np.zeros((n_theta + n_rec,) * 2)
    cov[:n_theta, :n_theta] = cov_full[np.ix_(idx, idx)]
    cov[n_theta:, n_theta:] = np.diag(1.0 / (2 * n_samples))
    names = _names(theta_s, n_rec)

    w_hat = problem.whisker(theta_s)
    f1_hat = float(w_hat.natural_frequencies_hz[0])
    priors = {
        k: {"dist": v[0], "a": v[1], "b": v[2], "default": True}
        for k, v in default_prior(f1_hat).items()
    }
    if "kappa" in user:
        priors.pop("f1_hz")
    for k, v in user.items():
        priors[k] = {"dist": v[0], "a": v[1], "b": v[2], "default": False}
    # Free decays on near-uniform timestamps get the gridded columns, with Taylor degrees
    # for the Laplace centre's frequencies (times a margin).
    omega_hat = np.asarray(w_hat.omega_rad_s)
    grids, grid_degrees = [], []
    for rec in problem.recordings:
        degrees, grid_arrays = None, None
        if rec.excitation == "decay" and np.size(rec.t) >= 16:
            grid = _decay_grid(np.asarray(rec.t), np.asarray(rec.y))
            deg = [_taylor_degree(_TAYLOR_MARGIN * om * grid["dmax"]) for om in omega_hat]
            if None not in deg:
                degrees = tuple(deg)
                grid_arrays = {k: jnp.asarray(v) for k, v in grid.items()}
        grids.append(grid_arrays)
        grid_degrees.append(degrees)
    args = {
        "problem": problem,
        "grids": grids,
        "prior": {
            k: jnp.asarray([p["a"], p["b"], float(prior_log_norm(p["dist"], p["a"], p["b"]))])
            for k, p in priors.items()
        },
        "nu": jnp.asarray(float(nu)),
    }
    model = _Model(
        n_theta=n_theta,
        n_rec=n_rec,
        likelihood=likelihood,
        marginal=bool(marginalize),
        priors=tuple((k, p["dist"]) for k, p in priors.items()),
        grid_degrees=tuple(grid_degrees),
    )
    return Problem(
        model=model,
        args=args,
        z0=z0,
        cov=cov,
        names=names,
        priors=priors,
        observations=obs,
        record=record,
        pin=pin,
        y_std=[float(np.std(o.y)) for o in obs],
        nu=float(nu),
    )


def _names(theta, n_rec):
    names = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(theta)[0]:
        key = jax.tree_util.keystr(path).replace("['", ".").replace("']", "").lstrip(".")
        key = key.replace("zeta_u", "logit_zeta")
        n = int(np.size(leaf))
        names += [key] if n == 1 else [f"{key}[{i}]" for i in range(n)]
    return names + [f"log_sigma[{j}]" for j in range(n_rec)]


def _laplace(record, obs, static, n_modes, zeta_per_mode, pin, f1_start_hz):
    """The calibration fit: its problem (recordings weighted by their residual scale), the
    optimum, its covariance (a small diagonal one where that is not finite) and each
    recording's residual scale σ_j in normalised units."""
    cal = calibrate(
        record,
        obs,
        static=static,
        n_modes=n_modes,
        zeta_per_mode=zeta_per_mode,
        pin=pin,
        f1_start_hz=f1_start_hz,
    )
    problem, cov = cal.problem, np.asarray(cal.covariance)
    if not np.all(np.isfinite(cov)):
        flat = np.asarray(problem.flatten(cal.optimum))
        scale = 1e-4 * np.maximum(np.abs(flat), 1e-2)
        cov = np.diag(scale**2)
    sig = np.array([1.0 / float(r.weight) for r in problem.recordings])
    return problem, cal.optimum, cov, sig


# --------------------------------------------------------------------------- sampling
def initial_walkers(prob: Problem, n_walkers: int, rng: np.random.Generator) -> np.ndarray:
    """Walkers drawn from the Laplace approximation, all with a finite log-probability.

    Draws ``z0 + L ε`` (``L Lᵀ = Σ``); walkers outside the support are drawn again, with
    the spread halved each round; the centre itself is moved inside a bounded prior.
    """
    ndim = prob.z0.size
    cov = 0.5 * (prob.cov + prob.cov.T)
    jitter = 1e-12 * max(float(np.max(np.abs(np.diag(cov)))), 1e-12)
    try:
        chol = np.linalg.cholesky(cov + jitter * np.eye(ndim))
    except np.linalg.LinAlgError:
        chol = np.diag(np.sqrt(np.maximum(np.abs(np.diag(cov)), 1e-12)))
    p = prob.z0 + rng.standard_normal((n_walkers, ndim)) @ chol.T
    scale = 1.0
    for _ in range(60):
        bad = ~np.isfinite(prob.log_prob(p))
        if not bad.any():
            return p
        scale *= 0.5
        p[bad] = prob.z0 + scale * rng.standard_normal((int(bad.sum()), ndim)) @ chol.T
    raise PosteriorError(
        "could not start the walkers with a finite log-probability: is the calibrated value "
        "inside the prior's support?"
    )


def emcee_moves(move: str):
    """The emcee moves for a name in :data:`MOVES`.

    ``de``: differential evolution (ter Braak 2006; emcee's ``DEMove``, after Nelson et al.
    2014): a walker steps by ``γ (x_j − x_k)`` for two walkers ``j ≠ k`` of the other half,
    ``γ ~ N(γ₀, (10⁻⁵ γ₀)²)``, ``γ₀ = 2.38/√(2 ndim)``. The differences carry the ensemble's
    spread and correlations, as the stretch move's lines do, and ``γ₀`` is the optimal
    random-walk scale for a Gaussian target in ``ndim`` dimensions, where the stretch move's
    scale (``a = 2``) is the same in any dimension; on these nearly Gaussian posteriors the
    autocorrelation times come out about three times shorter. ``stretch``: emcee's default
    (Goodman & Weare 2010), as in lmfit's ``Minimizer.emcee``. ``de-snooker``: DE 80 %,
    DE-snooker 20 % (ter Braak & Vrugt 2008; for posteriors with several modes).
    """
    import emcee

    if move == "de":
        return emcee.moves.DEMove()
    if move == "stretch":
        return emcee.moves.StretchMove()
    if move == "de-snooker":
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    raise PosteriorError(f"move must be one of {', '.join(MOVES)}; got {move!r}")


def run_sampler(
    prob: Problem,
    *,
    walkers: int = 32,
    steps: int = 2000,
    seed: int = 0,
    backend: str | Path | None = None,
    resume: bool = False,
    progress: bool = False,
    move: str = "de",
):
    """Run emcee (vectorised) and return the sampler.

    Args:
        prob: From :func:`setup_posterior`.
        walkers: Number of walkers (at least twice the dimension).
        steps: Steps to run (added to the backend's when resuming).
        seed: Seeds the start and emcee's own random state.
        backend: HDF5 file for the chain (needs ``h5py``).
        resume: Continue the chain in ``backend`` instead of starting afresh.
        progress: emcee's progress bar (tqdm).
        move: emcee's proposal, one of :data:`MOVES` (:func:`emcee_moves`).
    """
    import emcee

    ndim = prob.z0.size
    if walkers < 2 * ndim:
        raise PosteriorError(f"need at least {2 * ndim} walkers for {ndim} parameters")
    if steps < 1:
        raise PosteriorError("steps must be >= 1")
    moves = emcee_moves(move)  # refused before a backend file is touched
    be = None
    if backend is not None:
        try:
            import h5py  # noqa: F401
        except ImportError:
            raise PosteriorError("the HDF5 backend needs h5py (pip install h5py)") from None
        be = emcee.backends.HDFBackend(str(backend), name="whiskerid")
        if resume:
            if not Path(backend).exists() or be.iteration == 0:
                raise PosteriorError(f"{backend}: nothing to resume")
            if be.shape != (walkers, ndim):
                raise PosteriorError(
                    f"{backend}: holds {be.shape[0]} walkers × {be.shape[1]} parameters, "
                    f"not {walkers} × {ndim}"
                )
        else:
            be.reset(walkers, ndim)
    sampler = emcee.EnsembleSampler(
        walkers, ndim, prob._emcee_log_prob(), vectorize=True, backend=be, moves=moves
    )
    if resume:
        state = be.get_last_sample()
        if state.random_state is None:
            state.random_state = np.random.RandomState(seed).get_state()
    else:
        p0 = initial_walkers(prob, walkers, np.random.default_rng(seed))
        state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    sampler.whiskerid_move = move  # for the provenance (summarize)
    sampler.run_mcmc(state, steps, progress=progress)
    return sampler


# --------------------------------------------------------------------------- results
@dataclass
class Posterior:
    """Outcome of :func:`sample_posterior`.

    Attributes:
        params: Reported quantity → ``median, q16, q84, q2.5, q97.5, mean, std, tau, ess``.
        diagnostics: ``converged``, ``steps``, ``steps_needed``, ``walkers``, ``burn``,
            ``thin``, ``acceptance`` (mean), ``acceptance_min``, ``tau`` per sampled
            coordinate, ``max_tau``, ``log_prob_evals``, ``message``.
        correlations: ``{"names", "matrix"}`` of the reported quantities.
        samples: Burnt-in, thinned samples of the reported quantities ``(n, p)``.
        names: Their names.
        chain: The full chain in the sampled space ``(steps, walkers, ndim)``.
        chain_names: Names of the sampled coordinates.
        record: The record with a ``[posterior]`` table.
        provenance: Seed, sampler, likelihood, priors, data files with SHA-256, version.
    """

    params: dict[str, dict]
    diagnostics: dict[str, Any]
    correlations: dict[str, Any]
    samples: np.ndarray
    names: list[str]
    chain: np.ndarray = field(repr=False)
    chain_names: list[str] = field(default_factory=list)
    record: WhiskerRecord | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    derived_chain: np.ndarray | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        """The JSON summary (``whiskerid posterior --json``)."""
        return {
            "converged": self.diagnostics["converged"],
            "params": self.params,
            "tau": self.diagnostics["tau"],
            "acceptance": self.diagnostics["acceptance"],
            "ess": {k: v["ess"] for k, v in self.params.items()},
            "diagnostics": self.diagnostics,
            "correlations": self.correlations,
            "provenance": self.provenance,
        }


def derived_quantities(prob: Problem, z: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Reported quantities (f_1, ζ, κ, EI or C …, σ per recording) at points ``z``."""
    m = prob.model
    problem = prob.args["problem"]
    names = reported_names(problem)
    vals = np.asarray(
        _derived_batch(problem, m.marginal, jnp.asarray(np.asarray(z)[:, : m.n_theta]))
    )
    sig = np.exp(np.asarray(z)[:, m.n_theta :]) * np.asarray(prob.y_std)
    names += [f"sigma_{j + 1}" for j in range(m.n_rec)]
    return np.concatenate([vals, sig], axis=1), names


@eqx.filter_jit
def _derived_batch(problem, marginal, z):
    unravel = _unravel(problem, marginal)
    return jax.vmap(lambda v: jnp.stack(list(problem.reported(unravel(v)).values())))(z)


def _tau(x: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time of a chain ``(steps, walkers, ndim)`` (quiet)."""
    import logging

    import emcee

    log = logging.getLogger("emcee.autocorr")
    level = log.level
    log.setLevel(logging.ERROR)  # the "shorter than 50 tau" verdict is reported by us
    try:
        return np.asarray(emcee.autocorr.integrated_time(x, quiet=True), float)
    except Exception:  # too short for any estimate
        return np.full(x.shape[2], np.nan)
    finally:
        log.setLevel(level)


def summarize(prob: Problem, sampler, *, seed: int | None = None) -> Posterior:
    """Diagnostics, burn-in and thinning from τ, and the summary of the reported quantities."""
    chain = sampler.get_chain()
    steps, walkers, ndim = chain.shape
    tau = _tau(chain)
    max_tau = float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else float("nan")
    finite_tau = np.isfinite(max_tau)
    burn = math.ceil(2 * max_tau) if finite_tau else steps // 2
    burn = min(burn, steps - 1)
    min_tau = float(np.nanmin(tau)) if finite_tau else 2.0
    thin = max(1, int(0.5 * min_tau))
    needed = math.ceil(50 * max_tau) if finite_tau else None
    converged = bool(finite_tau and steps >= needed)
    acc = np.asarray(sampler.acceptance_fraction)
    derived_full, names = derived_quantities(prob, chain.reshape(-1, ndim))
    derived_full = derived_full.reshape(steps, walkers, -1)
    tau_d = _tau(derived_full)
    kept = derived_full[burn::thin].reshape(-1, derived_full.shape[2])
    params = {}
    for i, name in enumerate(names):
        x = kept[:, i]
        q = np.percentile(x, [2.5, 16, 50, 84, 97.5])
        t_i = float(tau_d[i])
        ess = walkers * (steps - burn) / t_i if np.isfinite(t_i) and t_i > 0 else float("nan")
        params[name] = {
            "median": float(q[2]),
            "q16": float(q[1]),
            "q84": float(q[3]),
            "q2.5": float(q[0]),
            "q97.5": float(q[4]),
            "mean": float(np.mean(x)),
            "std": float(np.std(x)),
            "tau": t_i,
            "ess": float(ess),
        }
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.corrcoef(kept.T) if kept.shape[0] > 2 else np.eye(len(names))
    if not finite_tau:
        msg = f"not converged: {steps} steps are too few for any estimate of tau"
    elif converged:
        msg = f"converged: {steps} steps >= 50 max tau = {needed}"
    else:
        msg = (
            f"not converged: {steps} steps < 50 max tau = {needed}; run at least {needed} "
            f"steps (e.g. resume with {needed - steps} more)"
        )
    diagnostics = {
        "converged": converged,
        "message": msg,
        "steps": int(steps),
        "steps_needed": needed,
        "walkers": int(walkers),
        "burn": int(burn),
        "thin": int(thin),
        "n_samples": int(kept.shape[0]),
        "acceptance": float(np.mean(acc)),
        "acceptance_min": float(np.min(acc)),
        "tau": {n: float(t) for n, t in zip(prob.names, tau, strict=True)},
        "max_tau": max_tau,
        "log_prob_evals": int(steps * walkers),
    }
    provenance = _provenance(prob, walkers, seed, getattr(sampler, "whiskerid_move", None))
    post = Posterior(
        params=params,
        diagnostics=diagnostics,
        correlations={"names": names, "matrix": np.round(np.nan_to_num(corr), 6).tolist()},
        samples=kept,
        names=names,
        chain=chain,
        chain_names=list(prob.names),
        provenance=provenance,
        derived_chain=derived_full,
    )
    post.record = _updated_record(prob.record, post)
    return post


def _provenance(prob, walkers, seed, move):
    import emcee

    from .._version import __version__

    files = []
    for o in prob.observations:
        if o.source and Path(o.source).exists():
            files.append({"path": str(o.source), "sha256": sha256_of(o.source), "name": o.name})
    return {
        "sampler": f"emcee {emcee.__version__} EnsembleSampler (vectorize=True)",
        "move": move or "unknown",
        "seed": -1 if seed is None else int(seed),
        "walkers": int(walkers),
        "likelihood": prob.model.likelihood,
        "nu": prob.nu if prob.model.likelihood == "student" else 0.0,
        "linear_nuisances": "marginalised analytically (flat prior)"
        if prob.model.marginal
        else "sampled (flat prior)",
        "noise": "unknown sigma per recording, sampled as log sigma",
        "n_modes": prob.args["problem"].n_modes,
        "pin": prob.pin,
        "priors": prob.priors,
        "start": "Laplace approximation of the calibration fit",
        "data_files": files,
        "whiskerid_version": __version__,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def _updated_record(record: WhiskerRecord, post: Posterior) -> WhiskerRecord:
    d = post.diagnostics
    table = {
        "converged": d["converged"],
        "message": d["message"],
        "params": post.params,
        "diagnostics": {k: v for k, v in d.items() if v is not None},
        "correlations": post.correlations,
        "provenance": post.provenance,
    }
    extra = dict(record.extra)
    extra["posterior"] = table
    return record.replace(extra=extra)


def sample_posterior(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    walkers: int = 32,
    steps: int = 2000,
    seed: int = 0,
    backend: str | Path | None = None,
    resume: bool = False,
    progress: bool = False,
    move: str = "de",
    **setup,
) -> Posterior:
    """Posterior of ζ, f_1, κ (EI or C) and the noise, jointly over recordings of one whisker.

    Args:
        record: The whisker's record (``[prior]`` table optional, see the module docstring).
        observations: One or more recordings.
        walkers: emcee walkers.
        steps: Steps per walker.
        seed: Makes the run reproducible (start and emcee's random state).
        backend: HDF5 file to store the chain in (``h5py``).
        resume: Continue the chain stored in ``backend``.
        progress: Show emcee's progress bar.
        move: emcee's proposal, one of :data:`MOVES` (:func:`emcee_moves`).
        **setup: Passed to :func:`setup_posterior` (``likelihood``, ``nu``, ``prior``,
            ``n_modes``, ``pin``, ``static``, ``marginalize``, ...).

    Returns:
        A :class:`Posterior` (``diagnostics["converged"]`` says whether the run was long
        enough: at least 50 autocorrelation times).
    """
    prob = setup_posterior(record, observations, **setup)
    sampler = run_sampler(
        prob,
        walkers=walkers,
        steps=steps,
        seed=seed,
        backend=backend,
        resume=resume,
        progress=progress,
        move=move,
    )
    return summarize(prob, sampler, seed=seed)
