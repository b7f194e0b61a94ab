"""What an accelerometer reads of the slow flow's ``u = a cos φ``: ``ü``, to first order.

With ``ȧ = −r(a)·a`` (``r = ζ(a)ω₀``, the smooth damping: viscous and velocity-squared) and
``φ̇ = p(a) = ω(a)√(1−ζ₀²)``, the velocity is ``u̇ = −a(r cos φ + p sin φ)`` and the
equivalent linear equation ``ü = −ω(a)²u − 2r·u̇`` gives

    ü = Re[−a·K(a)·e^{iφ}],   K(a) = ω(a)² − 2r² + 2i·r·p.

For a linear mode ``|K| = ω₀²`` exactly and its phase is constant, so the linear fit's two
free coefficients absorb it. A nonlinear mode's ``K`` moves along the decay: its modulus with
``ω(a)²`` (twice the frequency rise) and its phase ``≈ 2ζ(a)`` with the damping. The phase
alone is a quarter of a 0.4 % stiffening's phase drift when ζ is 1.25× ζ₀ at the release, so
leaving it out biases γ by about −25 % (−4σ on a 40 dB pluck); both parts are kept here, as
``K(a)/K(a₀)`` (the coefficients hold ``K(a₀)``).

Dry friction is not in ``r``: an accelerometer reads its quadrature through the staircase of
:func:`whiskerid.fit._nonlinear._friction._friction_offset`.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ...model import NonlinearMode


def _k(mode, a) -> tuple[Array, Array]:
    """Real and imaginary parts of ``K(a)`` (rad²/s²; module docstring)."""
    w = mode.omega(a)
    if isinstance(mode, NonlinearMode):  # the mode's own ζ(a), its smooth part (no friction)
        mode = eqx.tree_at(lambda m: m.coulomb_m_s2, mode, jnp.zeros_like(mode.coulomb_m_s2))
    # (a log-polynomial backbone's ζ(a) is smooth and holds all the damping)
    r = mode.zeta(a) * mode.omega0
    p = w * jnp.sqrt(1.0 - mode.zeta0**2)
    return w**2 - 2 * r**2, 2 * r * p


def start_on_backbone(mode, a_obs) -> Array:
    """The start amplitude ``a₀`` (m) of an accelerometer's decay from ``a_obs``, its observed
    amplitude divided by ``ω₀²``: ``a₀|K(a₀)| = a_obs·ω₀²``, by two fixed-point steps (each
    leaves ``(Δ|K|/|K|)²`` of the last one's error)."""
    a0 = a_obs
    for _ in range(2):
        a0 = a_obs * mode.omega0**2 / jnp.hypot(*_k(mode, a0))
    return a0


def accelerometer_columns(mode, a, a0, env, phi) -> tuple[Array, Array]:
    """Mode 1's two design columns for an accelerometer: ``env·Re, Im[K(a)/K(a₀)·e^{iφ}]``.

    Args:
        mode: The first mode (:class:`whiskerid.model.NonlinearMode` or a log-polynomial
            backbone).
        a: Envelope ``a(t)`` (m, ≥ 0).
        a0: Start amplitude (m).
        env: ``a/a₀`` (zero once friction holds the whisker).
        phi: Phase ``φ(t)`` (rad).
    """
    kr, ki = _k(mode, a)
    k0r, k0i = _k(mode, a0)
    den = k0r**2 + k0i**2
    rr, ri = (kr * k0r + ki * k0i) / den, (ki * k0r - kr * k0i) / den
    cos, sin = jnp.cos(phi), jnp.sin(phi)
    return env * (rr * cos - ri * sin), env * (rr * sin + ri * cos)
