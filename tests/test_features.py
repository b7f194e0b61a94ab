"""Features: sub-bin peaks, band energies, shapes under jit/vmap, both pipelines."""

import itertools
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import whiskerid as wi
from whiskerid.classify._features import fit_resonance, power_spectrum


def test_spectral_peaks_sub_bin_accuracy_and_order():
    t = np.arange(200) / 200.0
    x = np.sin(2 * np.pi * 37.3 * t) + 0.3 * np.sin(2 * np.pi * 60.6 * t)
    _f, p = power_spectrum(jnp.asarray(x), 200.0)
    amps = jnp.concatenate([jnp.zeros(1), jnp.sqrt(p)])
    freq, amp, width = wi.spectral_peaks(amps, 1.0, 3)
    assert abs(float(freq[0]) - 37.3) < 0.05 and abs(float(freq[1]) - 60.6) < 0.05
    assert amp[0] > 2.5 * amp[1]
    assert 0.8 < float(width[0]) < 3.0  # Hann main lobe: about 1.4 bins at half power


def test_band_energies_sum_to_one_and_locate_a_tone():
    t = np.arange(400) / 400.0
    f, p = power_spectrum(jnp.asarray(np.sin(2 * np.pi * 72.0 * t)), 400.0)
    e = wi.band_energies(f, p, jnp.linspace(0, 200, 9))
    assert abs(float(e.sum()) - 1) < 1e-12
    assert int(jnp.argmax(e)) == 2 and float(e[2]) > 0.95  # 72 Hz lies in [50, 75)


def test_resonance_fit_finds_a_damped_mode():
    """Within half the half-power bandwidth (2ζf = 3.7 Hz) from one noisy periodogram."""
    rng = np.random.default_rng(0)
    fs, n, fn, zeta = 200.0, 2000, 46.0, 0.04
    wn, wd = 2 * np.pi * fn, 2 * np.pi * fn * np.sqrt(1 - zeta**2)
    h = np.exp(-zeta * wn * np.arange(400) / fs) * np.sin(wd * np.arange(400) / fs)
    x = np.convolve(rng.standard_normal(n), h)[:n]
    f, p = power_spectrum(jnp.asarray(x), fs)
    fd, z, _, _, ok = fit_resonance(f, p, 45.0)
    assert bool(ok) and abs(float(fd) - 46.0) < 2.0 and 0.01 < float(z) < 0.12


@pytest.mark.parametrize(
    "rate, window, use_speed, octaves", [(200.0, 200, True, True), (100.0, 150, False, False)]
)
def test_fitted_features_shapes_any_rate_and_window(rate, window, use_speed, octaves):
    spec = wi.FeatureSpec(rate_hz=rate, window=window, use_speed=use_speed, octave_bands=octaves)
    x = np.random.default_rng(1).standard_normal((5, window))
    feats = wi.compute_features(spec, x, np.full(5, 0.2) if use_speed else None)
    assert feats.shape == (5, spec.n_features) and np.isfinite(np.asarray(feats)).all()
    # Standardised quantities ignore gain and offset; the log RMS moves by log(gain).
    feats2 = wi.compute_features(spec, 10 * x + 3, np.full(5, 0.2) if use_speed else None)
    np.testing.assert_allclose(feats2[:, 0] - feats[:, 0], np.log(10), atol=1e-9)
    np.testing.assert_allclose(feats2[:, 6:20], feats[:, 6:20], atol=1e-6)


def _octave_block(spec, feats):
    """The octave-band levels in a feature vector (no speed features)."""
    start = replace(spec, octave_bands=False).n_features
    return np.asarray(feats)[:, start : start + len(spec.octave_edges()) - 1]


def test_octave_bands_are_the_raw_power_per_octave():
    """Checked against NumPy: the Hann-windowed power of the raw window, summed per octave
    (edges Δf, 2Δf, … and Nyquist, the last band closed); a gain g adds 2 log g."""
    spec = wi.FeatureSpec(rate_hz=200.0, window=200, octave_bands=True)
    assert spec.octave_edges() == (1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 100.0)
    assert wi.FeatureSpec(rate_hz=100.0, window=64).octave_edges()[-1] == 50.0
    x = 3.0 + np.random.default_rng(7).standard_normal((4, 200))
    w = np.hanning(200)
    p = np.abs(np.fft.rfft((x - x.mean(1, keepdims=True)) * w)) ** 2 / np.sum(w**2)
    f = np.fft.rfftfreq(200, 1 / 200.0)
    edges = spec.octave_edges()
    want = np.stack(
        [p[:, (f >= lo) & ((f < hi) | (hi == edges[-1]) & (f == hi))].sum(1)
         for lo, hi in itertools.pairwise(edges)], axis=1
    )  # fmt: skip
    got = _octave_block(spec, wi.compute_features(spec, x))
    np.testing.assert_allclose(got, np.log(want), atol=1e-4)
    got10 = _octave_block(spec, wi.compute_features(spec, 10 * x))
    np.testing.assert_allclose(got10 - got, 2 * np.log(10), atol=1e-9)


def test_octave_levels_ignore_a_loud_line_elsewhere():
    """A loud drivetrain-like line at 40 Hz lowers the share of the low band but leaves
    the power in the low octaves where it was (what the octave levels are for)."""
    spec = wi.FeatureSpec(rate_hz=200.0, window=200, octave_bands=True)
    rng = np.random.default_rng(8)
    t = np.arange(200) / 200.0
    slow = np.cumsum(rng.standard_normal((8, 200)), axis=1) * 0.05  # most power < 4 Hz
    loud = slow + 3.0 * np.sin(2 * np.pi * 40.0 * t)
    quiet_f, loud_f = (np.asarray(wi.compute_features(spec, s)) for s in (slow, loud))
    np.testing.assert_allclose(_octave_block(spec, loud_f)[:, :2],
                               _octave_block(spec, quiet_f)[:, :2], atol=0.05)  # fmt: skip
    assert np.all(quiet_f[:, 6] - loud_f[:, 6] > 1.0)  # first relative band energy (log)


def test_model_files_without_octave_bands_keep_their_features():
    spec = wi.FeatureSpec(octave_bands=True)
    old = {k: v for k, v in spec.to_dict().items() if k != "octave_bands"}
    assert wi.FeatureSpec.from_dict(old).octave_bands is False
    assert wi.FeatureSpec.from_dict(spec.to_dict()) == spec


def test_paper_features_are_fft_magnitudes_of_the_standardised_window():
    spec = wi.FeatureSpec(kind="paper")
    x = np.random.default_rng(2).standard_normal((3, 200))
    z = (x - x.mean(1, keepdims=True)) / x.std(1, keepdims=True)
    np.testing.assert_allclose(wi.compute_features(spec, 5 * x), np.abs(np.fft.fft(z)), atol=1e-9)
    assert spec.n_features == 200


def test_speed_features_need_a_speed():
    with pytest.raises(ValueError, match="speed"):
        wi.compute_features(wi.FeatureSpec(use_speed=True), np.zeros((1, 200)))


def test_envelope_periodicity_finds_impacts_and_slope_follows_the_psd():
    """Impacts every 0.25 s (joints): the envelope autocorrelation peaks at that lag; a
    random signal with power ∝ f^-2 has a log-log spectral slope near -2."""
    spec = wi.FeatureSpec(rate_hz=200.0, window=200)
    rng = np.random.default_rng(3)
    x = 0.05 * rng.standard_normal(200)
    h = np.exp(-np.arange(20) / 3.0) * np.sin(2 * np.pi * 46 * np.arange(20) / 200.0)
    for start in (10, 60, 110, 160):
        x[start : start + 20] += h
    f = np.asarray(wi.compute_features(spec, x[None, :]))[0]
    env = 6 + spec.n_bands + 2 + 6 + 2 + spec.n_bands // 2  # envelope block
    assert f[env + 2] > 0.5  # strong periodic envelope
    assert abs(f[env + 3] - 0.25) < 0.03  # lag 50 samples = a quarter of the window
    white = rng.standard_normal((64, 400))
    red = np.fft.irfft(np.fft.rfft(white) / np.maximum(np.arange(201), 1), 400)[:, :200]
    slope = np.asarray(wi.compute_features(spec, red))[:, 6 + spec.n_bands + 2 + 3]
    assert -2.6 < float(np.median(slope)) < -1.4


@pytest.mark.parametrize("kind", ["fitted", "paper"])
def test_multichannel_windows_concatenate_per_channel_features(kind):
    spec1 = wi.FeatureSpec(kind=kind, rate_hz=100.0, window=100)
    spec3 = wi.FeatureSpec(kind=kind, rate_hz=100.0, window=100, channels=3)
    x = np.random.default_rng(5).standard_normal((4, 3, 100))
    x[:, 1] *= 7.0  # channels differ in scale, e.g. gyro and accelerometer
    f3 = np.asarray(wi.compute_features(spec3, x))
    assert f3.shape == (4, 3 * spec1.n_features) == (4, spec3.n_features)
    for c in range(3):
        fc = np.asarray(wi.compute_features(spec1, x[:, c]))
        np.testing.assert_allclose(f3[:, c * spec1.n_features : (c + 1) * spec1.n_features], fc,
                                   atol=1e-9)  # fmt: skip
    with pytest.raises(ValueError, match=r"\(n, 3, 100\)"):
        wi.compute_features(spec3, x[:, 0])


def _recorded(record, acc_fn, seconds=2.0, rate=200.0):
    """ADC codes (floats, no noise) of a whisker whose base accelerates as ``acc_fn(t)``:
    the exact model on a 2 kHz grid from rest, the Hall sensor (×20 amplifier) and the
    ADS1115's averaging over each conversion, sampled at ``rate``; the last ``seconds``."""
    from whiskerid.terrain import amplified_hall, hall_voltage

    grid = np.arange(0, seconds + 1.0, 1 / 2000.0)
    volts = np.asarray(hall_voltage(record.whisker(), amplified_hall(record, 20.0),
                                    jnp.asarray(grid), jnp.asarray(acc_fn(grid))))  # fmt: skip
    ts = 1.0 + np.arange(round(seconds * rate)) / rate
    conv = record.adc.conversion_time_s
    offsets = -(np.arange(16) + 0.5) / 16 * conv
    v = np.mean(np.interp(ts[:, None] + offsets[None, :], grid, volts), axis=1)
    return v / record.adc.lsb_v


def test_base_motion_band_level_of_a_sine_through_the_whisker():
    """A base acceleration of 1 m/s² amplitude (0.5 (m/s²)² mean square, −3 dB) below, near
    and above the paper whisker's 46 Hz resonance: the band that holds it reads −3 dB within
    1 dB once the whisker is divided out; the raw codes read anything but. (Higher up, the
    estimate assumes base motion at the bin's aliases too, which a lone sine lacks.)"""
    from whiskerid.classify._features import through_filter

    rec = wi.paper_record()
    spec = wi.FeatureSpec(deconvolve=True)
    num = spec.numbers(wi.WhiskerResponse(rec, 20.0))
    edges = jnp.asarray(spec.octave_edges())
    for f_hz in (3.0, 20.0, 46.0):
        x = _recorded(rec, lambda t, f=f_hz: np.sin(2 * np.pi * f * t), seconds=1.0)
        base = through_filter(jnp.asarray(x[None]), num.to_base)
        levels = np.asarray(wi.base_band_levels(base, 200.0, edges))
        band = int(np.searchsorted(np.asarray(edges), f_hz, side="right")) - 1
        raw = np.asarray(wi.base_band_levels(jnp.asarray(x[None]), 200.0, edges))
        assert abs(levels[0, band] + 3.01) < 1.0, (f_hz, levels)
        assert abs(raw[0, band] + 3.01) > 20


def test_recolouring_makes_another_whisker_look_like_the_training_one():
    """The same base motion recorded by the paper whisker and by one with f_1 × 0.7 and
    ζ 0.08: their spectra differ by many dB; the second recoloured to the first (what a
    model trained on the first sees with ``--whisker``) agrees within 1.5 dB, and the
    paper whisker recoloured to itself is unchanged."""
    from dataclasses import replace as dc_replace

    from whiskerid.classify._features import through_filter

    paper = wi.paper_record()
    structure = dc_replace(paper.structure,
                           shear_modulus_pa=paper.structure.shear_modulus_pa * 0.49)  # fmt: skip
    other = paper.replace(structure=structure, zeta=0.08)
    rng = np.random.default_rng(1)
    noise = np.fft.irfft(np.fft.rfft(rng.standard_normal(6000))
                         * (np.fft.rfftfreq(6000, 1 / 2000) < 90), 6000)  # fmt: skip

    def acc(t):
        return 20 * np.interp(t, np.arange(6000) / 2000, noise)

    xa, xb = _recorded(paper, acc), _recorded(other, acc)
    spec = wi.FeatureSpec(window=400, deconvolve=True)
    a, b = wi.WhiskerResponse(paper, 20.0), wi.WhiskerResponse(other, 20.0)
    to_a = spec.numbers(b, reference=a).recolour
    same = spec.numbers(a).recolour
    f = np.fft.rfftfreq(400, 1 / 200)
    keep = (f > 3) & (f < 85)

    def db(x):
        spec_ = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(400))) ** 2
        smooth = np.convolve(spec_, np.ones(5) / 5, mode="same")
        return 10 * np.log10(smooth[keep])

    raw_gap = np.median(np.abs(db(xb) - db(xa)))
    fixed_gap = np.median(np.abs(db(np.asarray(through_filter(xb[None], to_a))[0]) - db(xa)))
    assert raw_gap > 4 and fixed_gap < 1.5, (raw_gap, fixed_gap)
    np.testing.assert_allclose(np.asarray(through_filter(xa[None], same))[0], xa - xa.mean(),
                               atol=2e-3 * np.std(xa))  # fmt: skip


def _other_whisker(factor):
    from dataclasses import replace as dc_replace

    paper = wi.paper_record()
    g = paper.structure.shear_modulus_pa * factor**2
    return paper.replace(structure=dc_replace(paper.structure, shear_modulus_pa=g))


def test_recolouring_holds_at_the_window_edges_and_where_a_mode_folds():
    """The same base motion, its power falling as 1/f up to 500 Hz, recorded by the paper
    whisker and by one with f_1 × 0.7 (whose second mode, at 202 Hz, folds to 2 Hz at
    200 Hz; the paper whisker's folds to 88 Hz), in 1 s windows; the second recoloured to
    the first. With aliases counted as if the ground shook as hard above the band as in it
    (``alias_slope`` 0) the recoloured window reads 2-3 dB too quiet at 0.5-5 Hz and too loud
    at 80-100 Hz; zero-extended windows step at their edges, and the steps, with the
    weak whisker divided out, ring: the recoloured window's first and last 0.1 s miss the
    paper whisker's by more than their RMS, and its kurtosis rises. The settings a model
    is trained with (``default_spec``: each window extended by its own continuation, the
    aliases weighted) keep the bands within 1 and 1.5 dB, the edges within half their RMS
    and the kurtosis within 0.1 of the paper whisker's own."""
    from whiskerid.classify import ALIAS_SLOPE
    from whiskerid.classify._features import through_filter

    paper, other = wi.paper_record(), _other_whisker(0.7)
    rng = np.random.default_rng(1)
    n = 8000
    f = np.fft.rfftfreq(n, 1 / 2000)
    shaped = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) / np.sqrt(np.maximum(f, 1.0))
                          * (f < 500), n)  # fmt: skip

    def acc(t):
        return 20 / np.std(shaped) * np.interp(t, np.arange(n) / 2000, shaped)

    xa, xb = _recorded(paper, acc, seconds=3.0), _recorded(other, acc, seconds=3.0)
    starts = range(0, 401, 20)
    wa = np.stack([xa[s : s + 200] - xa[s : s + 200].mean() for s in starts])
    wb = jnp.asarray(np.stack([xb[s : s + 200] for s in starts]))[:, None]
    fr = np.fft.rfftfreq(200, 1 / 200)

    def db(y):
        return 10 * np.log10(np.mean(np.abs(np.fft.rfft(y * np.hanning(200))) ** 2, axis=0))

    def log_kurtosis(y):
        z = (y - y.mean(1, keepdims=True)) / y.std(1, keepdims=True)
        return np.log(np.mean(z**4, axis=1))

    def gaps(spec):
        to_a = spec.numbers(wi.WhiskerResponse(other, 20.0),
                            reference=wi.WhiskerResponse(paper, 20.0)).recolour  # fmt: skip
        y = np.asarray(jax.vmap(lambda w: through_filter(w, to_a, spec.extend_edges))(wb))[:, 0]
        gap = db(y) - db(wa)
        low, high = (np.median(gap[(fr >= lo) & (fr < hi)]) for lo, hi in ((0.5, 5), (80, 100)))
        edges = (y - wa)[:, np.r_[0:20, 180:200]]
        edge_error = np.sqrt(np.mean(edges**2)) / np.std(wa)
        return low, high, edge_error, np.mean(log_kurtosis(y) - log_kurtosis(wa))

    old = gaps(wi.FeatureSpec(deconvolve=True))
    new = gaps(wi.FeatureSpec(deconvolve=True, extend_edges=True, alias_slope=ALIAS_SLOPE))
    assert old[0] < -2 and old[1] > 2.5 and old[2] > 1 and old[3] > 0.25, old
    assert abs(new[0]) < 1 and abs(new[1]) < 1.5 and new[2] < 0.5 and new[3] < 0.1, new


def test_model_files_before_edges_and_alias_weights_keep_their_features():
    """A whisker-aware model written before the extended edges and the aliases' weight
    reads windows as it did; models trained now use both."""
    from whiskerid.classify import ALIAS_SLOPE, default_spec

    spec = wi.FeatureSpec(deconvolve=True, floor_match=True)
    old = {k: v for k, v in spec.to_dict().items() if k not in ("extend_edges", "alias_slope")}
    assert wi.FeatureSpec.from_dict(old) == spec
    assert spec.extend_edges is False and spec.alias_slope == 0.0
    ws = wi.WindowSet(np.zeros((2, 200)), np.array([0, 1]), ("a", "b"), np.array([0, 1]),
                      np.full(2, np.nan), ["r0", "r1"], 200.0)  # fmt: skip
    trained = default_spec(ws, whisker=True)
    assert trained.extend_edges and trained.alias_slope == ALIAS_SLOPE > 0
    assert not default_spec(ws).extend_edges
    with pytest.raises(ValueError, match="extend_edges"):
        wi.FeatureSpec(extend_edges=True)
    with pytest.raises(ValueError, match="alias_slope"):
        wi.FeatureSpec(deconvolve=True, alias_slope=-1.0)


def test_floor_match_narrows_the_noise_floors_of_whiskers_to_one():
    """The ADC's white noise alone, recorded by the paper whisker, by one with f_1 × 0.7
    (whose response above 60 Hz is 7-14 dB weaker) and by one with f_1 × 1.3 (stronger
    there): recoloured to the paper whisker, the weak one's floor stands far above the
    paper's at 80-95 Hz; with the floor matched the gap shrinks by more than half, the
    strong one reads the paper's level, and the same window always gets the same noise."""
    from dataclasses import replace as dc_replace

    from whiskerid.classify._features import matched_noise, through_filter

    paper = wi.paper_record()

    def scaled(factor):
        g = paper.structure.shear_modulus_pa * factor**2
        return wi.WhiskerResponse(
            paper.replace(structure=dc_replace(paper.structure, shear_modulus_pa=g)), 20.0
        )

    ref, weak, strong = wi.WhiskerResponse(paper, 20.0), scaled(0.7), scaled(1.3)
    x = jnp.asarray(2.0 * np.random.default_rng(0).standard_normal((48, 1, 200)))
    spec = wi.FeatureSpec(deconvolve=True, floor_match=True)
    f = np.fft.rfftfreq(200, 1 / 200)
    band = (f > 80) & (f < 95)

    def level(resp, matched):
        num = spec.numbers(resp, ref)

        def one(w):
            y = through_filter(w, num.recolour)
            return y + matched_noise(w, num.dither) if matched else y

        y = np.asarray(jax.vmap(one)(x))[:, 0]
        p = np.abs(np.fft.rfft((y - y.mean(1, keepdims=True)) * np.hanning(200))) ** 2
        return 10 * np.log10(np.mean(p[:, band]))

    plain_gap = level(weak, False) - level(ref, False)
    assert plain_gap > 8
    assert level(weak, True) - level(ref, True) < plain_gap / 2
    assert abs(level(strong, True) - level(ref, True)) < 1.5
    num = spec.numbers(weak, ref)
    np.testing.assert_array_equal(matched_noise(x[0], num.dither), matched_noise(x[0], num.dither))


def test_span_whiskers_rerecord_windows_with_their_own_floor():
    """Span whiskers around the paper whisker cover f_1 × 0.6-1.6 and ζ × 0.5-2, one in each
    slice of either range. White noise alone (the sensors' floor) recorded by the paper
    whisker and rerecorded as a whisker with f_1 × 0.7 (7-14 dB weaker above 60 Hz), then
    recoloured back as a model reads that whisker's recordings: its floor at 80-95 Hz
    stands as far above the paper's as a real recording of the weak whisker's does, where
    the filter alone gives back the paper's floor; rerecorded as the paper whisker itself,
    a window is unchanged."""
    from whiskerid.classify import ALIAS_SLOPE
    from whiskerid.classify._features import rerecorded, through_filter

    paper = wi.WhiskerResponse(wi.paper_record(), 20.0, alias_slope=ALIAS_SLOPE)
    span = paper.span(4, seed=0)
    f1 = [w.record.whisker().natural_frequencies_hz[0] for w in span]
    ratio = np.asarray(f1) / paper.record.whisker().natural_frequencies_hz[0]
    zeta = np.asarray([float(np.ravel(w.record.zeta)[0]) for w in span]) / 0.04
    for r, (lo, hi) in ((ratio, (0.6, 1.6)), (zeta, (0.5, 2.0))):
        assert sorted(np.floor(4 * np.log(r / lo) / np.log(hi / lo)).tolist()) == [0, 1, 2, 3]
    weak = paper.scaled(0.7, 1.0)
    x = 2.0 * np.random.default_rng(0).standard_normal((48, 200))
    freqs = np.fft.rfftfreq(400, 1 / 200)
    response, floor = paper.rerecord(weak, freqs, 200.0)
    back = jnp.asarray(weak.recolour(paper, freqs, 200.0))
    band = (freqs[::2] > 80) & (freqs[::2] < 95)

    def level(y):
        y = np.asarray(jax.vmap(lambda w: through_filter(w[None], back, True))(jnp.asarray(y)))
        p = np.abs(np.fft.rfft(y[:, 0] * np.hanning(200))) ** 2
        return 10 * np.log10(np.mean(p[:, band]))

    own = 10 * np.log10(np.mean(np.abs(np.fft.rfft(x * np.hanning(200))[:, band]) ** 2))
    real = level(x) - own  # the weak whisker's own recording of the floor, recoloured
    span_gap = level(rerecorded(x, response, floor, extend=True, seed=1)) - own
    bare_gap = level(rerecorded(x, response, 0 * floor, extend=True, seed=1)) - own
    gaps = (real, span_gap, bare_gap)
    assert real > 8 and abs(span_gap - real) < 1.5 and abs(bare_gap) < 1.5, gaps
    same, none = paper.rerecord(paper, freqs, 200.0)
    assert np.all(none == 0)
    np.testing.assert_allclose(rerecorded(x, same, none, extend=True, seed=1),
                               x - x.mean(1, keepdims=True), atol=1e-2)  # fmt: skip


def test_cross_channel_features_read_the_motion_ellipse():
    """Two channels moving together along 30° from sensor A: coherence near 1, orientation
    2θ = 60°, axis ratio near 0; independent channels: low coherence, ratio near 1."""
    rng = np.random.default_rng(0)
    s = rng.standard_normal(200)
    spec = wi.FeatureSpec(channels=2, cross_channel=True)
    together = np.stack([np.cos(np.pi / 6) * s, np.sin(np.pi / 6) * s])
    apart = rng.standard_normal((2, 200))
    feats = np.asarray(wi.compute_features(spec, np.stack([together, apart])))
    assert feats.shape == (2, spec.n_features)
    coh, c2, s2, ratio = (feats[:, -8:-4].mean(axis=1), feats[:, -4], feats[:, -3],
                          feats[:, -2])  # fmt: skip
    assert coh[0] > 0.99 and coh[1] < 0.5
    assert abs(np.degrees(np.arctan2(s2[0], c2[0])) - 60) < 1
    assert ratio[0] < 0.01 and ratio[1] > 0.6


def test_window_fit_features_read_a_damped_oscillation():
    """Per-window damped-oscillation fits (``fit_windows``) as features: a 30 Hz mode with
    ζ = 0.05 reads 30/100 of Nyquist and ζ within a few per cent, ok; pure noise gives a
    feature row that is finite whatever the fit did."""
    t = np.arange(200) / 200.0
    wd = 2 * np.pi * 30.0
    decay = np.exp(-0.05 * wd / np.sqrt(1 - 0.05**2) * t) * np.cos(wd * t + 0.3)
    noise = np.random.default_rng(0).standard_normal(200)
    spec = wi.FeatureSpec(window_fit=True)
    feats = np.asarray(wi.compute_features(spec, np.stack([decay, noise])))
    assert feats.shape == (2, spec.n_features) and np.isfinite(feats).all()
    fd, zeta, _, ok = feats[0, -4:]
    assert abs(fd - 0.3) < 1e-3 and abs(zeta - 0.05) < 2e-3 and ok == 1.0
    base = np.asarray(wi.compute_features(replace(spec, window_fit=False), decay[None]))
    np.testing.assert_allclose(feats[:1, :-4], base, rtol=1e-10, atol=1e-12)
