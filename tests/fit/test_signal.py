"""Spectral peaks: what counts as a peak."""

import numpy as np

import whiskerid as wi


def test_relative_threshold_is_against_the_largest_peak_not_the_largest_bin():
    freqs = np.arange(100) * 0.5
    amps = 10.0 * np.exp(-freqs)  # a skirt from DC (drift, a windowed transient): no peak
    amps[20] += 1.0  # the mode
    amps[60] += 0.03  # a small but real tone: 3 % of the mode, 0.3 % of the largest bin
    found = wi.find_peaks(freqs, amps, n=3, min_relative=0.02)
    np.testing.assert_allclose([p.frequency_hz for p in found], [10.0, 30.0], atol=0.05)
    (only,) = wi.find_peaks(freqs, amps, n=3, min_relative=0.05)
    assert abs(only.frequency_hz - 10.0) < 0.05


def test_pluck_peaks_above_the_window_ripple_are_the_mode_only():
    rec = wi.paper_record()
    sim = wi.simulate(rec, model="exact", observable="adc", rate_hz=200.0, duration_s=5.0,
                      seed=1, excitation="decay", tip_deflection_m=2e-3)  # fmt: skip
    f1 = float(rec.whisker().damped_frequencies_hz[0])
    ripple = wi.dominant_peaks(sim.t, sim.signal(), n=3, min_separation_hz=10.0)
    assert abs(ripple[0].frequency_hz - f1) < 0.2 and len(ripple) == 3
    clean = wi.dominant_peaks(sim.t, sim.signal(), n=3, min_separation_hz=10.0, min_relative=0.05)
    assert len(clean) == 1 and abs(clean[0].frequency_hz - f1) < 0.2


def test_find_peaks_interpolates_between_bins():
    rate, n = 100.0, 1000
    f0 = 12.34  # between the 0.1 Hz bins
    x = np.sin(2 * np.pi * f0 * np.arange(n) / rate)
    freqs, amps = wi.amplitude_spectrum(x, rate)
    (p,) = wi.find_peaks(freqs, amps, n=1)
    assert abs(p.frequency_hz - f0) < 0.01


def test_line_fit_is_polyfits_line_and_flat_through_one_distinct_x():
    from whiskerid.fit._data._signal import line_fit

    rng = np.random.default_rng(4)
    x = np.sort(rng.uniform(-3, 50, 200))
    y = 0.7 * x - 4 + rng.normal(0, 2, x.size)
    np.testing.assert_allclose(line_fit(x, y), np.polyfit(x, y, 1), rtol=1e-12)
    assert line_fit(np.full(4, 2.0), np.array([1.0, 2.0, 3.0, 6.0])) == (0.0, 3.0)
