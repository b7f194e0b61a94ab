"""Per-window damped-oscillation fits, many windows at once (per-window modal features)."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._data import CalibrationError
from .._numerics import cached_call, lsq
from ._decay import free_decay_columns
from ._problem import ZETA_MAX

# converged when |cos(residuals, each Jacobian column)| < this (MINPACK gtol).
WINDOW_GTOL = 1e-4


class WindowFits(eqx.Module):
    """Per-window damped-oscillation fits (leading axis: windows).

    Attributes:
        damped_frequency_hz: Fitted damped frequency ``f_d`` (Hz), as seen at the samples
            (an aliased frequency stays aliased).
        zeta: Damping ratio of the fitted oscillation.
        amplitude: Oscillation amplitude at the window's first sample (signal units).
        offset: Mean level (signal units).
        rms_residual: RMS of the residuals (signal units).
        ok: Whether the fit converged on finite data.
    """

    damped_frequency_hz: Float[Array, " windows"]
    zeta: Float[Array, " windows"]
    amplitude: Float[Array, " windows"]
    offset: Float[Array, " windows"]
    rms_residual: Float[Array, " windows"]
    ok: jax.Array


def _window_residuals(u, args):
    t, y = args
    fd = jnp.exp(u[0])
    zeta = lsq.to_interval(u[1], 0.0, ZETA_MAX)
    wd = 2 * jnp.pi * fd
    sigma = zeta * wd / jnp.sqrt(1 - zeta**2)
    # The factored form e^{−σt}(a cos + b sin), not a c_col + b s_col from
    # free_decay_columns: the SciPy and lmfit peers of benchmarks/calibrate.py evaluate
    # exactly this expression, and the optimistix path must take the same steps as they do.
    e = jnp.exp(-sigma * t)
    return u[4] + e * (u[2] * jnp.cos(wd * t) + u[3] * jnp.sin(wd * t)) - y


def window_model_residuals(u, args):
    """Residuals of the damped-oscillation window model, ``fn(params, (t, y))``.

    ``u = [log f_d, logit-ζ, a, b, offset]``; the model is
    ``offset + e^{−σt}(a cos ω_d t + b sin ω_d t)`` with ``σ = ζ ω_d/√(1−ζ²)``.
    Exposed for benchmarks and peers (SciPy, lmfit) that fit the same model.
    """
    return _window_residuals(u, args)


def window_start(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Start values ``u`` for :func:`window_model_residuals` from the data, batched.

    The better of :func:`_window_candidates` (smaller residual), with the linear
    coefficients ``(a, b, offset)`` solved by least squares there (variable projection).

    Returns:
        ``u = [log f_d, logit ζ, a, b, offset]`` per window, shape ``(windows, 5)``.
    """
    t = np.atleast_2d(np.asarray(t, dtype=float))
    y = np.atleast_2d(np.asarray(y, dtype=float))
    t = np.broadcast_to(t, y.shape)
    t = t - t[:, :1]
    st = _vp_best(jnp.asarray(_window_candidates(t, y)), jnp.asarray(t), jnp.asarray(y))
    return np.concatenate([np.asarray(st["u"]), np.asarray(st["coef"])], axis=1)


def _window_candidates(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Candidate ``(log f_d, logit ζ)`` per window (NumPy), shape ``(2, windows, 2)``.

    The frequency is the spectral peak (zero-padded ×4, parabolic sub-bin interpolation)
    once with a Hann window and once without: the Hann window suits steady oscillations but
    all but erases a decay that is over within the first tenth of the window, which the
    plain spectrum still sees. ζ from the RMS ratio of the first two quarters (logarithmic
    decrement; later quarters may hold only noise).
    """
    n, m = y.shape
    rate = 1.0 / np.median(np.diff(t, axis=1), axis=1)
    yc = y - y.mean(axis=1, keepdims=True)
    quarter = m // 4
    r1 = np.sqrt(np.mean(yc[:, :quarter] ** 2, axis=1))
    r2 = np.sqrt(np.mean(yc[:, quarter : 2 * quarter] ** 2, axis=1))
    dt_quarter = t[:, quarter] - t[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.log(r1 / r2) / dt_quarter
    out = np.zeros((2, n, 2))
    for k, taper in enumerate((np.hanning(m), np.ones(m))):
        fd = _spectral_peak(yc * taper, rate)
        zeta = np.clip(np.nan_to_num(sigma / (2 * np.pi * fd), nan=0.02), 0.003, 0.5)
        out[k, :, 0] = np.log(fd)
        out[k, :, 1] = np.log(zeta / ZETA_MAX) - np.log1p(-zeta / ZETA_MAX)
    return out


def _spectral_peak(x: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Largest spectral peak per row (Hz): zero-padded ×4, parabolic in log amplitude."""
    n, m = x.shape
    nfft = 4 * m
    spec = np.abs(np.fft.rfft(x, n=nfft, axis=1))
    spec[:, 0] = 0.0
    k = np.clip(np.argmax(spec, axis=1), 1, spec.shape[1] - 2)
    rows = np.arange(n)
    lo, mid, hi = (np.log(np.maximum(spec[rows, k + s], 1e-300)) for s in (-1, 0, 1))
    denom = lo - 2 * mid + hi
    shift = np.where(denom != 0, 0.5 * (lo - hi) / np.where(denom == 0, 1, denom), 0.0)
    return np.maximum((k + shift) * rate / nfft, rate / m)


# Variable projection. The window model is linear in (a, b, offset); only u = (log f_d,
# logit ζ) is nonlinear. Each evaluation solves the 3×3 linear least-squares problem exactly,
# so Levenberg–Marquardt runs on two parameters (Kaufman's Jacobian) and needs few steps
# from the spectral start. The functions below handle one window (samples on the last axis)
# and are ``vmap``-ed over windows; all small solves are unrolled (``lsq.cholesky_small``)
# so that every operation is a vector operation across windows.
def _vp_eval(u, t, y):
    """One window at ``u = (log f_d, logit ζ)``: exact linear coefficients, residuals, cost."""
    wd = 2 * jnp.pi * jnp.exp(u[0])
    zeta = lsq.to_interval(u[1], 0.0, ZETA_MAX)
    sigma = zeta * wd / jnp.sqrt(1 - zeta**2)
    c, s = free_decay_columns(t, sigma, wd)
    m = jnp.asarray(t.shape[-1], dtype=t.dtype)
    gcc, gss = jnp.sum(c * c), jnp.sum(s * s)
    # A tiny ridge keeps the Gram matrix definite when sin ω_d t vanishes at every sample
    # (ω_d at the Nyquist frequency) or the oscillation has decayed to nothing.
    ridge = 1e-12 * (gcc + gss + m)
    gram = [[gcc + ridge], [jnp.sum(c * s), gss + ridge], [jnp.sum(c), jnp.sum(s), m + ridge]]
    L = lsq.cholesky_small(gram)
    a, b, off = lsq.cho_solve_small(L, [jnp.sum(c * y), jnp.sum(s * y), jnp.sum(y)])
    r = a * c + b * s + off - y
    return {"u": u, "c": c, "s": s, "L": L, "coef": jnp.stack([a, b, off]), "r": r,
            "cost": 0.5 * jnp.sum(r * r), "wd": wd, "zeta": zeta, "sigma": sigma}  # fmt: skip


@jax.jit
def _vp_best(cands, t, y):
    """The candidate ``u`` (leading axis) with the smaller residual per window, evaluated."""
    evaluate = jax.vmap(_vp_eval)
    best = evaluate(cands[0], t, y)
    for u in cands[1:]:
        new = evaluate(u, t, y)
        take = new["cost"] < best["cost"]
        best = jax.tree_util.tree_map(lambda x, z, m=take: _where_lane(m, z, x), best, new)
    return best


def _where_lane(mask, x, y):
    """``where(mask, x, y)`` with ``mask`` per window broadcast over trailing axes."""
    return jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - mask.ndim)), x, y)


def _vp_normal(st, t):
    """Gauss–Newton normal equations in ``u`` (Kaufman's variable-projection Jacobian).

    Returns ``(H, g, gradient test)``: the 2×2 ``JᵀJ`` (nested lists), ``Jᵀr``, and the
    largest cosine between ``r`` and a column of ``J`` (MINPACK's ``gtol`` measure).
    """
    a, b, _ = st["coef"]
    c, s, r = st["c"], st["s"], st["r"]
    wd, zeta, sigma = st["wd"], st["zeta"], st["sigma"]
    p = a * c + b * s  # the oscillation e^{−σt}(a cos + b sin)
    q = b * c - a * s  # ∂p/∂ω_d = t q,  ∂p/∂σ = −t p
    # ∂ω_d/∂u₀ = ω_d, ∂σ/∂u₀ = σ (ζ fixed); ∂σ/∂u₁ = ω_d ζ(1 − ζ/ζmax)/(1 − ζ²)^{3/2}
    ds_du1 = wd * zeta * (1 - zeta / ZETA_MAX) / (1 - zeta**2) ** 1.5
    d0 = t * (wd * q - sigma * p)
    d1 = -ds_du1 * t * p
    # J = (I − P_B) D with P_B the projector on the linear columns B = [c, s, 1]:
    # JᵀJ = DᵀD − (BᵀD)ᵀ (BᵀB)⁻¹ BᵀD, and Jᵀr = Dᵀr because r ⟂ B at the exact coefficients.
    bd0 = [jnp.sum(c * d0), jnp.sum(s * d0), jnp.sum(d0)]
    bd1 = [jnp.sum(c * d1), jnp.sum(s * d1), jnp.sum(d1)]
    x0 = lsq.cho_solve_small(st["L"], bd0)
    x1 = lsq.cho_solve_small(st["L"], bd1)
    h00 = jnp.sum(d0 * d0) - sum(i * j for i, j in zip(bd0, x0, strict=True))
    h01 = jnp.sum(d0 * d1) - sum(i * j for i, j in zip(bd0, x1, strict=True))
    h11 = jnp.sum(d1 * d1) - sum(i * j for i, j in zip(bd1, x1, strict=True))
    g0, g1 = jnp.sum(d0 * r), jnp.sum(d1 * r)
    rn = jnp.sqrt(2 * st["cost"])
    tiny = jnp.finfo(t.dtype).tiny
    gtest = jnp.maximum(
        jnp.abs(g0) / jnp.maximum(jnp.sqrt(jnp.abs(h00)) * rn, tiny),
        jnp.abs(g1) / jnp.maximum(jnp.sqrt(jnp.abs(h11)) * rn, tiny),
    )
    return (h00, h01, h11), (g0, g1), gtest


def _vp_trial(st, lam, t):
    """The damped Gauss–Newton step from ``st`` (Marquardt's diagonal scaling)."""
    (h00, h01, h11), (g0, g1), gtest = _vp_normal(st, t)
    a00, a11 = h00 * (1 + lam), h11 * (1 + lam)
    det = a00 * a11 - h01 * h01
    du0 = -(a11 * g0 - h01 * g1) / det
    du1 = -(a00 * g1 - h01 * g0) / det
    return st["u"] + jnp.stack([du0, du1]), gtest


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _vp_fit(u0, t, y, *, max_steps: int = 40, rtol: float = 1e-10, gtol: float = 1e-6):
    """Variable-projection Levenberg–Marquardt over a batch of windows (leading axis).

    ``u0``: start values ``(log f_d, logit ζ)``, shape ``(windows, 2)``, or candidates of
    shape ``(k, windows, 2)`` of which each window starts from its best.

    All windows step together in one loop (no per-window ``while``) until every window has
    converged (relative cost change below ``rtol`` or gradient test below ``gtol``) or
    ``max_steps``. A window whose trial is worse or not finite keeps its point and raises
    its damping (×4; ÷3 after a success), so a NaN window only stalls itself.

    Returns:
        ``(u, coef, cost, ok, steps)``: nonlinear parameters ``(log f_d, logit ζ)``,
        linear ones ``(a, b, offset)``, half the residual sum of squares, convergence per
        window (finite, and MINPACK's gradient test below :data:`WINDOW_GTOL` or a residual
        at rounding level) and the number of loop steps taken.
    """
    evaluate = jax.vmap(_vp_eval)
    trial = jax.vmap(_vp_trial)
    st = _vp_best(u0[None] if u0.ndim == 2 else u0, t, y)
    n = t.shape[0]

    def cond(carry):
        k, _, _, done, _ = carry
        return (k < max_steps) & ~jnp.all(done)

    def body(carry):
        k, st, lam, done, _ = carry
        u_new, gtest = trial(st, lam, t)
        new = evaluate(u_new, t, y)
        better = jnp.isfinite(new["cost"]) & (new["cost"] < st["cost"]) & ~done
        small = st["cost"] - new["cost"] <= rtol * st["cost"]
        done = done | (better & small) | (gtest < gtol) | ~jnp.isfinite(st["cost"])
        st = jax.tree_util.tree_map(lambda x, z: _where_lane(better, z, x), st, new)
        lam = jnp.where(better, lam / 3, lam * 4)
        return k + 1, st, lam, done | (lam > 1e16), gtest

    init = (0, st, jnp.full(n, 1e-3), jnp.zeros(n, bool), jnp.full(n, jnp.inf))
    k, st, _, _, _ = jax.lax.while_loop(cond, body, init)
    _, gtest = trial(st, jnp.zeros(n), t)
    # Converged: residuals orthogonal to the Jacobian, or (noise-free data) residuals at
    # rounding level, where that cosine is a ratio of rounding errors.
    exact = st["cost"] <= 0.5 * 1e-16 * jnp.sum(y**2, axis=-1)
    ok = jnp.isfinite(st["cost"]) & jnp.all(jnp.isfinite(st["u"]), axis=-1)
    ok &= (gtest < WINDOW_GTOL) | exact
    return st["u"], st["coef"], st["cost"], ok, k


def _vp_fit_dict(u0, t, y, *, max_steps: int) -> dict:
    u, coef, cost, ok, _ = _vp_fit(u0, t, y, max_steps=max_steps)
    return {"u": u, "coef": coef, "cost": cost, "ok": ok}


def _vp_fit_cached(cands, t, y, *, max_steps: int):
    """:func:`_vp_fit` through the program cache (module ``_aot``): a fresh process loads
    the compiled loop instead of tracing it again (0.7 s of a warm nonlinear calibration)."""
    fn = functools.partial(_vp_fit_dict, max_steps=max_steps)
    out = cached_call("windows", fn, (cands, t, y), static=(max_steps,))
    return (np.asarray(out[k]) for k in ("u", "coef", "cost", "ok"))


def fit_windows(
    windows: Float[np.ndarray, "windows samples"],
    *,
    rate_hz: float | None = None,
    t: np.ndarray | None = None,
    solver: str = "levenberg-marquardt",
    max_steps: int = 100,
) -> WindowFits:
    """Fit a damped oscillation to each window at once (``vmap``; for per-window features).

    Model per window: ``offset + A e^{−ζω t} cos(ω_d t + φ)`` (one mode), evaluated at the
    given sample times. Start values come from each window's spectral peak and RMS decay
    (:func:`window_start`). The default solver is Levenberg–Marquardt by variable
    projection: the amplitude terms and offset are solved exactly at every step, so only
    ``log f_d`` and ``logit ζ`` are iterated, all windows together in one compiled loop
    (:func:`_vp_fit`; for 1000 windows of 200 samples the solve is 25–60× faster than a
    SciPy loop from the same starts, the whole call 15–35×: ``benchmarks/calibrate.py``).
    A window of NaNs or garbage gets ``ok = False`` and leaves the others untouched.

    Args:
        windows: Samples, shape ``(windows, samples)``.
        rate_hz: Uniform sample rate (Hz); or give ``t``.
        t: Sample times (s), shape ``(samples,)`` shared or ``(windows, samples)``.
        solver: ``levenberg-marquardt`` (variable projection, default), or an optimistix
            solver on all five parameters, ``vmap``-ed: ``optimistix-lm``, ``dogleg``,
            ``gauss-newton`` (slower: a vmapped adaptive solver runs every window until the
            slowest stops).
        max_steps: Step limit per window.

    Returns:
        :class:`WindowFits` with one entry per window. ``ok`` needs finite data and a
        converged fit: the residuals orthogonal to every Jacobian column (cosine below
        ``1e-4``, MINPACK's gradient test) for the default solver, optimistix's own status
        for the others.
    """
    y = np.asarray(windows, dtype=float)
    if y.ndim != 2 or y.shape[1] < 8:
        raise CalibrationError(f"windows must have shape (windows, samples >= 8), got {y.shape}")
    n, m = y.shape
    if t is None:
        if rate_hz is None or not rate_hz > 0:
            raise CalibrationError("fit_windows needs rate_hz or t")
        t = np.arange(m) / float(rate_hz)
    t = np.broadcast_to(np.asarray(t, dtype=float), (n, m))
    t = t - t[:, :1]
    finite = np.all(np.isfinite(y), axis=1) & np.all(np.isfinite(t), axis=1)
    finite &= np.all(np.diff(t, axis=1) > 0, axis=1)
    y_safe = np.where(finite[:, None], y, 0.0)
    t_safe = np.where(finite[:, None], t, np.arange(m)[None, :] / 100.0)
    mean = y_safe.mean(axis=1, keepdims=True)
    std = y_safe.std(axis=1, keepdims=True)
    std = np.where(std > 0, std, 1.0)
    yn = (y_safe - mean) / std
    data = (jnp.asarray(t_safe), jnp.asarray(yn))
    cands = _window_candidates(t_safe, yn)
    if solver == "levenberg-marquardt":
        u_nl, coef, cost, ok_fit = _vp_fit_cached(cands, t_safe, yn, max_steps=max_steps)
        u = np.concatenate([np.asarray(u_nl), np.asarray(coef)], axis=1)
    else:
        names = {"optimistix-lm": "levenberg-marquardt", "dogleg": "dogleg"}
        names["gauss-newton"] = "gauss-newton"
        if solver not in names:
            raise CalibrationError(
                "solver must be levenberg-marquardt, optimistix-lm, dogleg or gauss-newton; "
                f"got {solver!r}"
            )
        # rtol 1e-8 is ample for features and saves steps of the slowest lane
        u0 = window_start(t_safe, yn)
        res = lsq.batch_least_squares(
            _window_residuals,
            jnp.asarray(u0),
            data,
            solver=lsq.make_solver(names[solver], rtol=1e-8, atol=1e-10),
            max_steps=max_steps,
        )
        u, ok_fit, cost = np.asarray(res.value), np.asarray(res.ok), res.cost
    u = np.asarray(u)
    zeta = np.asarray(lsq.to_interval(jnp.asarray(u[:, 1]), 0.0, ZETA_MAX))
    rms = np.sqrt(2 * np.asarray(cost) / m) * std[:, 0]
    ok = np.asarray(ok_fit) & finite & np.all(np.isfinite(u), axis=1)
    nan = np.where(ok, 1.0, np.nan)
    return WindowFits(
        damped_frequency_hz=jnp.asarray(np.exp(u[:, 0]) * nan),
        zeta=jnp.asarray(zeta * nan),
        amplitude=jnp.asarray(np.hypot(u[:, 2], u[:, 3]) * std[:, 0] * nan),
        offset=jnp.asarray((u[:, 4] * std[:, 0] + mean[:, 0]) * nan),
        rms_residual=jnp.asarray(rms * nan),
        ok=jnp.asarray(ok),
    )
