"""Gradients of the responses with respect to EI, ζ, C (through ρa) and h_b."""

import jax
import jax.numpy as jnp
import pytest
from jax.test_util import check_grads

import whiskerid as wi

COIL = wi.paper_coil()
T = jnp.linspace(0.0, 0.08, 41)


def _whisker(p, tip_mass=0.0):
    """p = (EI scale, ζ, C scale): EI = s·G J, ρa = C ρ_w a (so d/dC is d/d(p[2]))."""
    return wi.Whisker(
        length_m=COIL.length_m,
        EI=COIL.EI * p[0],
        rho_a=COIL.coil_factor * p[2] * COIL.wire_density_kg_m3 * COIL.wire_area_m2,
        zeta=jnp.full(5, p[1]),
        tip_mass_kg=tip_mass,
        sensor_x_m=0.005,
    )


def _steady(p):
    w = _whisker(p)
    return wi.observe(w, wi.harmonic_steady_state(w, T, fb_hz=60.0, hb_m=p[3] * 1e-4)) * 1e6


def _from_rest(p):
    w = _whisker(p, tip_mass=0.002)  # the tip mass routes d/dC through the eigenvalues too
    return wi.observe(w, wi.harmonic_from_rest(w, T, fb_hz=60.0, hb_m=p[3] * 1e-4)) * 1e6


def _base(p):
    w = _whisker(p)
    t = jnp.linspace(0.0, 0.05, 501)
    acc = p[3] * 20.0 * jnp.sin(2 * jnp.pi * 70.0 * t)
    return wi.observe(w, wi.base_motion_response(w, t, acc), "acceleration", absolute=True)


def _decay(p):
    w = _whisker(p)
    return wi.observe(w, wi.free_decay(w, T, q0=wi.pluck(w, p[3] * 1e-3)), x_m=0.06) * 1e3


def _paper(p):
    return wi.paper_eq1(_whisker(p), T, fb_hz=100.0, hb_m=p[3] * 1e-4) * 1e6


@pytest.mark.parametrize(
    "fn",
    [
        _steady,
        pytest.param(_from_rest, marks=pytest.mark.slow),
        pytest.param(_base, marks=pytest.mark.slow),
        _decay,
        _paper,
    ],
)
def test_check_grads(fn):
    p = jnp.array([1.0, 0.04, 1.0, 1.0])
    check_grads(jax.jit(fn), (p,), order=1, modes=("fwd", "rev"), eps=1e-6, atol=1e-5, rtol=1e-5)


def test_only_kappa_matters_without_tip_mass():
    """Scaling EI and C together leaves the response unchanged (identifiability)."""
    a = _steady(jnp.array([1.0, 0.04, 1.0, 1.0]))
    b = _steady(jnp.array([2.0, 0.04, 2.0, 1.0]))
    assert float(jnp.max(jnp.abs(a - b))) < 1e-9 * float(jnp.max(jnp.abs(a)))
