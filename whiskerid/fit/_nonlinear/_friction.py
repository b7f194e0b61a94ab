"""Dry friction's exact free response beside the slow flow's averaged ``a cos ψ``.

The slow flow follows the staircase of a decay under Coulomb friction with a straight line
through its middles; these functions give the exact departure from it and where the motion
stops (see the physics page), for :class:`whiskerid.fit.NonlinearProblem`.
"""

import jax.numpy as jnp
from jaxtyping import Array


def friction_waveform(psi: Array) -> Array:
    """Dry friction's exact correction to ``a cos ψ`` per ``F/ω₀²``, one period of ``ψ``.

    Between two turns of the velocity the mode is a cosine ``A_k cos ψ + d_k`` about a
    centre ``d_k = (F/ω₀²) sgn(sin ψ)`` (the side it moves from), and each turn lowers
    ``A_k`` by ``2F/ω₀²``: a staircase, which the slow flow's ``a(t)`` follows as a straight
    line through its middles. The difference, ``(A_k − a)cos ψ = (F/ω₀²)(2θ/π − 1)cos ψ``
    with ``θ = ψ mod π``, plus the centre, is the exact free response's departure from
    ``a cos ψ``:

        w(ψ) = sgn(sin ψ) + (2θ/π − 1) cos ψ,

    continuous (and once differentiable) in ``ψ``, odd harmonics only; its first is
    ``(3/π) sin ψ`` and its 3rd, 5th… are the square wave's, which a sampled recording well
    above ``f₀`` sees.
    """
    theta = jnp.mod(psi, jnp.pi)
    side = jnp.where(jnp.mod(psi, 2 * jnp.pi) < jnp.pi, 1.0, -1.0)  # sgn(sin ψ), at turns too
    return side + (2 * theta / jnp.pi - 1) * jnp.cos(psi)


def friction_stop(mode, t, a, psi):
    """Where dry friction stops the decay, and where it holds the whisker.

    The slow flow's envelope falls to 0 and stays (:func:`whiskerid.model.slow_flow`), but the
    exact motion stops at a turn of the velocity, ``ψ = kπ``, the first one where the
    restoring force no longer beats friction: ``|u| ≤ F/ω₀²``. At a turn the exact position is
    ``a(t_k) cos kπ`` with ``a`` the averaged envelope continued straight through 0 (each half
    cycle lowers it by ``2F/ω₀²``; continued below 0 it still gives the right turn, on the
    side the whisker came from), and the whisker stays there.

    Args:
        mode: The mode (``F``, ``ω₀``).
        t: Sample times (s).
        a: The slow flow's envelope (m), clamped at 0.
        psi: The deflection's phase ``ψ`` at ``t`` (turns at multiples of π).

    Returns:
        ``(a, held, hold)``: the envelope continued to the stop and 0 after it, the mask of
        held samples, and the held deflection (m at the tip; 0 before the stop).
    """
    # a host array (the problem's leaves are NumPy) cannot be indexed by a traced index
    t = jnp.asarray(t)
    n = t.size
    alive = a > 0
    last = jnp.maximum(jnp.sum(alive) - 1, 0)
    # near 0 friction dominates: the envelope falls on a straight line
    a = jnp.where(alive, a, a[last] + mode.decay_rate(a[last]) * (t - t[last]))
    k = jnp.floor(psi / jnp.pi)
    frac = (k[1:] * jnp.pi - psi[:-1]) / jnp.where(psi[1:] > psi[:-1], psi[1:] - psi[:-1], 1.0)
    a_turn = jnp.concatenate([a[:1], a[:-1] + frac * (a[1:] - a[:-1])])
    turned = jnp.concatenate([jnp.zeros(1, bool), k[1:] > k[:-1]])
    stops = turned & (jnp.abs(a_turn) <= mode.coulomb_m_s2 / mode.omega0**2)
    first = jnp.min(jnp.where(stops, jnp.arange(n), n))
    held = jnp.arange(n) >= first
    at = jnp.minimum(first, n - 1)
    hold = jnp.where(held, jnp.cos(k[at] * jnp.pi) * a_turn[at], 0.0)
    return jnp.where(held, 0.0, a), held, hold


def _friction_offset(rec, psi, held, mode, per_m):
    """Dry friction's departure from the averaged ``a cos ψ`` in normalised observed units
    (:func:`friction_waveform`, times ``F/ω₀²`` at the tip), 0 once held
    (:func:`friction_stop`; the held level is fitted).

    A deflection sensor sees all of it; an accelerometer only the staircase part
    (``ü = −ω₀²(u − d_k)``: the centre is not accelerated), ``(2θ/π − 1)cos ψ`` in the
    observed phase (the sign flips with ``ü``'s half-period shift and the odd symmetry), and
    nothing once the whisker is held.
    """
    offset = mode.coulomb_m_s2 / mode.omega0**2  # m at the tip
    if rec.observable == "acceleration":
        theta = jnp.mod(psi, jnp.pi)
        wave = jnp.where(held, 0.0, offset * (2 * theta / jnp.pi - 1) * jnp.cos(psi))
    else:
        wave = jnp.where(held, 0.0, offset * friction_waveform(psi))
    return jnp.abs(rec.scale) * per_m * wave
