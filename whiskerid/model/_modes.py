"""Cantilever eigenvalues, mode shapes and participation factors, with an optional tip mass.

A uniform Euler–Bernoulli cantilever of length ``l``, bending stiffness ``EI`` and line
density ``ρa``, clamped at ``x = 0`` and carrying a point mass ``M_t`` at ``x = l``, has
natural frequencies ``ω_i = β_i² sqrt(EI/(ρa)) / l²`` where ``β_i`` are the positive roots of

    1 + cos β cosh β + μ β (cos β sinh β − sin β cosh β) = 0,    μ = M_t / (ρ a l).

With ``μ = 0`` these are the paper's constants D = 1.8751, 4.6941, 7.8548, 10.9955, 14.137.
The roots are found by bisection on brackets that hold for every ``μ ≥ 0`` (each root falls
from the ``μ = 0`` root towards the ``μ → ∞`` root of ``tan β = tanh β`` as μ grows) and are
differentiated implicitly, so gradients with respect to ``μ`` are exact. A concrete ``μ``
(not traced: no tip mass, or a tip-mass ratio that is a constant of the computation, as in a
fit of κ and ζ alone) is solved on the host once per value (cached), in the same brackets by
Newton steps kept inside them, then the same final Newton step, so a jitted model carries
the roots as constants instead of an 80-step loop; the two paths agree to rounding (within
1e-15 for ``μ ≤ 1000``, tested).

Why not ``optimistix.root_find`` with ``optimistix.Bisection``: it finds one root per call
from ``options=dict(lower=..., upper=...)`` in a ``while_loop`` with a tolerance test, so all
modes would be ``vmap``-ed (every lane then runs until the slowest stops). The bracket here
holds for every ``μ ≥ 0`` and every mode at
once, 80 halvings take any bracket to rounding level, and the gradient is already the
implicit-function one (the Newton step below), which is what ``optx.ImplicitAdjoint``
would add; a library solver would change none of the numbers and add a loop per mode.

Mode shapes use the dimensionless coordinate ``ξ = x / l``:

    φ(ξ) = cosh βξ − cos βξ − σ (sinh βξ − sin βξ),   σ = (cosh β + cos β)/(sinh β + sin β),

which satisfy φ(0) = φ'(0) = 0 and φ''(1) = 0; the shear condition at the tip gives the
frequency equation above. They are evaluated in a cancellation-free form
(``cosh z − σ sinh z = e^{−z} + (1 − σ) sinh z``), so high modes keep full precision.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import PerMode, Scalar

#: The paper's printed constants (roots of 1 + cos D cosh D = 0, rounded as printed).
PAPER_D = (1.8751, 4.6941, 7.8548, 10.9955, 14.137)

_BISECTION_STEPS = 80


def _bisect_np(f, lo: float, hi: float, steps: int = 200) -> float:
    """Plain bisection on a sign change (NumPy, used once per mode for the brackets)."""
    flo = f(lo)
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        fmid = f(mid)
        if np.sign(fmid) == np.sign(flo):
            lo, flo = mid, fmid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@functools.lru_cache(maxsize=64)
def _brackets(n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """Brackets ``[β_i(μ→∞), β_i(μ=0)]`` for the first ``n_modes`` roots."""

    def g0(b):  # 1 + cos cosh = 0, scaled by 1/cosh to stay finite
        return 1.0 / np.cosh(b) + np.cos(b)

    def ginf(b):  # μ → ∞ limit: cos tanh − sin = 0  (tan β = tanh β)
        return np.cos(b) * np.tanh(b) - np.sin(b)

    hi = np.array(
        [
            _bisect_np(g0, (2 * i - 1) * np.pi / 2 - 0.4, (2 * i - 1) * np.pi / 2 + 0.4)
            for i in range(1, n_modes + 1)
        ]
    )
    lo = np.array(
        [0.0]
        + [
            _bisect_np(ginf, (4 * k + 1) * np.pi / 4 - 0.2, (4 * k + 1) * np.pi / 4 + 0.2)
            for k in range(1, n_modes)
        ]
    )
    return lo, hi


def _frequency_function(beta, mu, xp=jnp):
    """The frequency equation divided by cosh β (same roots, no overflow); ``xp`` is
    ``jax.numpy``, ``numpy`` or ``math``."""
    return (
        1.0 / xp.cosh(beta)
        + xp.cos(beta)
        + mu * beta * (xp.cos(beta) * xp.tanh(beta) - xp.sin(beta))
    )


def _frequency_slope(beta, mu, xp=np):
    """The derivative in β of :func:`_frequency_function`; ``xp`` is ``numpy`` or ``math``."""
    c, s, ch, th = xp.cos(beta), xp.sin(beta), xp.cosh(beta), xp.tanh(beta)
    return -th / ch - s + mu * (c * th - s) + mu * beta * (-s * th + c / ch**2 - c)


def _value_and_slope(beta: float, mu: float) -> tuple[float, float]:
    """:func:`_frequency_function` and its derivative in β at one point (Python floats)."""
    return _frequency_function(beta, mu, math), _frequency_slope(beta, mu, math)


def _newton_in_bracket(mu: float, lo: float, hi: float) -> float:
    """The root of the frequency equation in ``[lo, hi]`` (a sign change) by Newton steps
    kept inside the bracket, which each evaluation narrows (a step that would leave it is a
    bisection instead), until a step is at rounding level: 5–8 evaluations where 80
    halvings took 80."""
    f_lo = _value_and_slope(lo, mu)[0]
    beta = 0.5 * (lo + hi)
    for _ in range(200):  # each bisection halves the bracket: far more than ever needed
        f, slope = _value_and_slope(beta, mu)
        if f == 0.0:
            return beta
        if (f > 0) == (f_lo > 0):
            lo, f_lo = beta, f
        else:
            hi = beta
        step = beta - f / slope if slope != 0.0 else math.nan
        new = step if lo <= step <= hi else 0.5 * (lo + hi)
        if abs(new - beta) <= 4 * np.finfo(float).eps * abs(beta):
            return new
        beta = new
    return beta


@functools.lru_cache(maxsize=256)
def _roots_np(mu: float, n_modes: int) -> np.ndarray:
    """:func:`cantilever_roots` at a concrete ``μ``, on the host (read-only, cached).

    The same bracket as the traced path's bisection, searched by safeguarded Newton steps
    (:func:`_newton_in_bracket`) instead of 80 halvings in NumPy (0.67 ms for each whisker
    not seen before in a process, a twentieth of a warm calibration), then the traced
    path's final Newton step. Both land on the root to rounding (within 1e-13, relative;
    tested against the traced bisection)."""
    lo, hi = _brackets(n_modes)
    beta = np.array([_newton_in_bracket(mu, a + 1e-12, b) for a, b in zip(lo, hi, strict=True)])
    # The traced path's final Newton step (a correction at rounding level).
    out = beta - _frequency_function(beta, mu, np) / _frequency_slope(beta, mu)
    out.setflags(write=False)
    return out


def host_roots(mu: float, n_modes: int) -> np.ndarray:
    """:func:`cantilever_roots` of a concrete ``μ ≥ 0`` as a NumPy array (read-only,
    cached), for host code: without the device transfer of ``cantilever_roots``'s JAX
    array."""
    return _roots_np(float(mu), int(n_modes))


def cantilever_roots(mu: Scalar | float, n_modes: int = 5) -> PerMode:
    """Dimensionless eigenvalues ``β_i`` of a cantilever with tip-mass ratio ``μ``.

    Args:
        mu: Tip mass over beam mass, ``M_t / (ρ a l)`` (dimensionless, ``≥ 0``).
        n_modes: How many roots to return (static).

    Returns:
        ``β_1 < β_2 < ...`` (shape ``(n_modes,)``); differentiable in ``mu``.
    """
    if not isinstance(mu, jax.core.Tracer):
        # Concrete μ: nothing to differentiate, so the roots are constants (cached).
        mu_np = np.asarray(mu, dtype=float)
        if mu_np.ndim == 0 and np.isfinite(mu_np) and mu_np >= 0:
            return jnp.asarray(_roots_np(float(mu_np), int(n_modes)))
    lo_np, hi_np = _brackets(int(n_modes))
    mu = jnp.asarray(mu, dtype=float)
    mu_c = jax.lax.stop_gradient(mu)
    lo = jnp.asarray(lo_np) + 1e-12
    hi = jnp.asarray(hi_np)
    f_lo = _frequency_function(lo, mu_c)

    def step(_, bounds):
        lo, hi, f_lo = bounds
        mid = 0.5 * (lo + hi)
        f_mid = _frequency_function(mid, mu_c)
        same = jnp.sign(f_mid) == jnp.sign(f_lo)
        return jnp.where(same, mid, lo), jnp.where(same, hi, mid), jnp.where(same, f_mid, f_lo)

    lo, hi, _ = jax.lax.fori_loop(0, _BISECTION_STEPS, step, (lo, hi, f_lo))
    beta = jax.lax.stop_gradient(0.5 * (lo + hi))
    # One Newton step at the converged root: the value is unchanged (F ≈ 0) and its
    # derivative is −F_μ / F_β, the implicit-function-theorem gradient.
    dfdb = jax.grad(lambda b: _frequency_function(b, mu_c))
    slope = jax.lax.stop_gradient(jax.vmap(dfdb)(beta))
    return beta - _frequency_function(beta, mu) / slope


def _sigma_and_one_minus_sigma(beta):
    denom = jnp.sinh(beta) + jnp.sin(beta)
    sigma = (jnp.cosh(beta) + jnp.cos(beta)) / denom
    one_minus = (jnp.sin(beta) - jnp.cos(beta) - jnp.exp(-beta)) / denom
    return sigma, one_minus


# The modal helpers below are jitted: called with concrete arrays (plots, simulations, checks),
# each is then one compiled program per shape instead of a dozen operations compiled one by
# one; inside a traced function they are inlined as before.
@functools.partial(jax.jit, static_argnames="derivative")
def mode_shape(beta: PerMode, xi, derivative: int = 0):
    """Mode shapes ``φ_i`` (or their ``ξ``-derivatives) at ``ξ = x/l``.

    Args:
        beta: Eigenvalues, shape ``(modes,)``.
        xi: Positions along the beam divided by its length; any shape ``S``.
        derivative: 0 to 3, the order of ``d/dξ``.

    Returns:
        Array of shape ``S + (modes,)``. Normalised so that ``φ_i(1) = ±2`` for ``μ = 0``.
    """
    sigma, one_minus = _sigma_and_one_minus_sigma(beta)
    z = jnp.asarray(xi)[..., None] * beta
    e, sh, ch, s, c = jnp.exp(-z), jnp.sinh(z), jnp.cosh(z), jnp.sin(z), jnp.cos(z)
    if derivative == 0:
        return e + one_minus * sh - c + sigma * s
    if derivative == 1:
        return beta * (-e + one_minus * ch + s + sigma * c)
    if derivative == 2:
        return beta**2 * (e + one_minus * sh + c - sigma * s)
    if derivative == 3:
        return beta**3 * (-e + one_minus * ch - s - sigma * c)
    raise ValueError(f"derivative must be 0, 1, 2 or 3, not {derivative!r}")


@functools.lru_cache(maxsize=16)
def _gauss_legendre(n_points: int) -> tuple[np.ndarray, np.ndarray]:
    nodes, weights = np.polynomial.legendre.leggauss(n_points)
    return 0.5 * (nodes + 1.0), 0.5 * weights  # mapped to [0, 1]


def quadrature(n_modes: int) -> tuple[jax.Array, jax.Array]:
    """Gauss–Legendre nodes and weights on ``[0, 1]``, enough for ``n_modes`` mode shapes."""
    nodes, weights = _gauss_legendre(max(96, 12 * int(n_modes)))
    return jnp.asarray(nodes), jnp.asarray(weights)


@jax.jit
def integral_of_shape(beta: PerMode) -> PerMode:
    """``∫₀¹ φ_i dξ`` in closed form."""
    sigma, one_minus = _sigma_and_one_minus_sigma(beta)
    return (
        1.0
        - jnp.exp(-beta)
        + one_minus * (jnp.cosh(beta) - 1.0)
        - jnp.sin(beta)
        + sigma * (1.0 - jnp.cos(beta))
    ) / beta


@jax.jit
def modal_mass_ratio(beta: PerMode, mu: Scalar | float) -> PerMode:
    """Modal mass over beam mass: ``∫₀¹ φ_i² dξ + μ φ_i(1)²``."""
    nodes, weights = quadrature(beta.shape[0])
    phi = mode_shape(beta, nodes)
    return weights @ phi**2 + mu * mode_shape(beta, 1.0) ** 2


@jax.jit
def participation_factors(beta: PerMode, mu: Scalar | float) -> PerMode:
    """Mass-weighted participation factors ``Γ_i = ∫ m φ_i / ∫ m φ_i²`` (tip mass included).

    They appear in the modal equations for base excitation,
    ``q̈_i + 2 ζ_i ω_i q̇_i + ω_i² q_i = −Γ_i ÿ_b``, and satisfy ``Σ Γ_i φ_i(ξ) → 1``.
    """
    numerator = integral_of_shape(beta) + mu * mode_shape(beta, 1.0)
    return numerator / modal_mass_ratio(beta, mu)


def project_shape(beta: PerMode, mu: Scalar | float, shape_fn) -> PerMode:
    """Modal coordinates of a deflection shape ``w(ξ)`` (mass-weighted projection).

    Args:
        beta: Eigenvalues.
        mu: Tip-mass ratio.
        shape_fn: Vectorised function of ``ξ`` giving the deflection (m) or velocity (m/s).

    Returns:
        ``q_i = (∫ φ_i w dξ + μ φ_i(1) w(1)) / (∫ φ_i² dξ + μ φ_i(1)²)``.
    """
    nodes, weights = quadrature(beta.shape[0])
    phi = mode_shape(beta, nodes)
    numerator = (weights * shape_fn(nodes)) @ phi + mu * mode_shape(beta, 1.0) * shape_fn(1.0)
    return numerator / modal_mass_ratio(beta, mu)
