"""The log-posterior: likelihood of each recording (linear nuisances marginalised or
sampled), priors, and the jitted, vmapped batch function emcee calls."""

import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ..fit import (
    ZETA_MAX,
    FitProblem,
    cho_solve_small,
    cholesky_small,
    decay_rates,
    free_decay_columns,
    recording_design,
    sincos,
    to_interval,
)
from ._grid import _decay_tables, _grid_columns, _taylor_radius
from ._prior import prior_logpdf


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
        w_j = problem.whisker_of(theta, j)  # its own tip mass in the added-mass model
        lp = lp + _rec_loglik(
            model, rec, rp, grid, w_j, log_sigma[j], args["nu"], degrees[j], tables[j]
        )
    if problem.static_test is not None:
        lp = lp - 0.5 * jnp.sum(problem.static_residuals(theta) ** 2)
    lp = lp - 0.5 * jnp.sum(problem.prior_residuals(theta) ** 2)  # e.g. the added masses
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
    tables, ok = [], jnp.array(True)
    recs = zip(problem.recordings, args["grids"], model.grid_degrees, strict=True)
    for j, (rec, grid, degrees) in enumerate(recs):
        if degrees is None:
            tables.append(None)
            continue
        w = problem.whisker_of(theta, j)
        omega = w.omega_rad_s
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


def _drop_c(tree):
    return {**tree, "recs": [{k: v for k, v in r.items() if k != "c"} for r in tree["recs"]]}
