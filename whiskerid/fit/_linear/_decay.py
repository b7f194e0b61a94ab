"""Free-decay columns: the damped modal terms every fit of a ringing whisker is built on.

Each mode contributes ``e^{−σt} cos(ω_d t)`` and ``e^{−σt} sin(ω_d t)`` (``σ = ζω``,
``ω_d = ω√(1−ζ²)``), which are the real and imaginary parts of ``e^{λt}``,
``λ = −σ + iω_d``: with them any initial condition is a linear combination. An ADS1115
result is the average of its input over the conversion period; the average of ``e^{λ(t+o_k)}``
over the offsets ``o_k`` is ``e^{λt}`` times the constant ``A = mean_k e^{λ o_k}``, so the
averaged columns cost one evaluation per sample, not one per offset.

Used by the calibration's design and the posterior's log-density (both with the fast
:func:`whiskerid.fit.sincos`) and the per-window fits.
"""

import functools

import jax
import jax.numpy as jnp


def decay_rates(omega, zeta):
    """``(σ, ω_d) = (ζω, ω√(1−ζ²))`` of modes with natural frequencies ``omega`` (rad/s)."""
    return zeta * omega, omega * jnp.sqrt(1.0 - zeta**2)


# Jitted: called with concrete arrays (plots, checks, tests) each is one compiled program,
# not one per operation; inside a traced function it is inlined.
@jax.jit
def conversion_average(sigma, wd, offsets):
    """``A = mean_k e^{λ o_k}`` (real and imaginary parts) over the averaging offsets.

    Args:
        sigma: Decay rates ``σ`` (1/s): a scalar, one per mode, or one per mode as a column
            (``(modes, 1)``, for a ``(modes, samples)`` block).
        wd: Damped angular frequencies ``ω_d`` (rad/s), same shape.
        offsets: Times (s) before each sample at which the converter averages, shape ``(k,)``.

    Returns:
        ``(Re A, Im A)``, each of the shape of ``sigma`` (at least 1-D).
    """
    off = jnp.reshape(jnp.asarray(offsets), (-1,) + (1,) * max(jnp.ndim(sigma), 1))
    e = jnp.exp(-sigma * off)
    return jnp.mean(e * jnp.cos(wd * off), axis=0), jnp.mean(e * jnp.sin(wd * off), axis=0)


@functools.partial(jax.jit, static_argnames="sincos")
def free_decay_columns(t, sigma, wd, offsets=None, *, sincos=None):
    """``e^{−σt} cos ω_d t`` and ``e^{−σt} sin ω_d t``, averaged over a conversion if asked.

    Args:
        t: Sample times (s), broadcast against ``sigma`` and ``wd`` (e.g. ``t[:, None]``
            with one rate per mode for a ``(samples, modes)`` block).
        sigma: Decay rates ``σ = ζω`` (1/s).
        wd: Damped angular frequencies ``ω_d`` (rad/s).
        offsets: The converter's averaging offsets (s), or None for point samples.
        sincos: A function ``x ↦ (sin x, cos x)``; ``jnp.sin``/``jnp.cos`` when None.

    Returns:
        ``(cos column(s), sin column(s))``.
    """
    e = jnp.exp(-sigma * t)
    if sincos is None:
        c, s = e * jnp.cos(wd * t), e * jnp.sin(wd * t)
    else:
        sn, cs = sincos(wd * t)
        c, s = e * cs, e * sn
    if offsets is None:
        return c, s
    a_re, a_im = conversion_average(sigma, wd, offsets)
    return c * a_re - s * a_im, s * a_re + c * a_im
