"""The paper's Eq. 1: transcription and the spectra of its modal-analysis figure."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import paper_eq1_numpy

import whiskerid as wi


@pytest.mark.parametrize(
    ("fb", "hb", "x"), [(100.0, 1e-4, 0.005), (300.0, 3e-4, 0.03), (37.0, 2e-4, 0.06)]
)
def test_matches_independent_numpy_transcription(fb, hb, x):
    w = wi.paper_whisker()
    t = np.linspace(0, 0.4, 4001)  # the literal form overflows later; ours does not
    ours = np.asarray(wi.paper_eq1(w, jnp.asarray(t), fb_hz=fb, hb_m=hb, x_m=x))
    ref = paper_eq1_numpy(
        t, x, fb=fb, hb=hb, l=0.06, EI=float(w.EI), rho_a=float(w.rho_a), zeta=0.04
    )
    np.testing.assert_allclose(ours, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_long_records_stay_finite():
    t = jnp.arange(0, 60.0, 1 / 200)
    assert np.all(np.isfinite(wi.paper_eq1(wi.paper_whisker(), t, fb_hz=100.0, hb_m=1e-4)))


@pytest.mark.parametrize("fb", [100.0, 300.0])
def test_modal_analysis_figure_peaks(fb):
    """Dominant peak at f_b for h_b = 0.1 and 0.3 mm; side peaks at f_b ± f_d1."""
    w = wi.paper_whisker()
    fd1 = float(w.damped_frequencies_hz[0])
    t = np.arange(20_000) / 20_000.0
    found = {}
    for hb in (1e-4, 3e-4):
        y = np.asarray(wi.paper_eq1(w, jnp.asarray(t), fb_hz=fb, hb_m=hb))
        peaks = wi.dominant_peaks(t, y, n=3)
        found[hb] = peaks
        assert peaks[0].frequency_hz == pytest.approx(fb, abs=0.05)
        sides = sorted(p.frequency_hz for p in peaks[1:])
        np.testing.assert_allclose(sides, [fb - fd1, fb + fd1], atol=0.1)
    # Linear in h_b: the same frequencies, amplitudes in ratio 3.
    assert found[3e-4][0].amplitude / found[1e-4][0].amplitude == pytest.approx(3.0, rel=1e-6)


def test_paper_whisker_driven_at_100_hz_peaks_at_54_100_146():
    """Eq. 1 as printed: the drive and side bands at ``f_b ± f_d1`` (46 Hz), not a resonance."""
    t = np.arange(20_000) / 20_000.0
    y = np.asarray(wi.paper_eq1(wi.paper_whisker(), jnp.asarray(t), fb_hz=100.0, hb_m=1e-4))
    got = sorted(round(p.frequency_hz) for p in wi.dominant_peaks(t, y, n=3))
    assert got == [54, 100, 146]


def test_no_resonance_at_f1_unlike_a_linear_beam():
    """Eq. 1 tends to a quasi-static term: driving at f_1 is not amplified."""
    w = wi.paper_whisker()
    t = jnp.arange(0, 4.0, 1 / 20_000)
    late = t > 3.0
    f1 = float(w.natural_frequencies_hz[0])
    amp = lambda fn, f: float(jnp.max(jnp.abs(fn(f)[late])))
    paper = lambda f: wi.paper_eq1(w, t, fb_hz=f, hb_m=1e-4)
    exact = lambda f: wi.observe(w, wi.harmonic_steady_state(w, t, fb_hz=f, hb_m=1e-4))
    assert amp(paper, f1) / amp(paper, 0.8 * f1) < 2.0
    assert amp(exact, f1) / amp(exact, 0.8 * f1) > 5.0


def test_jit_vmap_and_grad():
    w = wi.paper_whisker()
    t = jnp.linspace(0, 0.2, 200)
    f = jax.jit(lambda hb: wi.paper_eq1(w, t, fb_hz=100.0, hb_m=hb))
    batch = jax.vmap(f)(jnp.array([1e-4, 2e-4]))
    np.testing.assert_allclose(batch[1], 2 * batch[0], rtol=1e-12)
    g = jax.grad(lambda hb: jnp.sum(f(hb) ** 2))(1e-4)
    assert g == pytest.approx(2 * float(jnp.sum(f(1e-4) ** 2)) / 1e-4, rel=1e-9)
