"""The exact modal model against an independent finite-element beam and direct integration."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ALU, ALU_THEORY_F1, FEMBeam

import whiskerid as wi


@pytest.fixture(scope="module")
def paper_fem():
    w = wi.paper_whisker()
    return FEMBeam(length=0.06, EI=float(w.EI), rho_a=float(w.rho_a), zeta=0.04, n_el=40)


@jax.jit
def _amplitudes(w, freqs, x):
    """Steady-state amplitude of the relative deflection at x, one per frequency."""

    def one(f):
        t = jnp.linspace(0, 1, 256, endpoint=False) / f
        y = wi.observe(w, wi.harmonic_steady_state(w, t, fb_hz=f, hb_m=1e-4), x_m=x)
        return jnp.max(jnp.abs(y))

    return jax.vmap(one)(jnp.asarray(freqs))


def _amplitude(w, f, x):
    return float(_amplitudes(w, jnp.array([f]), x)[0])


@pytest.mark.parametrize("x", [0.005, 0.06])
def test_steady_amplitude_within_half_percent_1_to_500_hz(paper_fem, x):
    w = wi.paper_whisker()  # five modes, as the paper
    f1, f2 = (float(f) for f in w.natural_frequencies_hz[:2])
    freqs = np.unique(np.concatenate([np.geomspace(1, 500, 30), [f1, f2]]))
    fem = np.array([paper_fem.steady_amplitude(x, f, 1e-4) for f in freqs])
    ratio = np.asarray(_amplitudes(w, freqs, x)) / fem
    assert np.max(np.abs(ratio - 1)) < 0.005, (freqs[np.argmax(np.abs(ratio - 1))], ratio)


def test_static_correction_is_what_makes_five_modes_enough(paper_fem):
    """Without it the five-mode sum is off by > 5 % at x_s (slow convergence at the clamp)."""
    w = wi.paper_whisker()
    t = jnp.linspace(0, 1 / 500, 256, endpoint=False)
    bare = wi.observe(
        w, wi.harmonic_steady_state(w, t, fb_hz=500.0, hb_m=1e-4), static_correction=False
    )
    ratio = float(jnp.max(jnp.abs(bare))) / paper_fem.steady_amplitude(0.005, 500.0, 1e-4)
    assert abs(ratio - 1) > 0.05


def test_resonance_peak_at_f1(paper_fem):
    w = wi.paper_whisker()
    f1 = float(w.natural_frequencies_hz[0])
    amps = np.asarray(_amplitudes(w, np.array([0.5, 0.9, 1.0, 1.1, 1.5]) * f1, 0.005))
    assert amps[2] == amps.max()
    assert amps[2] > 2 * max(amps[1], amps[3]) and amps[2] > 8 * max(amps[0], amps[4])
    # Peak height of a lightly damped mode: amplification ≈ 1/(2ζ) relative to quasi-static.
    assert amps[2] == pytest.approx(paper_fem.steady_amplitude(0.005, f1, 1e-4), rel=5e-3)


def test_free_decay_matches_direct_integration():
    w = wi.paper_whisker(12)
    fem = FEMBeam(length=0.06, EI=float(w.EI), rho_a=float(w.rho_a), zeta=0.04, n_el=16)
    t = np.linspace(0, 0.1, 2001)
    ref = fem.integrate(t, n_modes=12, w0=fem.static_tip_shape(1e-3))
    state = wi.free_decay(w, jnp.asarray(t), q0=wi.pluck(w, 1e-3))
    for x in (0.005, 0.06):
        ours = np.asarray(wi.observe(w, state, x_m=x))
        fem_x = ref @ fem.interpolation(x)
        assert np.max(np.abs(ours - fem_x)) < 0.01 * np.max(np.abs(fem_x))


def test_steady_state_is_the_limit_of_the_response_from_rest():
    w = wi.paper_whisker()
    t = jnp.linspace(3.0, 3.1, 500)  # after ~ 40 time constants of mode 1
    a = wi.observe(w, wi.harmonic_from_rest(w, t, fb_hz=70.0, hb_m=1e-4))
    b = wi.observe(w, wi.harmonic_steady_state(w, t, fb_hz=70.0, hb_m=1e-4))
    np.testing.assert_allclose(a, b, atol=1e-6 * float(jnp.max(jnp.abs(b))))


def test_base_motion_scan_equals_closed_form_for_a_sine():
    """Sampled base acceleration of a sine from rest: the scan must match the closed form."""
    w = wi.paper_whisker()
    fb, hb = 120.0, 1e-4
    t = jnp.arange(0, 0.5, 1 / 40_000)
    acc = -hb * (2 * np.pi * fb) ** 2 * jnp.sin(2 * np.pi * fb * t)
    scan = wi.base_motion_response(w, t, acc)
    fast = wi.base_motion_response(w, t, acc, uniform=True)
    np.testing.assert_allclose(fast.q, scan.q, rtol=1e-9, atol=1e-9 * float(jnp.abs(scan.q).max()))
    closed = wi.harmonic_from_rest(w, t, fb_hz=fb, hb_m=hb)
    for obs in ("deflection", "velocity"):
        a, b = wi.observe(w, scan, obs), wi.observe(w, closed, obs)
        assert float(jnp.max(jnp.abs(a - b))) < 2e-3 * float(jnp.max(jnp.abs(b)))


@pytest.mark.slow
def test_base_motion_non_uniform_steps_match_direct_integration():
    w = wi.paper_whisker(8)
    fem = FEMBeam(length=0.06, EI=float(w.EI), rho_a=float(w.rho_a), zeta=0.04, n_el=16)
    rng = np.random.default_rng(3)
    t = np.cumsum(np.concatenate([[0.0], rng.uniform(0.5e-4, 1.5e-4, 2000)]))  # ~10 kHz, jittered
    acc = 30 * np.sin(2 * np.pi * 35 * t) + 20 * np.sin(2 * np.pi * 150 * t + 1) * np.exp(-5 * t)
    ref = fem.integrate(t, n_modes=8, base_acc=lambda s: np.interp(s, t, acc))
    ref = ref @ fem.interpolation(0.06)
    # Same truncation on both sides (8 modes, no static correction): this checks the scan.
    state = wi.base_motion_response(w, jnp.asarray(t), jnp.asarray(acc))
    ours = np.asarray(wi.observe(w, state, x_m=0.06, static_correction=False))
    assert np.max(np.abs(ours - ref)) < 5e-3 * np.max(np.abs(ref))


@pytest.mark.parametrize("length", [0.30, 0.50])
def test_tip_mass_aluminium_beam_matches_stated_theory(length):
    beam = wi.UniformBeam(
        length_m=length,
        youngs_modulus_pa=ALU["E"],
        density_kg_m3=ALU["rho"],
        width_m=ALU["width"],
        thickness_m=ALU["thickness"],
    )
    w = wi.whisker_from_structure(beam, tip_mass_kg=ALU["tip_mass"], sensor_x_m=length)
    f1 = float(w.natural_frequencies_hz[0])
    assert f1 == pytest.approx(ALU_THEORY_F1[length], rel=5e-3)
    fem = FEMBeam(
        length=length, EI=beam.EI, rho_a=beam.rho_a, zeta=0.01, tip_mass=ALU["tip_mass"], n_el=30
    )
    np.testing.assert_allclose(w.natural_frequencies_hz, fem.frequencies_hz(5), rtol=1e-4)


def test_tip_mass_steady_state_matches_fem():
    beam = wi.UniformBeam(
        length_m=0.3,
        youngs_modulus_pa=ALU["E"],
        density_kg_m3=ALU["rho"],
        width_m=ALU["width"],
        thickness_m=ALU["thickness"],
    )
    w = wi.whisker_from_structure(beam, tip_mass_kg=0.02, sensor_x_m=0.05, zeta=0.02)
    fem = FEMBeam(length=0.3, EI=beam.EI, rho_a=beam.rho_a, zeta=0.02, tip_mass=0.02, n_el=40)
    freqs = np.array([5.0, float(w.natural_frequencies_hz[0]), 60.0, 200.0])
    for x in (0.05, 0.3):
        fem_amps = [fem.steady_amplitude(x, f, 1e-4) for f in freqs]
        np.testing.assert_allclose(_amplitudes(w, freqs, x), fem_amps, rtol=5e-3)


def test_jit_and_vmap_agree_with_eager():
    w = wi.paper_whisker()
    t = jnp.linspace(0, 0.3, 300)

    def response(scale):
        ww = jax.tree_util.tree_map(lambda x: x, w)
        ww = wi.Whisker(
            length_m=ww.length_m,
            EI=ww.EI * scale,
            rho_a=ww.rho_a,
            zeta=ww.zeta,
            sensor_x_m=ww.sensor_x_m,
        )
        return wi.observe(ww, wi.harmonic_from_rest(ww, t, fb_hz=80.0, hb_m=1e-4))

    scales = jnp.array([0.8, 1.0, 1.3])
    batch = jax.jit(jax.vmap(response))(scales)
    for i, s in enumerate(scales):
        np.testing.assert_allclose(batch[i], response(s), rtol=1e-10, atol=1e-18)
