"""An identified backbone: ``f(a)`` and ``ζ(a)`` as polynomials in ``ln a``.

The parametric model (:class:`whiskerid.model.NonlinearMode`) bends the backbone by fixed
laws: ``f`` linear or quadratic in ``a``, ``ζ`` linear in ``a`` or in ``1/a``. A real joint
need not follow any of them (the 30 cm cantilever's frequency keeps rising by a constant
step per factor ``e`` of falling amplitude, with no plateau). Here the data draw the curves
themselves, over the amplitudes they span:

    f(a) = f_lo (1 + S_f(ln a)),    ζ(a) = ζ_lo exp(S_z(ln a)),

with ``S_f``, ``S_z`` the polynomials through their values at ``K`` knots equally spaced in
``ln a`` from ``a_lo`` (the smallest amplitude the recordings inform, three times the noise)
to ``a_ref`` (the largest start), both 0 at the first knot: ``f_lo`` and ``ζ_lo`` (the fit's
``f1_hz`` and ``zeta``) are the frequency and damping at ``a_lo``, *not* ``a → 0`` values,
which a free decay can only reach by extrapolation. Beyond the end knots the curves continue
as their tangents in ``ln a``, at most two factors ``e`` below ``a_lo`` and one above
``a_ref``. ``K = 1`` is the linear model; ``K = 2`` a frequency and a log-damping linear in
``ln a``. The slow flow is the parametric one's with ``ζ(a)ω(a)`` as the decay rate,
``ȧ = −ζ(a)ω(a)a`` and ``φ̇ = ω(a)√(1−ζ_lo²)``, one Runge–Kutta step per sample
(:func:`whiskerid.model.slow_flow`, which takes any mode with ``omega`` and ``decay_rate``).

A polynomial and not a natural cubic spline: natural end conditions force zero curvature in
``ln a`` at both ends of the range, where a power law ``a^p`` (a joint's micro-slip) bends
most.

**How many knots.** Each extra knot adds two parameters. The fits for ``K = 2 …`` are
compared by the Bayesian information criterion in its likelihood-ratio form,
``BIC = RSS/(s²·r) + p ln n``, with ``s²`` the most flexible fit's residual variance and
``r ≥ 1`` the median ratio of its HAC to its white-noise variances (residuals that stay
correlated carry fewer independent samples; for white noise ``r ≈ 1`` and this is the usual
BIC). The lowest is kept.

**What it is good for (measured).** On SciPy plucks (``benchmarks/calibrate_nonlinear_logpoly.py``)
``f(a)`` is within its 1σ (pulls ±2.3); ``ζ(a)`` under velocity-squared damping is not (pulls
to 6: ``ζ₀ + ka`` bends in ``ln a`` more than the knots chosen follow, and a pointwise 1σ does
not carry the order's choice). On the real cantilever at 30 cm it is what BIC asks for and
lowers the residual at f₁ 5–20×. A study tool, not a ``calibrate`` option.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

#: Knot counts tried by :func:`calibrate_logpoly_backbone` (1 is the linear model).
KNOTS = (2, 3, 4)
#: Extrapolation limits below the first knot and above the last (in ln a).
BELOW, ABOVE = 2.0, 1.0


def lagrange_matrix(n_knots: int) -> np.ndarray:
    """``C`` with ``S(u) = Σ_j (C y)_j u^j``: the power-series coefficients of the polynomial
    through values ``y`` at ``u = 0, 1, …, K−1`` (the inverse Vandermonde matrix)."""
    u = np.arange(n_knots, dtype=float)
    return np.linalg.inv(np.vander(u, increasing=True))


def knot_polynomial(x: Array, x0: Array, h: Array, y: Array, C: Array) -> Array:
    """The polynomial in ``x`` through ``y`` at knots ``x0 + h·k``; straight lines (its
    tangents) beyond the end knots, ``x`` clipped :data:`BELOW`/:data:`ABOVE` beyond."""
    k = y.shape[0]
    if k == 1:
        return jnp.broadcast_to(y[0], jnp.shape(x))
    x = jnp.clip(x, x0 - BELOW, x0 + h * (k - 1) + ABOVE)
    c = C @ y
    powers = jnp.arange(k)
    d = c[1:] * powers[1:]  # the derivative's coefficients

    def poly(u):
        return jnp.sum(c * u[..., None] ** powers, axis=-1)

    def slope(u):
        return jnp.sum(d * u ** powers[:-1]) / h

    u = (x - x0) / h
    end = k - 1.0
    inside = poly(jnp.clip(u, 0.0, end))
    below = y[0] + slope(0.0) * (x - x0)
    above = y[-1] + slope(end) * (x - x0 - h * end)
    return jnp.where(u < 0, below, jnp.where(u > end, above, inside))


class LogPolyBackbone(eqx.Module):
    """A mode whose backbone is a pair of polynomials in ``ln a`` (see the module docstring).

    It has the interface of :class:`whiskerid.model.NonlinearMode` that the slow flow and
    the fit use (``omega``, ``frequency_hz``, ``zeta``, ``decay_rate``, ``omega0``,
    ``zeta0``, ``f0_hz``), with ``f0_hz``/``zeta0`` the values at the first knot ``a_lo``.

    Attributes:
        ln_a_lo: ``ln a_lo`` (a in m, mode 1 tip deflection), the first knot.
        h: Knot spacing in ``ln a``.
        f_lo_hz: ``f(a_lo)`` (Hz).
        zeta_lo: ``ζ(a_lo)``.
        s_f: ``S_f`` at the knots (first one 0).
        s_z: ``S_z`` at the knots (first one 0).
        C: :func:`lagrange_matrix` of the knots.
    """

    ln_a_lo: Array
    h: Array
    f_lo_hz: Array
    zeta_lo: Array
    s_f: Array
    s_z: Array
    C: Array

    def __check_init__(self):
        if self.s_f.shape != self.s_z.shape or self.C.shape != (self.s_f.size,) * 2:
            raise ValueError("LogPolyBackbone: s_f, s_z and C must match the knots")

    @property
    def f0_hz(self) -> Array:
        """``f(a_lo)`` (Hz): the smallest informed amplitude's, not an ``a → 0`` value."""
        return self.f_lo_hz

    @property
    def zeta0(self) -> Array:
        """``ζ(a_lo)``."""
        return self.zeta_lo

    @property
    def omega0(self) -> Array:
        """``2π f(a_lo)`` (rad/s)."""
        return 2 * jnp.pi * self.f_lo_hz

    def _s(self, values, a):
        x = jnp.log(jnp.maximum(jnp.asarray(a), 1e-300))
        return knot_polynomial(x, self.ln_a_lo, self.h, values, self.C)

    def omega(self, a) -> Array:
        """``ω(a) = 2πf(a)`` (rad/s)."""
        return self.omega0 * (1.0 + self._s(self.s_f, a))

    def frequency_hz(self, a) -> Array:
        """``f(a)`` (Hz)."""
        return self.omega(a) / (2 * jnp.pi)

    def zeta(self, a) -> Array:
        """``ζ(a)``."""
        return self.zeta_lo * jnp.exp(self._s(self.s_z, a))

    def decay_rate(self, a) -> Array:
        """``ȧ = −ζ(a)ω(a)a``."""
        return -self.zeta(a) * self.omega(a) * jnp.asarray(a)


def logpoly_mode(problem, params) -> LogPolyBackbone:
    """The backbone of a log-polynomial :class:`whiskerid.fit.NonlinearProblem` at
    ``params`` (``nl`` = ``S_f`` then ``S_z`` at knots 2…)."""
    w = problem.base.whisker(params)
    k = problem.n_knots
    nl = params["nl"]
    zero = jnp.zeros(1)
    return LogPolyBackbone(
        ln_a_lo=problem.ln_a_lo,
        h=(jnp.log(problem.a_ref) - problem.ln_a_lo) / max(k - 1, 1),
        f_lo_hz=w.omega_rad_s[0] / (2 * jnp.pi),
        zeta_lo=w.zeta[0],
        s_f=jnp.concatenate([zero, nl[: k - 1]]),
        s_z=jnp.concatenate([zero, nl[k - 1 :]]),
        C=jnp.asarray(lagrange_matrix(k)),
    )


def lowest_informed_amplitude(linear, amps) -> float:
    """``a_lo`` (m): the smallest amplitude the recordings inform, from the linear fit.

    Per recording, the envelope at its end (``a₀e^{−ζωT}``) or three times the noise as an
    amplitude, whichever is larger; the noise is the linear residual's RMS or, when smaller,
    its first differences' (``std(Δr)/√2``: a misfit at the whisker's frequency is smooth
    and differencing suppresses it, white noise not); then the smallest over the
    recordings, at most half the largest start."""
    w = linear.problem.whisker(linear.optimum)
    rate = float(w.zeta[0] * w.omega_rad_s[0])
    lows = []
    for (t, y, model), a0 in zip(linear.curves, amps, strict=True):
        r = np.asarray(y) - np.asarray(model)
        m = np.asarray(model) - np.mean(model)
        noise = min(float(np.std(r)), float(np.std(np.diff(r)) / np.sqrt(2)))
        peak = float(np.max(np.abs(m[: max(m.size // 20, 8)])))
        lows.append(max(a0 * np.exp(-rate * (t[-1] - t[0])), 3 * a0 * np.sqrt(2) * noise / peak))
    return float(min(min(lows), 0.5 * max(amps)))


def backbone_at(cal, amplitude_m: float) -> dict:
    """``f(a)`` (Hz) and ``ζ(a)`` of a nonlinear fit at one amplitude (m), with their 1σ
    from the fit's covariance (parametric or log-polynomial backbone)."""
    problem = cal.problem
    flat = problem.flatten(cal.optimum)

    def fn(v):
        m = problem.mode(problem.unflatten(v))
        return jnp.stack([m.frequency_hz(amplitude_m), m.zeta(amplitude_m)])

    val, jac = np.asarray(fn(flat)), np.asarray(jax.jacfwd(fn)(flat))
    std = np.sqrt(np.maximum(np.diag(jac @ np.asarray(cal.covariance) @ jac.T), 0.0))
    return {"amplitude_m": float(amplitude_m), "f_hz": float(val[0]), "f_std": float(std[0]),
            "zeta": float(val[1]), "zeta_std": float(std[1])}  # fmt: skip


def logpoly_table(cal) -> dict:
    """The record's ``[fit.nonlinear]`` table of a log-polynomial fit: the curve itself
    (``a_lo_m``, ``a_ref_m``, ``f_lo_hz``, ``zeta_lo``, ``s_f``, ``s_z`` at the knots) and
    the reported backbone. ``simulate`` and ``posterior`` refuse it (they play and sample
    the parametric model)."""
    m = cal.problem.mode(cal.optimum)
    return {
        "backbone_model": "log-polynomial",
        "amplitude": "mode 1 tip deflection (m)",
        "a_lo_m": float(np.exp(cal.problem.ln_a_lo)),
        "a_ref_m": float(cal.problem.a_ref),
        "f_lo_hz": float(m.f_lo_hz),
        "zeta_lo": float(m.zeta_lo),
        "s_f": [float(v) for v in m.s_f],
        "s_z": [float(v) for v in m.s_z],
        "backbone": {k: v for k, v in cal.backbone.items() if k != "windows"},
    }
