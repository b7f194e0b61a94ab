"""A weakly nonlinear mode: cubic stiffness and amplitude-dependent damping.

Real whiskers and beams are stiffer and lose energy differently at large amplitude: the
frequency of a free decay drifts as it dies out and its damping ratio is not one number. One
mode, its deflection ``u`` (m, at the point where it is read), obeys

    u'' + 2ζ₀ω₀u' + ω₀²(u + κu|u| + γu³) + c|u'|u' + F sgn(u') = −b(t)

with ``ω₀ = 2πf₀`` the small-amplitude natural frequency, ``ζ₀`` its viscous damping ratio,
``κ`` (1/m) a stiffness change linear in the amplitude (the odd quadratic ``u|u|``: a
clamp that slips a little, or a contact that closes, at every deflection), ``γ`` (1/m²) a
cubic (Duffing) stiffness, ``c`` (1/m) a velocity-squared (aerodynamic or material) loss,
``F`` (m/s²) dry (Coulomb) friction and ``b`` the base acceleration.

**Harmonic balance.** With ``u ≈ a cos ψ`` the restoring force's first harmonic is
``ω₀²a(1 + 8κa/(3π) + 3γa²/4) cos ψ`` (``(1/π)∫cos²ψ|cos ψ|dψ = 8/(3π)`` over a period,
``(1/π)∫cos⁴ψ dψ = 3/4``), so to first order the backbone is
``ω(a) = ω₀(1 + 4κa/(3π) + 3γa²/8)``: a frequency shift linear in ``a`` (``κ``) or
quadratic (``γ``); ``κ < 0`` softens. A loss term is replaced by the viscous damping that
dissipates the same energy per cycle (equivalent linearisation):

* velocity-squared: ``ζ_eq = 4c·a·ω/(3πω₀)`` (grows with ``a``);
* Coulomb: ``ζ_eq = 2F/(πω₀²a)·(ω₀/ω)`` (grows as ``1/a``: it dominates late in a decay,
  and the envelope then ends in finite time).

So ``ζ(a) = ζ₀ + ζ_eq`` is a curve, and ``a → 0`` gives the linear ``f₀`` and ``ζ₀``.

**Slow flow.** Averaging (Krylov–Bogoliubov) over a cycle gives the envelope and phase of a
free decay: ``da/dt = −ζ(a)ω₀a``, ``dφ/dt = ω(a)√(1−ζ₀²)`` (the last factor makes it exactly
the linear model's ``e^{−ζ₀ω₀t}cos(ω_d t)`` when the nonlinear terms vanish). It is integrated
by a classical Runge–Kutta step between consecutive samples (:func:`slow_flow`): the envelope
changes by ``ζω₀Δt`` per sample, a few per cent, so the fourth-order step is exact to
rounding. This is the cheap form the calibration fits.

**The ODE** itself is integrated with diffrax (:func:`nonlinear_response`; Tsit5 with an
adaptive step, differentiable), for checks of the slow flow and for forced (base) motion.
The Coulomb term is smoothed there as ``F tanh(u'/v_s)`` to stay differentiable.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._custom_types import Scalar

#: The stored nonlinear coefficients (tip amplitude), as :class:`NonlinearMode` names them.
COEFFICIENTS = ("gamma_per_m2", "quadratic_per_m", "coulomb_m_s2", "kappa_per_m")


def _scalar(x) -> Array:
    return jnp.asarray(x, dtype=float)


class NonlinearMode(eqx.Module):
    """One weakly nonlinear mode (see the module docstring for the equation).

    Attributes:
        f0_hz: Small-amplitude natural frequency ``f₀`` (Hz).
        zeta0: Viscous (small-amplitude) damping ratio ``ζ₀``.
        gamma_per_m2: Cubic stiffness ``γ`` (1/m²); > 0 stiffening, < 0 softening.
        quadratic_per_m: Velocity-squared damping ``c`` (1/m).
        coulomb_m_s2: Dry friction ``F`` (m/s², force per modal mass).
        kappa_per_m: Amplitude-linear stiffness ``κ`` (1/m) of ``u|u|``; < 0 softening.
    """

    f0_hz: Scalar = eqx.field(converter=_scalar)
    zeta0: Scalar = eqx.field(converter=_scalar)
    gamma_per_m2: Scalar = eqx.field(converter=_scalar, default=0.0)
    quadratic_per_m: Scalar = eqx.field(converter=_scalar, default=0.0)
    coulomb_m_s2: Scalar = eqx.field(converter=_scalar, default=0.0)
    kappa_per_m: Scalar = eqx.field(converter=_scalar, default=0.0)

    def __check_init__(self):
        for name in ("f0_hz", "zeta0", "gamma_per_m2", "quadratic_per_m", "coulomb_m_s2",
                     "kappa_per_m"):  # fmt: skip
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(f"NonlinearMode.{name} must be a scalar")

    @property
    def omega0(self) -> Scalar:
        """``ω₀ = 2πf₀`` (rad/s)."""
        return 2 * jnp.pi * self.f0_hz

    def omega(self, a: ArrayLike) -> Array:
        """Backbone ``ω(a) = ω₀(1 + 4κa/(3π) + 3γa²/8)`` (rad/s) at amplitude ``a`` (m)."""
        a = jnp.asarray(a)
        shift = 4 * self.kappa_per_m * a / (3 * jnp.pi) + 0.375 * self.gamma_per_m2 * a**2
        return self.omega0 * (1.0 + shift)

    def frequency_hz(self, a: ArrayLike) -> Array:
        """Backbone frequency ``f(a)`` (Hz), undamped."""
        return self.omega(a) / (2 * jnp.pi)

    def zeta(self, a: ArrayLike) -> Array:
        """Equivalent damping ratio ``ζ(a)`` at amplitude ``a`` (m); ``ζ₀`` at ``a → 0``
        without friction (with it, ζ grows without bound as ``a → 0``)."""
        a = jnp.asarray(a)
        ratio = self.omega(a) / self.omega0
        safe_a = jnp.where(a > 0, a, 1.0)
        coulomb = jnp.where(
            a > 0, 2 * self.coulomb_m_s2 / (jnp.pi * self.omega0**2 * safe_a) / ratio, jnp.inf
        )
        coulomb = jnp.where(self.coulomb_m_s2 == 0, 0.0, coulomb)
        return self.zeta0 + 4 * self.quadratic_per_m * a * ratio / (3 * jnp.pi) + coulomb

    def decay_rate(self, a: ArrayLike) -> Array:
        """``da/dt = −ζ(a)ω₀a`` written without the ``1/a`` of friction (finite at 0)."""
        a = jnp.asarray(a)
        ratio = self.omega(a) / self.omega0
        w0 = self.omega0
        viscous = self.zeta0 * w0 * a
        quadratic = 4 * self.quadratic_per_m * ratio * w0 * a**2 / (3 * jnp.pi)
        friction = 2 * self.coulomb_m_s2 / (jnp.pi * w0 * ratio)
        return -(viscous + quadratic + jnp.where(a > 0, friction, 0.0))


def _slow_rhs(mode: NonlinearMode, a):
    damped = jnp.sqrt(1.0 - mode.zeta0**2)
    return mode.decay_rate(a), mode.omega(a) * damped


@jax.jit
def slow_flow(
    mode: NonlinearMode, t: Float[Array, " n"], a0: ArrayLike, phi0: ArrayLike = 0.0
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Envelope ``a(t)`` and phase ``φ(t)`` of a free decay by the averaged equations.

    ``u(t) ≈ a(t) cos φ(t)``. One Runge–Kutta (4th order) step between consecutive samples,
    which may be unevenly spaced; the envelope is clamped at 0 (friction stops a decay in
    finite time).

    Args:
        mode: The mode.
        t: Sample times (s), increasing; the decay starts at ``t[0]``.
        a0: Amplitude at ``t[0]`` (m).
        phi0: Phase at ``t[0]`` (rad).

    Returns:
        ``(a, φ)`` at ``t``.
    """
    t = jnp.asarray(t, dtype=float)
    dts = jnp.diff(t)

    def step(state, dt):
        a, phi = state
        k1a, k1p = _slow_rhs(mode, a)
        k2a, k2p = _slow_rhs(mode, jnp.maximum(a + 0.5 * dt * k1a, 0.0))
        k3a, k3p = _slow_rhs(mode, jnp.maximum(a + 0.5 * dt * k2a, 0.0))
        k4a, k4p = _slow_rhs(mode, jnp.maximum(a + dt * k3a, 0.0))
        a_new = jnp.maximum(a + dt * (k1a + 2 * k2a + 2 * k3a + k4a) / 6, 0.0)
        phi_new = phi + dt * (k1p + 2 * k2p + 2 * k3p + k4p) / 6
        return (a_new, phi_new), (a_new, phi_new)

    start = (jnp.asarray(a0, dtype=float), jnp.asarray(phi0, dtype=float))
    _, (a, phi) = jax.lax.scan(step, start, dts)
    return jnp.concatenate([start[0][None], a]), jnp.concatenate([start[1][None], phi])


def slow_flow_decay(mode: NonlinearMode, t, a0, phi0=0.0) -> Array:
    """The free decay ``u(t) ≈ a(t) cos φ(t)`` (m) by :func:`slow_flow`."""
    a, phi = slow_flow(mode, t, a0, phi0)
    return a * jnp.cos(phi)


@eqx.filter_jit
def nonlinear_response(
    mode: NonlinearMode,
    t: Float[Array, " n"],
    u0: ArrayLike,
    v0: ArrayLike = 0.0,
    *,
    base_acc: Float[Array, " n"] | None = None,
    friction_velocity_m_s: float = 1e-6,
    rtol: float = 1e-9,
    atol: float = 1e-12,
    max_steps: int = 1_000_000,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Integrate the mode's ODE with diffrax (Tsit5, adaptive, differentiable).

    Args:
        mode: The mode.
        t: Output times (s), increasing; the state ``(u0, v0)`` is at ``t[0]``.
        u0: Initial deflection (m).
        v0: Initial velocity (m/s).
        base_acc: Base acceleration at ``t`` (m/s², times the mode's participation factor),
            interpolated linearly between samples; None for a free decay.
        friction_velocity_m_s: ``v_s`` of the smoothed friction ``F tanh(u'/v_s)``.
        rtol: Relative tolerance of the step controller.
        atol: Absolute tolerance (m, m/s).
        max_steps: Step limit.

    Returns:
        ``(u, u')`` at ``t``: the deflection relative to the base and its velocity.
    """
    import diffrax  # here: importing the model package (every calibration) does not load it

    t = jnp.asarray(t, dtype=float)
    w0 = mode.omega0
    drive = None if base_acc is None else diffrax.LinearInterpolation(t, jnp.asarray(base_acc))

    def rhs(s, y, args):
        u, v = y
        acc = -(
            2 * mode.zeta0 * w0 * v
            + w0**2 * (u + mode.kappa_per_m * u * jnp.abs(u) + mode.gamma_per_m2 * u**3)
            + mode.quadratic_per_m * jnp.abs(v) * v
            + mode.coulomb_m_s2 * jnp.tanh(v / friction_velocity_m_s)
        )
        if drive is not None:
            acc = acc - drive.evaluate(s)
        return v, acc

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs),
        diffrax.Tsit5(),
        t0=t[0],
        t1=t[-1],
        dt0=0.05 / (mode.f0_hz * 2 * jnp.pi),
        y0=(jnp.asarray(u0, dtype=float), jnp.asarray(v0, dtype=float)),
        saveat=diffrax.SaveAt(ts=t),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
    )
    return sol.ys


def nonlinear_coefficients(record) -> dict | None:
    """The nonlinear coefficients a calibration stored in ``record`` (``[fit.nonlinear]``:
    ``gamma_per_m2``, ``quadratic_per_m``, ``coulomb_m_s2``, ``kappa_per_m`` for mode 1's tip
    amplitude; a term not stored is 0; ``f0_hz``, mode 1's a → 0 frequency, where stored),
    or None for a linear record. A fit with free higher
    modes (``calibrate --free-modes``) adds ``free_f_hz`` and ``free_zeta``: modes 2…'s
    fitted frequencies (Hz) and damping ratios, from ``[fit.nonlinear.free_modes]``."""
    nl = (record.extra.get("fit") or {}).get("nonlinear")
    if not nl:
        return None
    if nl.get("backbone_model") == "log-polynomial":
        raise ValueError(
            "this record's backbone f(a), zeta(a) is an identified curve (a log-polynomial "
            "fit), which simulate cannot play: calibrate with the parametric nonlinear model"
        )
    out = {k: float(nl.get(k, 0.0)) for k in COEFFICIENTS}
    if "f0_hz" in nl:  # the a → 0 frequency (the record's κ is the linear fit's)
        out["f0_hz"] = float(nl["f0_hz"])
    free = nl.get("free_modes")
    if free:
        out["free_f_hz"] = tuple(float(f) for f in free["f_hz"])
        out["free_zeta"] = tuple(float(z) for z in free["zeta"])
    return out


def nonlinear_pluck_state(whisker, t: Float[Array, " n"], q0, coefficients: dict):
    """A pluck's modal state with mode 1 nonlinear (the ODE by diffrax), the others linear.

    The coefficients are for mode 1's *tip* deflection ``u = φ₁(l) q₁``; in the modal
    coordinate they become ``γφ₁(l)²``, ``κ|φ₁(l)|``, ``c|φ₁(l)|`` and ``F/|φ₁(l)|``.

    Args:
        whisker: The whisker (mode 1's ``ζ₀`` is its first mode's, and so is ``f₀`` unless
            the coefficients hold the fit's ``f0_hz``).
        t: Increasing times from the release (s).
        q0: Modal displacements at the release (:func:`whiskerid.model.pluck`).
        coefficients: As :func:`nonlinear_coefficients` (with ``free_f_hz``, ``free_zeta``:
            modes 2… ring at these, not at the beam's frequencies and ζ).

    Returns:
        A :class:`whiskerid.model.ModalState`.
    """
    from ._modes import mode_shape

    lin = _linear_modes(whisker, t, q0, coefficients)
    phi = jnp.abs(mode_shape(whisker.beta, 1.0)[0])
    mode = NonlinearMode(
        f0_hz=coefficients.get("f0_hz", whisker.natural_frequencies_hz[0]),
        zeta0=whisker.zeta[0],
        gamma_per_m2=coefficients["gamma_per_m2"] * phi**2,
        quadratic_per_m=coefficients["quadratic_per_m"] * phi,
        coulomb_m_s2=coefficients["coulomb_m_s2"] / phi,
        kappa_per_m=coefficients.get("kappa_per_m", 0.0) * phi,
    )
    u, v = nonlinear_response(mode, t, q0[0], 0.0)
    w0 = mode.omega0
    acc = -(
        2 * mode.zeta0 * w0 * v
        + w0**2 * (u + mode.kappa_per_m * u * jnp.abs(u) + mode.gamma_per_m2 * u**3)
        + mode.quadratic_per_m * jnp.abs(v) * v
        + mode.coulomb_m_s2 * jnp.tanh(v / 1e-6)
    )
    return lin._replace(
        q=lin.q.at[:, 0].set(u), qd=lin.qd.at[:, 0].set(v), qdd=lin.qdd.at[:, 0].set(acc)
    )


def _linear_modes(whisker, t, q0, coefficients: dict):
    """The pluck's linear modal state, modes 2… at the fit's free ``f_k``, ``ζ_k`` when the
    coefficients hold them (mode 1 is overwritten by the caller)."""
    from ._response import ModalParams, ModalState, _free, modal_params

    omega, zeta, gamma = modal_params(whisker)
    zeta = jnp.broadcast_to(jnp.asarray(zeta, dtype=float), omega.shape)
    f_free = jnp.asarray(coefficients.get("free_f_hz", ()), dtype=float)
    k = min(int(f_free.size), int(omega.size) - 1)  # the whisker may have fewer modes
    if k:
        omega = omega.at[1 : 1 + k].set(2 * jnp.pi * f_free[:k])
        zeta = zeta.at[1 : 1 + k].set(jnp.asarray(coefficients["free_zeta"], dtype=float)[:k])
    q, qd, qdd = _free(ModalParams(omega, zeta, gamma), t, q0, jnp.zeros_like(q0))
    zeros = jnp.zeros(jnp.shape(t))
    return ModalState(q, qd, qdd, zeros, zeros, zeros)
