"""The whisker's tip against a moving ground: unilateral contact with friction (diffrax).

The linear terrain simulator moves only the whisker's base; its tip never touches
anything. Here the tip rests on the ground the robot drives over, pressed into it by a
preload, so that it can lose contact, bounce, and stick or slip. Geometry, in the vertical
plane of the robot's travel (``x`` forward, ``y`` up):

* the whisker's axis makes an angle ``θ`` (``tilt_rad``) with the horizontal; its bending
  deflection ``w`` is along ``e_n = (sin θ, cos θ)``. ``θ < 0`` is a whisker trailing
  backward-down (a tip that is dragged), ``θ > 0`` one pointing forward-down (a tip that
  is pushed, which jams when ``tan θ > 1/μ``), ``θ = 0`` the paper's horizontal whisker;
* the base moves vertically with the body, ``y_b(t)``; the ground under the tip has height
  ``z(t)`` (the profile at the tip's position ``x = v t + const``);
* the penetration of the tip into the ground is
  ``δ = d₀ + z − y_b − w_tip cos θ`` (``d₀``, the preload: how far the undeformed whisker's
  tip would sink into the mean ground);
* normal force, Hunt–Crossley (``n = 1`` a linear penalty spring with damping):
  ``N = max(k δ₊ⁿ (1 + α δ̇), 0)``: no adhesion, no force out of contact, and a damping
  that vanishes with the penetration, so that the force is continuous at touch-down;
* friction, smoothed Coulomb: the tip slides forward over the ground at
  ``u = v + ẇ_tip sin θ``; the ground's force on it is ``T = −μ N tanh(u/v_s)``
  (horizontal). ``v_s`` is a regularisation velocity: below it, sticking is a steep creep
  of slope ``μN/v_s`` (a stick phase), which keeps the model differentiable;
* the generalised force on the bending coordinate is ``Q = N cos θ + T sin θ`` (the axial
  component does not bend a linear beam).

Each mode ``i`` (mass-normalised as in :mod:`whiskerid.model`, modal mass ``m_i``) obeys

    q̈_i + 2ζ_iω_i q̇_i + ω_i² q_i = −Γ_i ÿ_b cos θ + φ_i(l) Q / m_i,

integrated by diffrax (an adaptive Runge–Kutta method, Tsit5, by default; its steps are
capped at the input grid's spacing so that no texture feature is stepped over). The
sensor reads ``Σ φ_i(x_s) q_i`` plus the quasi-static response of the truncated modes to
both the base acceleration and the tip force (``R_F(x) = x²(3l − x)/(6EI) −
Σ φ_i(x)φ_i(l)/(m_iω_i²)``, the mode-acceleration correction of :func:`observe`).

Amplitude-dependent modes: the modal restoring force is
:meth:`ContactModes.restoring` (linear, ``2ζωq̇ + ω²q``); a nonlinear modal model plugs
in by subclassing :class:`ContactModes` and overriding it (e.g. ``ω²(q + γq³)``).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._custom_types import PerMode, Scalar, Times
from ..model import Whisker, modal_params
from ..model._modes import modal_mass_ratio, mode_shape
from ..model._response import residual_flexibility


def _scalar(x) -> jax.Array:
    return jnp.asarray(x, dtype=float).reshape(())


class ContactParams(eqx.Module):
    """Contact of the whisker's tip with one ground (all SI).

    Attributes:
        stiffness: ``k`` in ``N = k δⁿ (1 + α δ̇)`` (N/mⁿ).
        exponent: ``n``: 1 for a linear penalty spring (compliant ground), 1.5 for a
            Hertz contact (a rounded elastic tip on a hard ground).
        damping: Hunt–Crossley ``α`` (s/m): ``1 − e ≈ 2αv_i/3`` for a restitution ``e`` at
            an impact speed ``v_i``.
        friction: Coulomb coefficient ``μ``.
        slip_velocity: ``v_s`` of ``tanh(u/v_s)`` (m/s).
        preload: ``d₀``: how far the undeformed tip would sink into the mean ground (m);
            the static contact force follows from it and the whisker's stiffness.
        tilt_rad: ``θ``, the whisker's angle below the horizontal; negative: trailing.
    """

    stiffness: Scalar = eqx.field(converter=_scalar)
    exponent: Scalar = eqx.field(converter=_scalar, default=1.0)
    damping: Scalar = eqx.field(converter=_scalar, default=0.0)
    friction: Scalar = eqx.field(converter=_scalar, default=0.0)
    slip_velocity: Scalar = eqx.field(converter=_scalar, default=0.01)
    preload: Scalar = eqx.field(converter=_scalar, default=0.001)
    tilt_rad: Scalar = eqx.field(converter=_scalar, default=0.0)

    def __check_init__(self):
        names = ("stiffness", "exponent", "damping", "friction", "slip_velocity", "preload",
                 "tilt_rad")  # fmt: skip
        values = {k: getattr(self, k) for k in names}
        if any(isinstance(v, jax.core.Tracer) for v in values.values()):
            return
        v = {k: float(x) for k, x in values.items()}
        if not (v["stiffness"] >= 0 and 1 <= v["exponent"] <= 2 and v["damping"] >= 0
                and v["friction"] >= 0 and v["slip_velocity"] > 0
                and abs(v["tilt_rad"]) < np.pi / 2):  # fmt: skip
            raise ValueError(
                f"contact parameters out of range: {v} (need k >= 0, 1 <= n <= 2, α >= 0, "
                "μ >= 0, v_s > 0, |θ| < π/2)"
            )
        if np.sin(v["tilt_rad"]) * v["friction"] >= np.cos(v["tilt_rad"]):
            raise ValueError(
                f"tan θ = {np.tan(v['tilt_rad']):.3g} >= 1/μ = "
                f"{1 / max(v['friction'], 1e-30):.3g}: "
                "a whisker pushed forward at this angle jams into the ground (self-locking); "
                "tilt it less, or backward (θ < 0)"
            )

    def normal_force(self, delta, delta_dot):
        """``N`` (N) for a penetration ``δ`` (m) and its rate (m/s)."""
        pen = jnp.maximum(delta, 0.0)
        # δ₊ⁿ with a zero gradient out of contact (a bare power has a NaN gradient at 0)
        safe = jnp.where(pen > 0, pen, 1.0)
        spring = jnp.where(pen > 0, safe**self.exponent, 0.0) * self.stiffness
        return jnp.maximum(spring * (1.0 + self.damping * delta_dot), 0.0)


class ContactModes(eqx.Module):
    """What the contact simulation needs of a whisker's modes.

    Attributes:
        omega: ``ω_i`` (rad/s).
        zeta: ``ζ_i``.
        gamma: Participation factors ``Γ_i``.
        phi_tip: ``φ_i(l)``.
        phi_sensor: ``φ_i(x_s)``.
        modal_mass: ``m_i`` (kg).
        residual_acc: Quasi-static sensor deflection per unit base acceleration of the
            truncated modes (m per m/s²).
        residual_force: The same per unit tip force (m/N).
    """

    omega: PerMode
    zeta: PerMode
    gamma: PerMode
    phi_tip: PerMode
    phi_sensor: PerMode
    modal_mass: PerMode
    residual_acc: Scalar
    residual_force: Scalar

    def restoring(self, q: PerMode, qd: PerMode) -> PerMode:
        """Modal restoring acceleration (linear: ``2ζωq̇ + ω²q``). Override for
        amplitude-dependent modes."""
        return 2 * self.zeta * self.omega * qd + self.omega**2 * q

    @property
    def tip_flexibility(self) -> Scalar:
        """Static tip deflection per unit tip force of the modes kept (m/N)."""
        return jnp.sum(self.phi_tip**2 / (self.modal_mass * self.omega**2))


def contact_modes(whisker: Whisker) -> ContactModes:
    """The :class:`ContactModes` of a (linear) whisker."""
    omega, zeta, gamma = modal_params(whisker)
    beta, l, xs = whisker.beta, whisker.length_m, whisker.sensor_x_m
    mass = whisker.rho_a * l * modal_mass_ratio(beta, whisker.mu)
    phi_tip, phi_s = mode_shape(beta, 1.0), mode_shape(beta, xs / l)
    static_force = xs**2 * (3 * l - xs) / (6 * whisker.EI)
    r_force = static_force - jnp.sum(phi_s * phi_tip / (mass * omega**2))
    return ContactModes(omega, zeta, gamma, phi_tip, phi_s, mass,
                        residual_flexibility(whisker, xs), r_force)  # fmt: skip


class ContactInputs(eqx.Module):
    """The motion the whisker sees, on a uniform time grid.

    Attributes:
        t0: First grid time (s).
        dt: Grid spacing (s).
        base: Base height ``y_b`` (m), velocity (m/s) and acceleration (m/s²),
            shape ``(3, n)``.
        ground: Ground height under the tip ``z`` (m) and its rate (m/s), shape ``(2, n)``.
        speed: Robot speed ``v`` (m/s).
    """

    t0: Scalar
    dt: Scalar
    base: Float[Array, "3 n"]
    ground: Float[Array, "2 n"]
    speed: Scalar

    def at(self, t):
        """Inputs at time ``t``, linear between grid points: ``(y_b, ẏ_b, ÿ_b, z, ż)``."""
        s = (t - self.t0) / self.dt
        n = self.base.shape[1]
        k = jnp.clip(jnp.floor(s), 0, n - 2).astype(int)
        f = s - k
        both = jnp.concatenate([self.base, self.ground])
        return both[:, k] * (1 - f) + both[:, k + 1] * f


def _kinematics(modes: ContactModes, c: ContactParams, y, inputs):
    """Normal force, friction and generalised tip force for a state and inputs."""
    n = modes.omega.shape[0]
    q, qd = y[..., :n], y[..., n:]
    yb, ybd, _, z, zd = inputs
    cos, sin = jnp.cos(c.tilt_rad), jnp.sin(c.tilt_rad)
    w_tip, wd_tip = q @ modes.phi_tip, qd @ modes.phi_tip
    delta = c.preload + z - yb - w_tip * cos
    delta_dot = zd - ybd - wd_tip * cos
    return c.normal_force(delta, delta_dot), delta, w_tip, wd_tip, cos, sin


def _tip_force(modes: ContactModes, c: ContactParams, y, inputs, speed):
    """``(Q, N, u)``: generalised tip force (N), normal force (N), sliding velocity (m/s)."""
    normal, _, _, wd_tip, cos, sin = _kinematics(modes, c, y, inputs)
    slide = speed + wd_tip * sin
    friction = -c.friction * normal * jnp.tanh(slide / c.slip_velocity)
    return normal * cos + friction * sin, normal, slide


def _vector_field(t, y, args):
    modes, c, inputs = args
    n = modes.omega.shape[0]
    q, qd = y[:n], y[n:]
    now = inputs.at(t)
    force, _, _ = _tip_force(modes, c, y, now, inputs.speed)
    qdd = (-modes.restoring(q, qd) - modes.gamma * now[2] * jnp.cos(c.tilt_rad)
           + modes.phi_tip * force / modes.modal_mass)  # fmt: skip
    return jnp.concatenate([qd, qdd])


class ContactResult(eqx.Module):
    """The contact simulation on the output grid.

    Attributes:
        t: Output times (s).
        deflection: Relative deflection at the sensor (m), static correction included.
        normal: Normal force (N).
        slide: Sliding velocity of the tip over the ground (m/s).
        state: Modal displacements and velocities, shape ``(n, 2 × modes)``.
        steps: Solver steps taken.
    """

    t: Times
    deflection: Float[Array, " n"]
    normal: Float[Array, " n"]
    slide: Float[Array, " n"]
    state: Float[Array, "n states"]
    steps: Array


def static_state(modes: ContactModes, c: ContactParams, speed: float) -> np.ndarray:
    """Static equilibrium of the whisker pressed on the mean ground while sliding at
    ``speed``: the modal state ``(q, 0)`` (host-side bisection on the penetration)."""
    cos, sin = float(np.cos(c.tilt_rad)), float(np.sin(c.tilt_rad))
    lever = cos - float(c.friction) * sin * float(np.tanh(speed / float(c.slip_velocity)))
    flex = float(modes.tip_flexibility)
    k, n, d0 = float(c.stiffness), float(c.exponent), float(c.preload)
    lo, hi = 0.0, max(d0, 0.0)
    for _ in range(80):  # g(δ) = δ − d₀ + cos·flex·lever·k δⁿ is increasing in δ
        mid = 0.5 * (lo + hi)
        g = mid - d0 + cos * flex * lever * k * mid**n
        lo, hi = (mid, hi) if g < 0 else (lo, mid)
    force = k * lo**n * lever
    q = np.asarray(modes.phi_tip / (modes.modal_mass * modes.omega**2)) * force
    return np.concatenate([q, np.zeros_like(q)])


def simulate_contact(
    modes: ContactModes,
    contact: ContactParams,
    inputs: ContactInputs,
    t_out: Times,
    y0: Float[Array, " states"],
    *,
    rtol: float = 1e-6,
    atol: float = 1e-10,
    max_steps: int = 2_000_000,
    solver=None,
    fixed_step: bool = False,
    adjoint=None,
) -> ContactResult:
    """Integrate the whisker with its tip on the ground from ``t_out[0]`` to ``t_out[-1]``.

    Traceable (jit, vmap and grad with respect to the contact parameters). Steps adapt
    (PID control on ``rtol``/``atol``, in metres and m/s of the modal coordinates) and are
    at most the input grid's spacing.

    Args:
        modes: The whisker's modes (:func:`contact_modes`).
        contact: The contact parameters.
        inputs: Base and ground motion on a uniform grid covering ``t_out``.
        t_out: Output times (s), increasing.
        y0: Modal state ``(q, q̇)`` at ``t_out[0]`` (e.g. :func:`static_state`).
        rtol: Relative tolerance.
        atol: Absolute tolerance.
        max_steps: Step budget.
        solver: A diffrax solver instance; ``diffrax.Tsit5()`` by default (an implicit
            one, e.g. ``diffrax.Kvaerno5()``, for very stiff contacts).
        fixed_step: Step from each output time to the next instead (``t_out`` uniform; no
            error control: cheap and smooth in the parameters, for fits whose contact is
            soft enough for the grid; ``rtol``, ``atol`` and ``max_steps`` are unused).
        adjoint: A diffrax adjoint; ``diffrax.ForwardMode()`` for forward-mode
            derivatives (``jax.jvp``/``jacfwd``); reverse mode by default.
    """
    import diffrax  # here: importing the terrain package does not load diffrax

    if fixed_step:  # the steps are the output times: save them, not an interpolation
        controller, dt0 = diffrax.ConstantStepSize(), (t_out[-1] - t_out[0]) / (len(t_out) - 1)
        saveat, max_steps = diffrax.SaveAt(t0=True, steps=True), len(t_out) - 1
    else:
        controller = diffrax.PIDController(rtol=rtol, atol=atol, dtmax=inputs.dt)
        dt0, saveat = inputs.dt / 4, diffrax.SaveAt(ts=t_out)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_vector_field),
        diffrax.Tsit5() if solver is None else solver,
        t0=t_out[0],
        t1=t_out[-1],
        dt0=dt0,
        y0=y0,
        args=(modes, contact, inputs),
        saveat=saveat,
        stepsize_controller=controller,
        max_steps=max_steps,
        **({} if adjoint is None else {"adjoint": adjoint}),
    )
    ys = sol.ys
    now = jax.vmap(inputs.at)(t_out).T
    force, normal, slide = jax.vmap(lambda y, u: _tip_force(modes, contact, y, u, inputs.speed))(
        ys, now.T
    )
    n = modes.omega.shape[0]
    acc_perp = now[2] * jnp.cos(contact.tilt_rad)
    deflection = (ys[:, :n] @ modes.phi_sensor - modes.residual_acc * acc_perp
                  + modes.residual_force * force)  # fmt: skip
    return ContactResult(t_out, deflection, normal, slide, ys, sol.stats["num_steps"])
