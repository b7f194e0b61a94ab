"""The contact simulator against solutions not written with its code: the linear modal
simulator (tip lifted off), the frequency response of the linear system with a tip spring
(permanent contact, no friction), and an event-based SciPy integration (intermittent
Hunt–Crossley contact with smoothed friction)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from whiskerid.model import base_motion_response, modal_params, observe, paper_record
from whiskerid.model._modes import modal_mass_ratio, mode_shape
from whiskerid.terrain import ContactInputs, ContactParams, contact_modes, simulate_contact

DT = 5e-4
SIM = jax.jit(simulate_contact, static_argnames=("rtol", "atol"))


def _whisker(n_modes=3):
    return paper_record().whisker().with_modes(n_modes)


def _sine_inputs(t, h_b, f_b, ground=None, speed=0.2, dt=DT):
    w = 2 * np.pi * f_b
    base = np.stack([h_b * np.sin(w * t), h_b * w * np.cos(w * t), -h_b * w**2 * np.sin(w * t)])
    g = np.zeros((2, t.size)) if ground is None else ground
    return ContactInputs(t[0], dt, jnp.asarray(base), jnp.asarray(g), speed)


def test_lifted_tip_is_the_linear_simulator():
    """Out of contact (the ground 1 m below the tip) the sensor reads exactly what the
    linear modal simulator gives for the base motion across the tilted whisker
    (``ÿ_b cos θ``)."""
    w = _whisker(5)
    t = np.arange(0, 1.0, DT)
    inputs = _sine_inputs(t, 1e-4, 37.0)
    c = ContactParams(stiffness=1e4, preload=-1.0, friction=0.5, tilt_rad=-0.3)
    res = SIM(contact_modes(w), c, inputs, jnp.asarray(t), jnp.zeros(10))
    across = inputs.base[2] * np.cos(-0.3)
    ref = observe(w, base_motion_response(w, jnp.asarray(t), across, uniform=True))
    assert float(jnp.max(res.normal)) == 0.0
    err = float(jnp.max(jnp.abs(res.deflection - ref)) / jnp.max(jnp.abs(ref)))
    assert err < 1e-4


@pytest.mark.slow
def test_permanent_contact_without_friction_matches_frequency_response():
    """A linear penalty spring that never opens (large preload, no friction): the steady
    state at the drive frequency equals the complex frequency response of the modal
    equations with the tip spring, solved as a linear system."""
    w = _whisker(3)
    omega, zeta, gamma = (np.asarray(a) for a in modal_params(w))
    beta = w.beta
    mass = np.asarray(w.rho_a * w.length_m * modal_mass_ratio(beta, w.mu))
    phi_l = np.asarray(mode_shape(beta, 1.0))
    phi_s = np.asarray(mode_shape(beta, w.sensor_x_m / w.length_m))
    k, f_b, h_b, theta = 200.0, 31.0, 2e-4, -0.2
    wb = 2 * np.pi * f_b
    # M q̈ + C q̇ + K q = −m Γ ÿ_b cosθ + φ k (d₀ − y_b − φ·q cosθ) cosθ
    stiff = np.diag(mass * omega**2) + k * np.cos(theta) ** 2 * np.outer(phi_l, phi_l)
    damp = np.diag(2 * mass * zeta * omega)
    rhs = mass * gamma * wb**2 * h_b * np.cos(theta) - phi_l * k * np.cos(theta) * h_b
    q_hat = np.linalg.solve(stiff - wb**2 * np.diag(mass) + 1j * wb * damp, rhs)  # × sin(ω t)
    # inputs are linear between grid points: a sine loses (ωh)²/12 of its amplitude
    t = np.arange(0, 2.5, DT / 8)
    c = ContactParams(stiffness=k, exponent=1.0, preload=0.05, tilt_rad=theta)
    m = contact_modes(w)
    q_static = np.linalg.solve(stiff, phi_l * k * 0.05 * np.cos(theta))
    y0 = jnp.concatenate([jnp.asarray(q_static), jnp.zeros(3)])
    inputs = _sine_inputs(t, h_b, f_b, dt=DT / 8)
    res = SIM(m, c, inputs, jnp.asarray(t), y0, rtol=1e-8, atol=1e-13)
    assert float(jnp.min(res.normal)) > 0  # permanent contact
    late = t > 1.5
    q = np.asarray(res.state[late, :3]) - q_static
    basis = np.stack([np.sin(wb * t[late]), np.cos(wb * t[late])], axis=1)
    fit = np.linalg.lstsq(basis, q, rcond=None)[0]
    # q(t) = Im(q̂ e^{iωt}) = Re(q̂) sin ωt + Im(q̂) cos ωt
    measured = fit[0] + 1j * fit[1]
    assert abs(measured @ phi_s - q_hat @ phi_s) < 1e-4 * abs(q_hat @ phi_s)


def _scipy_reference(w, c, t_end, h_b, f_b, a_g, f_g, speed):
    """Event-based integration (DOP853, tight tolerances): a smooth free flight and a
    smooth contact phase, restarted at every touch-down and lift-off."""
    omega, zeta, gamma = (np.asarray(a) for a in modal_params(w))
    beta = w.beta
    mass = np.asarray(w.rho_a * w.length_m * modal_mass_ratio(beta, w.mu))
    phi_l = np.asarray(mode_shape(beta, 1.0))
    n = omega.size
    cos, sin = np.cos(c["theta"]), np.sin(c["theta"])
    wb, wg = 2 * np.pi * f_b, 2 * np.pi * f_g

    def gap(t, y, *_):  # penetration δ
        return c["d0"] + a_g * np.sin(wg * t) - h_b * np.sin(wb * t) - cos * (phi_l @ y[:n])

    def rhs(t, y, touching):
        q, qd = y[:n], y[n:]
        force = 0.0
        if touching:
            delta = gap(t, y)
            ddot = a_g * wg * np.cos(wg * t) - h_b * wb * np.cos(wb * t) - cos * (phi_l @ qd)
            normal = max(c["k"] * max(delta, 0.0) ** c["n"] * (1 + c["alpha"] * ddot), 0.0)
            slide = speed + sin * (phi_l @ qd)
            force = normal * cos - c["mu"] * normal * np.tanh(slide / c["vs"]) * sin
        acc = -h_b * wb**2 * np.sin(wb * t)
        qdd = -2 * zeta * omega * qd - omega**2 * q - gamma * acc * cos + phi_l * force / mass
        return np.concatenate([qd, qdd])

    def lift_off(t, y, *_):
        return gap(t, y)

    def touch_down(t, y, *_):
        return gap(t, y)

    lift_off.terminal = touch_down.terminal = True
    lift_off.direction, touch_down.direction = -1, 1  # no re-detection at a restart
    y, t0, touching, pieces, events = np.zeros(2 * n), 0.0, True, [], 0
    q_lift = np.zeros(n)
    y[:n] = q_lift
    while t0 < t_end:
        sol = solve_ivp(rhs, (t0, t_end), y, args=(touching,), method="DOP853", rtol=1e-10,
                        atol=1e-14, events=lift_off if touching else touch_down,
                        dense_output=True)  # fmt: skip
        pieces.append(sol)
        if sol.status != 1:
            break
        events += 1
        t0, y = sol.t_events[0][0], sol.y_events[0][0]
        touching = not touching
    return pieces, events


@pytest.mark.parametrize("friction", [pytest.param(0.0, marks=pytest.mark.slow), 0.6])
def test_intermittent_contact_matches_event_based_scipy(friction):
    """Hertz contact (n = 1.5) with Hunt–Crossley damping on a sinusoidal ground, a base
    shaken at 37 Hz: the tip loses and regains contact many times; the sensor deflection
    agrees with SciPy's event-based integration of the same equations (written here in
    NumPy) to 0.2 % of its range."""
    w = _whisker(3)
    par = {"k": 2e4, "n": 1.5, "alpha": 5.0, "mu": friction, "vs": 0.01, "d0": 2e-4,
           "theta": -0.3}  # fmt: skip
    h_b, f_b, a_g, f_g, speed, t_end = 3e-4, 37.0, 3e-4, 11.0, 0.2, 0.4
    pieces, events = _scipy_reference(w, par, t_end, h_b, f_b, a_g, f_g, speed)
    assert events >= 4  # the contact really is intermittent
    t = np.arange(0, t_end, DT / 4)
    wg = 2 * np.pi * f_g
    ground = np.stack([a_g * np.sin(wg * t), a_g * wg * np.cos(wg * t)])
    inputs = ContactInputs(t[0], DT / 4, jnp.asarray(
        _sine_inputs(t, h_b, f_b).base), jnp.asarray(ground), speed)  # fmt: skip
    c = ContactParams(stiffness=par["k"], exponent=par["n"], damping=par["alpha"],
                      friction=friction, slip_velocity=par["vs"], preload=par["d0"],
                      tilt_rad=par["theta"])  # fmt: skip
    m = contact_modes(w)
    res = SIM(m, c, inputs, jnp.asarray(t), jnp.zeros(6), rtol=1e-9, atol=1e-14)
    ref_q = np.concatenate([
        p.sol(t[(t >= p.t[0]) & (t <= p.t[-1]) & ~_covered(t, pieces[:i])])[:3].T
        for i, p in enumerate(pieces)
    ])  # fmt: skip
    phi_s = np.asarray(m.phi_sensor)
    ours = np.asarray(res.state[:, :3]) @ phi_s
    ref = ref_q @ phi_s
    assert ref.shape == ours.shape
    # the inputs are linear between grid points here, exact in SciPy: a small difference
    assert np.max(np.abs(ours - ref)) < 2e-3 * np.ptp(ref)


def _covered(t, pieces):
    out = np.zeros(t.shape, bool)
    for p in pieces:
        out |= (t >= p.t[0]) & (t <= p.t[-1])
    return out


def test_dataset_synth_contact_refuses_two_sensors(tmp_path, capsys):
    from whiskerid.cli import main

    args = ["dataset", "synth", "--out", str(tmp_path / "d"), "--contact", "--channels", "2"]
    assert main(args) == 2
    assert "--contact simulates one Hall sensor" in capsys.readouterr().err


@pytest.mark.slow
def test_contact_runs_are_the_linear_runs_with_the_tip_down(tmp_path):
    """Same seed, same run: the contact recording has the linear one's sample times (the
    same random draws), its own metadata, and a tip that touches the ground."""
    from whiskerid.terrain import RunSpec, iter_contact_runs, iter_runs

    spec = [RunSpec("brick", 0.2, 0)]
    (lin,) = iter_runs(spec, duration_s=2.0, seed=3)
    (con,) = iter_contact_runs(spec, duration_s=2.0, seed=3)
    np.testing.assert_array_equal(lin.t, con.t)
    assert con.meta["source"] == "whiskerid contact simulator"
    assert abs(float(con.meta["perturbation_hz"]) - 48 * 0.2 / (2 * np.pi * 0.035)) < 3
    assert 0.3 < float(con.meta["contact_fraction"]) <= 1.0
    assert np.std(con.columns["adc"]) > 3 * np.std(lin.columns["adc"])


@pytest.mark.slow
def test_gradient_through_the_contact_matches_finite_differences():
    """The simulation is differentiable in the contact parameters (smoothed friction, a
    force continuous at touch-down): d(mean square deflection)/d(log k, μ, d₀) by reverse
    mode through diffrax agrees with central differences."""
    w = _whisker(2)
    m = contact_modes(w)
    t = np.arange(0, 0.3, DT)
    wg = 2 * np.pi * 9.0
    ground = jnp.asarray(np.stack([3e-4 * np.sin(wg * t), 3e-4 * wg * np.cos(wg * t)]))
    inputs = ContactInputs(t[0], DT, _sine_inputs(t, 2e-4, 37.0).base, ground, 0.2)

    def loss(theta):
        c = ContactParams(stiffness=jnp.exp(theta[0]), exponent=1.5, damping=5.0,
                          friction=theta[1], preload=theta[2], tilt_rad=-0.4)  # fmt: skip
        res = simulate_contact(m, c, inputs, jnp.asarray(t), jnp.zeros(4), rtol=1e-9,
                               atol=1e-14)  # fmt: skip
        return jnp.mean((res.deflection * 1e6) ** 2)

    theta = jnp.array([np.log(2e4), 0.6, 2e-4])
    grad = jax.jit(jax.grad(loss))(theta)
    f = jax.jit(loss)
    for i, h in enumerate((1e-3, 1e-3, 1e-7)):
        e = jnp.zeros(3).at[i].set(h)
        fd = (f(theta + e) - f(theta - e)) / (2 * h)
        assert abs(float(fd)) * (1.0, 1.0, 2e-4)[i] > 0.5  # each parameter matters (loss ≈ 10)
        assert abs(float(grad[i]) - float(fd)) < 2e-3 * abs(float(fd))
