"""The exact modal model of a cantilever under base excitation, in JAX.

The relative deflection (beam minus base) is ``w(x, t) = Σ_i φ_i(x) q_i(t)`` with

    q̈_i + 2 ζ_i ω_i q̇_i + ω_i² q_i = −Γ_i ÿ_b(t)

(a linear beam resonates at ``f_i``; the paper's Eq. 1 as printed does not). Everything here is
float64-ready and works under ``jit``, ``vmap`` and ``grad``.
Three forms are provided:

* :func:`harmonic_steady_state` and :func:`harmonic_from_rest` for ``y_b = h_b sin(ω_b t)``
  (closed form at any time);
* :func:`free_decay` from initial modal displacements and velocities (closed form), with
  :func:`pluck` and :func:`tap` to build them from a tip deflection or a tip impulse;
* :func:`base_motion_response` from rest for an arbitrary sampled base acceleration, by the
  exact per-mode discretisation of a piecewise-linear input inside ``lax.scan`` (any, even
  non-uniform, time steps).

Each returns a :class:`ModalState` (``q``, ``q̇``, ``q̈`` over time), which
:func:`observe` turns into deflection, velocity or acceleration at a point of the beam.

**Static correction.** Near the clamp (where the paper's Hall sensor sits, ``x_s/l = 0.083``)
the modal sum converges slowly: with five modes the relative deflection at ``x_s`` is off
by up to 13 % against a converged finite-element beam, because every higher mode still
responds quasi-statically. :func:`observe` therefore adds, by default, the exact
quasi-static response of all truncated modes (the mode-acceleration method):
``−ÿ_b(t) R(x)`` with ``R(x) = S(x) − Σ_{i≤n} Γ_i φ_i(x)/ω_i²``, where
``S(x) = ρa x²(6l² − 4lx + x²)/(24 EI) + M_t x²(3l − x)/(6 EI)`` is the static deflection
per unit base acceleration (``Σ_{all i} Γ_i φ_i/ω_i² = S``). This is exact as
``f_b/f_{n+1} → 0`` and brings five modes within 0.1 % of the finite-element beam from
1 Hz to 500 Hz.
"""

from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import ModalSeries, PerMode, Samples, ScalarLike, Times
from ._modes import mode_shape, participation_factors, project_shape
from ._whisker import Whisker

Observable = Literal["deflection", "velocity", "acceleration"]
OBSERVABLES = ("deflection", "velocity", "acceleration")


class ModalState(NamedTuple):
    """Modal displacements, velocities and accelerations, shape ``(samples, modes)``.

    ``base_acc`` is the base acceleration ``ÿ_b`` at the same samples (m/s²), needed for
    absolute accelerations; ``base_jerk`` and ``base_snap`` are its first and second time
    derivatives, used by the static correction of velocities and accelerations.
    """

    q: ModalSeries
    qd: ModalSeries
    qdd: ModalSeries
    base_acc: Samples
    base_jerk: Samples
    base_snap: Samples


class ModalParams(NamedTuple):
    """Per-mode quantities the response formulas need."""

    omega: PerMode  # rad/s
    zeta: PerMode
    gamma: PerMode  # participation factors


def modal_params(whisker: Whisker) -> ModalParams:
    """``ω_i``, ``ζ_i`` and ``Γ_i`` of a whisker."""
    beta = whisker.beta
    omega = beta**2 * jnp.sqrt(whisker.kappa) / whisker.length_m**2
    return ModalParams(omega, whisker.zeta, participation_factors(beta, whisker.mu))


def shape_at(whisker: Whisker, x_m: ScalarLike | None = None) -> PerMode:
    """Mode shapes ``φ_i(x)`` at ``x`` (the sensor position by default)."""
    x = whisker.sensor_x_m if x_m is None else jnp.asarray(x_m, dtype=float)
    return mode_shape(whisker.beta, x / whisker.length_m)


def observe(
    whisker: Whisker,
    state: ModalState,
    observable: Observable = "deflection",
    *,
    x_m: ScalarLike | None = None,
    absolute: bool = False,
    static_correction: bool = True,
) -> Samples:
    """Deflection (m), velocity (m/s) or acceleration (m/s²) at ``x`` along the beam.

    Args:
        whisker: The whisker the state belongs to.
        state: Modal response over time.
        observable: Which derivative to return.
        x_m: Position from the clamp (m); the whisker's sensor position by default.
        absolute: Relative to the base (what a base-mounted Hall sensor sees) when False;
            in the inertial frame when True. Only accelerations can be made absolute here
            (an accelerometer on the beam measures ``ẅ + ÿ_b``).
        static_correction: Add the quasi-static response of the truncated modes (see the
            module docstring); False gives the bare modal sum.
    """
    x = whisker.sensor_x_m if x_m is None else jnp.asarray(x_m, dtype=float)
    phi = shape_at(whisker, x)
    series = {
        "deflection": (state.q, state.base_acc),
        "velocity": (state.qd, state.base_jerk),
        "acceleration": (state.qdd, state.base_snap),
    }
    if observable not in series:
        raise ValueError(f"observable must be one of {OBSERVABLES}, not {observable!r}")
    modal, base_derivative = series[observable]
    out = modal @ phi
    if static_correction:
        out = out - base_derivative * residual_flexibility(whisker, x)
    if absolute:
        if observable != "acceleration":
            raise ValueError("absolute=True is available for accelerations only")
        out = out + state.base_acc
    return out


def static_deflection_per_acc(whisker: Whisker, x_m: ScalarLike) -> jax.Array:
    """``S(x)``: static relative deflection per unit base acceleration (m per m/s²)."""
    x, l, ei = jnp.asarray(x_m, dtype=float), whisker.length_m, whisker.EI
    distributed = whisker.rho_a * x**2 * (6 * l**2 - 4 * l * x + x**2) / (24 * ei)
    return distributed + whisker.tip_mass_kg * x**2 * (3 * l - x) / (6 * ei)


def residual_flexibility(whisker: Whisker, x_m: ScalarLike) -> jax.Array:
    """``R(x) = S(x) − Σ_{i≤n} Γ_i φ_i(x)/ω_i²``: what the truncated modes add statically."""
    omega, _, gamma = modal_params(whisker)
    return static_deflection_per_acc(whisker, x_m) - jnp.sum(
        gamma * shape_at(whisker, x_m) / omega**2
    )


def _damped(omega, zeta):
    return omega * jnp.sqrt(1.0 - zeta**2)


@jax.jit  # one program per shape when called with concrete arrays, not one per operation
def _free(params: ModalParams, t, q0, v0):
    """Closed-form free response of each mode (broadcast over ``t[:, None]``)."""
    omega, zeta, _ = params
    wd = _damped(omega, zeta)
    t = jnp.asarray(t)[:, None]
    decay = jnp.exp(-zeta * omega * t)
    c, s = jnp.cos(wd * t), jnp.sin(wd * t)
    q = decay * (q0 * c + (v0 + zeta * omega * q0) / wd * s)
    qd = decay * (v0 * c - (omega**2 * q0 + zeta * omega * v0) / wd * s)
    qdd = -2 * zeta * omega * qd - omega**2 * q
    return q, qd, qdd


def free_decay(whisker: Whisker, t: Times, *, q0: PerMode, v0: PerMode | None = None) -> ModalState:
    """Free vibration from modal displacements ``q0`` (m) and velocities ``v0`` (m/s).

    Build ``q0``/``v0`` with :func:`pluck`, :func:`tap` or :func:`project_initial_shape`.
    """
    params = modal_params(whisker)
    v0 = jnp.zeros_like(q0) if v0 is None else v0
    q, qd, qdd = _free(params, t, q0, v0)
    zeros = jnp.zeros(jnp.shape(t))
    return ModalState(q, qd, qdd, zeros, zeros, zeros)


def pluck(whisker: Whisker, tip_deflection_m: ScalarLike) -> PerMode:
    """Modal displacements of the static shape under a tip force (a pluck released at rest).

    The shape is ``w₀(ξ) = δ ξ² (3 − ξ)/2`` for a tip deflection ``δ`` (Euler–Bernoulli,
    ``F l³/(3 EI) = δ``); a tip mass does not change a static shape.
    """
    delta = jnp.asarray(tip_deflection_m, dtype=float)
    return project_shape(whisker.beta, whisker.mu, lambda xi: delta * xi**2 * (3 - xi) / 2)


def tap(whisker: Whisker, impulse_ns: ScalarLike) -> PerMode:
    """Modal velocities after an impulse ``P`` (N·s) at the tip: ``P φ_i(l) / m_i``."""
    from ._modes import modal_mass_ratio

    beta = whisker.beta
    modal_mass = whisker.rho_a * whisker.length_m * modal_mass_ratio(beta, whisker.mu)
    return jnp.asarray(impulse_ns, dtype=float) * mode_shape(beta, 1.0) / modal_mass


def project_initial_shape(whisker: Whisker, shape_fn) -> PerMode:
    """Modal coordinates of any initial shape ``w₀(ξ)`` given as a function of ``ξ = x/l``."""
    return project_shape(whisker.beta, whisker.mu, shape_fn)


def _harmonic_coefficients(params: ModalParams, omega_b, h_b):
    """``q_ss = K (a sin ω_b t − b cos ω_b t)`` per mode."""
    omega, zeta, gamma = params
    a = omega**2 - omega_b**2
    b = 2 * zeta * omega * omega_b
    k = gamma * h_b * omega_b**2 / (a**2 + b**2)
    return k, a, b


def harmonic_steady_state(
    whisker: Whisker, t: Times, *, fb_hz: ScalarLike, hb_m: ScalarLike
) -> ModalState:
    """Steady-state response to ``y_b = h_b sin(2π f_b t)`` (closed form)."""
    params = modal_params(whisker)
    omega_b = 2 * jnp.pi * jnp.asarray(fb_hz, dtype=float)
    h_b = jnp.asarray(hb_m, dtype=float)
    k, a, b = _harmonic_coefficients(params, omega_b, h_b)
    t2 = jnp.asarray(t)[:, None]
    s, c = jnp.sin(omega_b * t2), jnp.cos(omega_b * t2)
    q = k * (a * s - b * c)
    qd = k * omega_b * (a * c + b * s)
    phase = omega_b * jnp.asarray(t)
    base_acc = -h_b * omega_b**2 * jnp.sin(phase)
    base_jerk = -h_b * omega_b**3 * jnp.cos(phase)
    return ModalState(q, qd, -(omega_b**2) * q, base_acc, base_jerk, -(omega_b**2) * base_acc)


def harmonic_from_rest(
    whisker: Whisker, t: Times, *, fb_hz: ScalarLike, hb_m: ScalarLike
) -> ModalState:
    """Full response to ``y_b = h_b sin(2π f_b t)`` switched on at ``t = 0`` from rest.

    Steady state plus the free transient that cancels its initial displacement and velocity.
    """
    params = modal_params(whisker)
    omega_b = 2 * jnp.pi * jnp.asarray(fb_hz, dtype=float)
    k, a, b = _harmonic_coefficients(params, omega_b, jnp.asarray(hb_m, dtype=float))
    steady = harmonic_steady_state(whisker, t, fb_hz=fb_hz, hb_m=hb_m)
    q, qd, qdd = _free(params, t, k * b, -k * omega_b * a)
    return steady._replace(q=steady.q + q, qd=steady.qd + qd, qdd=steady.qdd + qdd)


def base_motion_response(
    whisker: Whisker, t: Times, base_acc: Samples, *, uniform: bool = False
) -> ModalState:
    """Response from rest to a sampled base acceleration ``ÿ_b(t_k)`` (m/s²).

    The input is taken as piecewise linear between samples; for such an input the
    per-step update is exact: with ``u(s) = u_k + (u_{k+1} − u_k) s/h``, a particular
    solution is ``q_p(s) = c₀ + c₁ s`` (``c₁ = b/ω²``, ``c₀ = a/ω² − 2ζ b/ω³``), so
    ``x_{k+1} = Φ(h) (x_k − x_p(0)) + x_p(h)`` with the closed-form transition matrix
    ``Φ(h) = e^{A h}``. ``t`` must increase; the response is zero at ``t[0]``.

    Args:
        whisker: The whisker.
        t: Sample times (s); steps may differ (non-uniform timestamps).
        base_acc: Base acceleration at ``t`` (m/s²).
        uniform: Promise that the steps are all equal to ``t[1] − t[0]``: the transition is
            then computed once instead of at every step (about 3× faster).
    """
    omega, zeta, gamma = modal_params(whisker)
    t = jnp.asarray(t, dtype=float)
    u = -jnp.asarray(base_acc, dtype=float)[:, None] * gamma  # modal forcing, (samples, modes)
    h_all = jnp.diff(t)

    def step(carry, inputs):
        q, qd = carry
        h, u0, u1 = inputs
        phi = fixed if uniform else _transition(omega, zeta, h)
        slope = (u1 - u0) / h
        c1 = slope / omega**2
        c0 = u0 / omega**2 - 2 * zeta * slope / omega**3
        dq, dv = q - c0, qd - c1
        q_new = phi[0] * dq + phi[1] * dv + c0 + c1 * h
        qd_new = phi[2] * dq + phi[3] * dv + c1
        return (q_new, qd_new), (q_new, qd_new)

    if uniform:
        h_all = jnp.full_like(h_all, t[1] - t[0])
        fixed = _transition(omega, zeta, h_all[0])
    zeros = jnp.zeros_like(omega)
    _, (q, qd) = jax.lax.scan(step, (zeros, zeros), (h_all, u[:-1], u[1:]))
    q = jnp.concatenate([zeros[None], q])
    qd = jnp.concatenate([zeros[None], qd])
    qdd = u - 2 * zeta * omega * qd - omega**2 * q
    acc = jnp.asarray(base_acc, dtype=float)
    jerk = _derivative(t, acc)
    return ModalState(q, qd, qdd, acc, jerk, _derivative(t, jerk))


def _transition(omega, zeta, h):
    """Entries ``(Φ₁₁, Φ₁₂, Φ₂₁, Φ₂₂)`` of ``e^{A h}`` for ``q̈ + 2ζωq̇ + ω²q = 0``."""
    wd = _damped(omega, zeta)
    e = jnp.exp(-zeta * omega * h)
    c, s = jnp.cos(wd * h), jnp.sin(wd * h)
    k = zeta * omega / wd
    return e * (c + k * s), e * s / wd, -e * omega**2 / wd * s, e * (c - k * s)


def _derivative(t, y):
    """Second-order finite differences on a (possibly non-uniform) grid."""
    return jnp.gradient(y, t)
