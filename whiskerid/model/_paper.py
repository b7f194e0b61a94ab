"""The paper's Eq. 1, exactly as printed (Yu et al., "A Method to use Nonlinear Dynamics in a
Whisker Sensor for Terrain Identification by Mobile Robots").

    y(x, t) = Σ_{i=1}^{5} −(𝒜 ℬ 𝒞) / 𝒟

    𝒜 = 2 a h_b l⁴ ω_b² ρ e^{−D_i² t ζ sqrt(EI/(aρ))/l²} sin(ω_b t)
        (cos D_i − 1)(cosh D_i − 1)(cos D_i + cosh D_i)
    ℬ = sinh(D_i x/l) − sin(D_i x/l)
        + (cos(D_i x/l) − cosh(D_i x/l))(sin D_i + sinh D_i)/(cos D_i + cosh D_i)
    𝒞 = ζ sin(λ_i sqrt(1−ζ²) t) − e^{+D_i² t ζ sqrt(EI/(aρ))/l²} sqrt(1−ζ²)
        + cos(λ_i sqrt(1−ζ²) t) sqrt(1−ζ²),       λ_i = D_i² sqrt(EI/(aρ))/l²
    𝒟 = D_i⁴ EI sqrt(1−ζ²) (3 sinh D cos²D cosh D − D cos²D − 3 sin D cos D cosh²D
        + 3 sinh D cos D + D cosh²D − 3 sin D cosh D + 2 D sin D sinh D)

Read closely, each mode contributes ``sin(ω_b t)`` times a damped step response of
that mode, so the spectrum has a peak at ``f_b`` flanked by peaks at ``f_b ± f_d,i``, and
there is no resonance at ``f_b = f_i``. This module keeps the formula as printed and is the
``paper`` model; :mod:`whiskerid._response` is the exact modal model.

The only rearrangement is numerical: 𝒜 carries ``e^{−ζλt}`` and 𝒞 carries ``e^{+ζλt}``,
which overflow float64 for the fifth mode after about a second; their product is formed as
``e^{−ζλt} 𝒞`` (the same value, algebraically) so long records stay finite.
"""

import jax
import jax.numpy as jnp

from .._custom_types import Samples, ScalarLike, Times
from ._modes import PAPER_D
from ._whisker import Whisker


def _denominator(d, ei, root):
    c, s, ch, sh = jnp.cos(d), jnp.sin(d), jnp.cosh(d), jnp.sinh(d)
    bracket = (
        3 * sh * c**2 * ch
        - d * c**2
        - 3 * s * c * ch**2
        + 3 * sh * c
        + d * ch**2
        - 3 * s * ch
        + 2 * d * s * sh
    )
    return d**4 * ei * root * bracket


@jax.jit  # one program per shape when called with concrete arrays, not one per operation
def paper_eq1(
    whisker: Whisker,
    t: Times,
    *,
    fb_hz: ScalarLike,
    hb_m: ScalarLike,
    x_m: ScalarLike | None = None,
    D: tuple[float, ...] = PAPER_D,
) -> Samples:
    """The paper's Eq. 1: beam displacement ``y(x, t)`` (m) for ``y_b = h_b sin(ω_b t)``.

    Args:
        whisker: Supplies ``l``, ``EI``, ``aρ`` (``rho_a``) and ζ (mode ``i`` uses
            ``zeta[i]``, or the last value when the whisker has fewer modes than ``D``).
        t: Times (s).
        fb_hz: Base excitation frequency ``f`` (Hz); ``ω_b = 2π f``.
        hb_m: Base excitation amplitude ``h_b`` (m).
        x_m: Position along the beam (m); the sensor position by default.
        D: The mode constants; the paper's five printed values by default.
    """
    t = jnp.asarray(t, dtype=float)[:, None]
    x = whisker.sensor_x_m if x_m is None else jnp.asarray(x_m, dtype=float)
    d = jnp.asarray(D, dtype=float)
    zeta = whisker.zeta[jnp.minimum(jnp.arange(d.shape[0]), whisker.n_modes - 1)]
    l, ei, rho_a = whisker.length_m, whisker.EI, whisker.rho_a
    omega_b = 2 * jnp.pi * jnp.asarray(fb_hz, dtype=float)
    h_b = jnp.asarray(hb_m, dtype=float)
    root = jnp.sqrt(1 - zeta**2)
    lam = d**2 * jnp.sqrt(ei / rho_a) / l**2
    decay = jnp.exp(-lam * zeta * t)

    a_without_exp = (
        2
        * rho_a
        * h_b
        * l**4
        * omega_b**2
        * jnp.sin(omega_b * t)
        * (jnp.cos(d) - 1)
        * (jnp.cosh(d) - 1)
        * (jnp.cos(d) + jnp.cosh(d))
    )
    dx = d * x / l
    b = (
        jnp.sinh(dx)
        - jnp.sin(dx)
        + (jnp.cos(dx) - jnp.cosh(dx)) * (jnp.sin(d) + jnp.sinh(d)) / (jnp.cos(d) + jnp.cosh(d))
    )
    # e^{−ζλt} · 𝒞, with e^{−ζλt} e^{+ζλt} = 1 taken exactly.
    decay_times_c = (
        zeta * decay * jnp.sin(lam * root * t) - root + decay * jnp.cos(lam * root * t) * root
    )
    terms = -(a_without_exp * b * decay_times_c) / _denominator(d, ei, root)
    return jnp.sum(terms, axis=-1)
