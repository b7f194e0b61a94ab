"""Per-window features for terrain classification (JAX: jitted, vmapped over windows).

Two pipelines, both for any sample rate and window length (a :class:`FeatureSpec` holds
them, and goes into model files):

* ``paper``: the paper's (Section IV): standardise the window (zero mean, unit standard
  deviation), then the magnitude of its full FFT: ``window`` inputs (200 at 200 Hz, 1 s).
* ``fitted``: a short vector of physically meaningful quantities, made comparable across
  speeds and amplitudes:

  - amplitude and shape in time: log RMS, skewness, log kurtosis and log crest factor (joint
    and bump impacts are spiky), zero-crossing rate, RMS of the first difference;
  - spectrum of the standardised, Hann-windowed window: relative energies in ``n_bands``
    equal bands up to Nyquist (they sum to one), spectral centroid and flatness;
  - the dominant spectral peak and its side peaks (the paper's "dominant frequency
    sandwiched by two less dominant components"): frequency with parabolic
    sub-bin interpolation of the log amplitude, relative amplitude and half-power width;
  - fitted modal quantities: a single-mode resonance
    ``P(f) = A²/((1 − r²)² + (2ζr)²) + c``, ``r = f/f_n``, fitted to each window's power
    spectrum by Levenberg–Marquardt (``_lsq.least_squares``, never raising; vmapped over
    windows): damped frequency ``f_n√(1 − ζ²)``, ``ζ``, gain × amplitude ``A`` (times the
    window RMS) and the floor-to-peak ratio, plus the fit's ``ok`` flag;
  - absolute levels in octave bands (``octave_bands``): ``log`` of the window's power in
    ``[Δf, 2Δf), [2Δf, 4Δf), …`` up to Nyquist (``Δf`` the bin spacing), not divided by
    the total. The relative band energies above are shares of the total power, so one
    strong component elsewhere (a loud drivetrain line at 20–65 Hz) lowers every other
    share; these levels do not move with it, and the octaves resolve the lowest bins
    (soft ground moves the body most at 0.5–3 Hz, one or two bins of a 1 s window, all
    inside the first equal-width band). Used with the speed: without it, a level says
    as much about how fast a run went as about the ground;
  - when the speed ``v`` is known (``use_speed``): a texture of wavelength ``λ`` appears at
    ``f = v/λ`` (the robot passes ``v/λ`` wavelengths a second), so the spectrum is also
    summarised on the *spatial* frequency ``n = f/v`` (cycles/m): relative energies in
    log-spaced bands over ``[spatial_lo, spatial_hi]``, the dominant peak and the centroid
    as log spatial frequencies, and the RMS divided by ``v²`` (base acceleration for a
    given profile grows as ``v²``).

Frequencies are given as fractions of Nyquist, so a spec is meaningful at its own rate only;
model files record the rate and recordings are resampled to it.

The compiled feature function depends on a spec's *structure* only (kind, window length,
numbers of bands and peaks, which optional parts): its physical numbers (the rate and the
spatial-frequency range) are traced arguments (:class:`Numbers`), so models of one
structure at other rates, or with other training speeds, share one compilation.
"""

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._features_spec import _DEFAULT
from ._features_spec import N_CROSS as N_CROSS
from ._features_spec import N_WINDOW_FIT as N_WINDOW_FIT
from ._features_spec import FeatureKind as FeatureKind
from ._features_spec import FeatureSpec as FeatureSpec
from ._features_spec import Numbers as Numbers
from ._features_whisker import EXTEND_ORDER as EXTEND_ORDER
from ._features_whisker import EXTEND_RIDGE as EXTEND_RIDGE
from ._features_whisker import FLOOR_PERCENTILE as FLOOR_PERCENTILE
from ._features_whisker import _cross_features
from ._features_whisker import base_band_levels as base_band_levels
from ._features_whisker import extend_window as extend_window
from ._features_whisker import matched_noise as matched_noise
from ._features_whisker import noise_floor as noise_floor
from ._features_whisker import rerecorded as rerecorded
from ._features_whisker import through_filter as through_filter

_EPS = 1e-12


def octave_edges(window: int, rate_hz, df_hz) -> Float[Array, " edges"]:
    """:meth:`FeatureSpec.octave_edges` for a traced rate: how many edges there are
    depends on the window length only (Nyquist is ``window / 2`` bins)."""
    count = len(replace(_DEFAULT, window=window).octave_edges())
    df = df_hz
    doublings = jnp.asarray([2.0**j for j in range(count - 1)])
    return jnp.concatenate([df * doublings, jnp.reshape(rate_hz / 2, (1,))])


def standardise(x: Float[Array, " window"]) -> Float[Array, " window"]:
    """Zero mean, unit standard deviation (a constant window stays at zero)."""
    x = x - jnp.mean(x)
    return x / jnp.maximum(jnp.std(x), _EPS)


def paper_features(x: Float[Array, " window"]) -> Float[Array, " window"]:
    """The paper's input: ``|FFT|`` of the standardised window (all ``window`` bins)."""
    return jnp.abs(jnp.fft.fft(standardise(x)))


def power_spectrum(x: Float[Array, " window"], rate_hz: float):
    """One-sided power of the standardised, Hann-windowed window; DC dropped.

    Returns:
        ``(freqs_hz, power)``, bins 1 … ``window // 2``.
    """
    f = jnp.fft.rfftfreq(x.shape[-1], 1.0 / rate_hz)
    return f[1:], _power(x)


def _power(x: Float[Array, " window"]) -> Float[Array, " bins"]:
    """The power of :func:`power_spectrum`."""
    n = x.shape[-1]
    w = jnp.hanning(n)
    return (jnp.abs(jnp.fft.rfft(standardise(x) * w)) ** 2 / jnp.sum(w**2))[1:]


def band_energies(
    freqs: Float[Array, " bins"], power: Float[Array, " bins"], edges: Float[Array, " edges"]
) -> Float[Array, " bands"]:
    """Fraction of the power in each band ``[edges[k], edges[k+1])`` (the last one closed).

    The fractions sum to one when the edges cover every bin.
    """
    inside = (freqs[None, :] >= edges[:-1, None]) & (freqs[None, :] < edges[1:, None])
    inside = inside.at[-1].set(inside[-1] | (freqs == edges[-1]))
    e = inside @ power
    total = jnp.sum(jnp.where(inside.any(axis=0), power, 0.0))
    return e / jnp.maximum(total, _EPS)


def spectral_peaks(amps: Float[Array, " bins"], df: float, n: int = 3):
    """The ``n`` largest local maxima with parabolic interpolation of the log amplitude.

    Args:
        amps: Amplitudes of bins ``0 … m-1`` (bin ``k`` at ``k·df``).
        df: Bin spacing (Hz).
        n: Peaks returned (fewer maxima: the remaining ones have zero amplitude).

    Returns:
        ``(freq_hz, amplitude, width_hz)``, each shape ``(n,)``, dominant first. The width is
        the full width at half power of the fitted parabola.
    """
    y = jnp.log(jnp.maximum(amps, _EPS))
    inner = jnp.arange(1, amps.shape[0] - 1)
    is_max = (y[inner] > y[inner - 1]) & (y[inner] >= y[inner + 1])
    score = jnp.where(is_max, y[inner], -jnp.inf)
    top, idx = jax.lax.top_k(score, n)
    k = inner[idx]
    y0, y1, y2 = y[k - 1], y[k], y[k + 1]
    curv = y0 - 2 * y1 + y2  # negative at a maximum
    safe = jnp.where(curv < 0, curv, -_EPS)
    shift = jnp.clip(0.5 * (y0 - y2) / safe, -0.5, 0.5)
    peak_y = y1 - 0.25 * (y0 - y2) * shift
    # Half power in amplitude is ln(√2) below the top: (c/2) Δ² = −ln √2 on each side.
    width = 2 * jnp.sqrt(jnp.log(2.0) / jnp.maximum(-safe, _EPS)) * df
    valid = jnp.isfinite(top)
    freq = jnp.where(valid, (k + shift) * df, 0.0)
    return freq, jnp.where(valid, jnp.exp(peak_y), 0.0), jnp.where(valid, width, 0.0)


def _resonance(params, freqs):
    from ..fit import to_interval  # here: a loaded model's restart need not import fit

    u_f, u_z, log_a2, log_c, f_lo, f_hi = params
    fn = to_interval(u_f, f_lo, f_hi)
    zeta = to_interval(u_z, 0.005, 0.5)
    r = freqs / fn
    return jnp.exp(log_a2) / ((1 - r**2) ** 2 + (2 * zeta * r) ** 2) + jnp.exp(log_c), fn, zeta


def fit_resonance(freqs: Float[Array, " bins"], power: Float[Array, " bins"], f0: float):
    """Fit ``A²/((1 − r²)² + (2ζr)²) + c`` to a power spectrum in the log domain.

    Starts at ``f_n = f0`` (the dominant peak), ``ζ = 0.05``. Never raises: check ``ok``.

    Returns:
        ``(damped_freq_hz, zeta, amplitude A, floor c, ok)``.
    """
    f_lo, f_hi = freqs[0], freqs[-1]
    smooth = jnp.convolve(power, jnp.ones(3) / 3, mode="same")
    target = jnp.log(smooth + 1e-6)
    f0 = jnp.clip(f0, f_lo + 0.02 * (f_hi - f_lo), f_hi - 0.02 * (f_hi - f_lo))
    p_f = (f0 - f_lo) / (f_hi - f_lo)
    y0 = jnp.stack(
        [jnp.log(p_f) - jnp.log1p(-p_f), jnp.log(0.045 / 0.455), jnp.log(jnp.max(smooth) * 0.01),
         jnp.log(jnp.median(smooth) + 1e-6)]
    )  # fmt: skip

    def residual(y, args):
        model, _, _ = _resonance((*y, f_lo, f_hi), freqs)
        return jnp.log(model + 1e-6) - target

    from ..fit import least_squares  # imported when traced, not by a restarted stream

    fit = least_squares(residual, y0, max_steps=48)
    _, fn, zeta = _resonance((*fit.value, f_lo, f_hi), freqs)
    return (
        fn * jnp.sqrt(1 - zeta**2),
        zeta,
        jnp.exp(0.5 * fit.value[2]),
        jnp.exp(fit.value[3]),
        fit.ok,
    )


def _envelope(z: Float[Array, " window"]) -> Float[Array, " window"]:
    """Magnitude of the analytic signal (Hilbert envelope) of a zero-mean window."""
    n = z.shape[-1]
    h = jnp.zeros(n).at[0].set(1.0).at[1 : (n + 1) // 2].set(2.0)
    if n % 2 == 0:
        h = h.at[n // 2].set(1.0)
    return jnp.abs(jnp.fft.ifft(jnp.fft.fft(z) * h))


def _autocorr(x: Float[Array, " window"]) -> Float[Array, " window"]:
    """Normalised (biased) autocorrelation of a zero-mean sequence, lags ``0 … n-1``."""
    n = x.shape[-1]
    f = jnp.fft.rfft(x, 2 * n)
    ac = jnp.fft.irfft(jnp.abs(f) ** 2, 2 * n)[:n]
    return ac / jnp.maximum(ac[0], _EPS)


def _closed_form_mode(freqs, power, pf, pw):
    """A resonance read off the spectrum without iterating (fast, for online use).

    Damped frequency = the interpolated dominant peak, ``ζ ≈ Δf/(2 f)`` from its
    half-power width, and the peak's height above the spectral floor (the median bin).
    """
    k = jnp.argmin(jnp.abs(freqs - pf))
    zeta = jnp.clip(pw / (2 * jnp.maximum(pf, freqs[0])), 0.0, 1.0)
    return zeta, jnp.log(power[k] + _EPS) - jnp.log(jnp.median(power) + _EPS)


def fitted_features(
    spec: FeatureSpec, x: Float[Array, " window"], speed_mps, numbers: Numbers | None = None
) -> Float[Array, " features"]:
    """The ``fitted`` feature vector of one window (see the module docstring).

    ``numbers`` replaces the spec's physical numbers (traced ones, inside a compiled
    function); the spec's own by default.
    """
    num = spec.numbers() if numbers is None else numbers
    rate_hz = num.rate_hz
    nyq = rate_hz / 2
    per_nyq = num.per_nyquist  # 1 / nyq, correctly rounded (see FeatureSpec.numbers)
    n = x.shape[-1]
    x0 = x - jnp.mean(x)
    rms = jnp.maximum(jnp.std(x0), _EPS)
    z = x0 / rms
    log_rms = jnp.log(rms)
    time_feats = [
        log_rms,
        jnp.mean(z**3),
        jnp.log(jnp.mean(z**4) + _EPS),  # a flat-lined sensor: z = 0
        jnp.log(jnp.max(jnp.abs(z)) + _EPS),
        jnp.mean(jnp.signbit(z[1:]) != jnp.signbit(z[:-1])),
        jnp.std(jnp.diff(z)),
    ]
    freqs, power = num.freqs_hz, _power(x)
    edges = jnp.linspace(0.0, nyq, spec.n_bands + 1).at[-1].set(nyq)
    bands = jnp.log(band_energies(freqs, power, edges) + 1e-4)
    total = jnp.maximum(jnp.sum(power), _EPS)
    pn = power / total
    centroid = jnp.sum(freqs * pn)
    flatness = jnp.mean(jnp.log(power + _EPS)) - jnp.log(jnp.mean(power) + _EPS)
    # Spectral shape: spread, entropy, 85 % roll-off, log-log slope, peak over floor.
    spread = jnp.sqrt(jnp.sum((freqs - centroid) ** 2 * pn))
    entropy = -jnp.sum(pn * jnp.log(pn + _EPS)) / jnp.log(pn.shape[0])
    rolloff = freqs[jnp.argmax(jnp.cumsum(pn) >= 0.85)]
    lf = jnp.log(freqs)
    lp = jnp.log(power + 1e-6)
    lfc = lf - jnp.mean(lf)
    slope = jnp.sum(lfc * (lp - jnp.mean(lp))) / jnp.sum(lfc**2)
    resid = jnp.std(lp - jnp.mean(lp) - slope * lfc)
    peak_floor = jnp.log(jnp.max(power) + _EPS) - jnp.log(jnp.median(power) + _EPS)
    shape_feats = [spread * per_nyq, entropy, rolloff * per_nyq, slope, resid, peak_floor]
    # Broadband part: a running median over 5 bins removes narrow lines (the drivetrain's
    # motor tone and harmonics, class-independent) and keeps the terrain's broadband
    # content; its level, its share of the power and its coarse band shape.
    m = power.shape[0]
    padded = jnp.pad(power, 2, mode="edge")
    broad = jnp.median(jnp.stack([padded[i : i + m] for i in range(5)]), axis=0)
    b_total = jnp.maximum(jnp.sum(broad), _EPS)
    b_edges = jnp.linspace(0.0, nyq, spec.n_bands // 2 + 1).at[-1].set(nyq)
    b_bands = jnp.log(band_energies(freqs, broad, b_edges) + 1e-4)
    b_level = log_rms + 0.5 * (jnp.log(b_total) - jnp.log(total))
    broad_feats = [b_level, jnp.log(b_total / total)]
    # Envelope (impacts of joints, bumps, clods) and periodicity (joints every v/spacing).
    env = _envelope(z)
    env_mean = jnp.maximum(jnp.mean(env), _EPS)
    e0 = env - env_mean
    env_ac = _autocorr(e0)
    sig_ac = _autocorr(z)
    lo = jnp.maximum(jnp.round(0.05 * rate_hz), 2)
    lags = jnp.arange(n)
    usable = (lags >= lo) & (lags <= n // 2)
    env_ac_u = jnp.where(usable, env_ac, -jnp.inf)
    env_lag = jnp.argmax(env_ac_u)
    env_feats = [
        jnp.std(env) / env_mean,
        jnp.log(jnp.mean(e0**4) / jnp.maximum(jnp.mean(e0**2) ** 2, _EPS) + _EPS),
        env_ac_u[env_lag],
        env_lag / n,  # lag as a fraction of the window
        jnp.max(jnp.where(usable, jnp.abs(sig_ac), -jnp.inf)),
        env_ac[1],
    ]
    df = num.df_hz
    amps = jnp.concatenate([jnp.zeros(1), jnp.sqrt(power)])  # bin k at k·df again
    pf, pa, pw = spectral_peaks(amps, df, spec.n_peaks)
    peak_feats = jnp.concatenate([pf * per_nyq, jnp.log(pa / jnp.sqrt(total) + 1e-6), pw * per_nyq])
    parts = [
        jnp.stack(time_feats),
        bands,
        jnp.stack([centroid * per_nyq, flatness]),
        jnp.stack(shape_feats),
        jnp.stack(broad_feats),
        b_bands,
        jnp.stack(env_feats),
        peak_feats,
    ]
    zeta_cf, peak_cf = _closed_form_mode(freqs, power, pf[0], pw[0])
    parts.append(jnp.stack([zeta_cf, peak_cf]))
    if spec.modal_fit:
        fd, zeta, amp, floor, ok = fit_resonance(freqs, power, pf[0])
        parts.append(
            jnp.stack([fd * per_nyq, zeta, jnp.log(amp + _EPS) + log_rms,
                       jnp.log(floor + _EPS) - 2 * jnp.log(amp + _EPS), ok.astype(float)])
        )  # fmt: skip
    if spec.octave_bands:
        # Shares of the standardised window's power, times its total and the variance:
        # the raw window's power per octave.
        o_share = band_energies(freqs, power, octave_edges(spec.window, rate_hz, num.df_hz))
        parts.append(jnp.log(o_share + 1e-8) + jnp.log(total) + 2 * log_rms)
    if spec.use_speed:
        v = jnp.asarray(speed_mps, dtype=float)
        s_edges = num.spatial_edges  # host-computed (see FeatureSpec.numbers)
        s_bands = jnp.log(band_energies(freqs / v, power, s_edges) + 1e-4)
        parts.append(s_bands)
        parts.append(jnp.stack([jnp.log(jnp.maximum(pf[0], df) / v),
                                jnp.log(jnp.maximum(centroid, df) / v),
                                log_rms - 2 * jnp.log(v),
                                b_level - 2 * jnp.log(v)]))  # fmt: skip
    return jnp.concatenate(parts)


def window_features(spec: FeatureSpec, x, speed_mps=jnp.nan, numbers: Numbers | None = None):
    """Feature vector of one window for either pipeline.

    ``x`` has shape ``spec.window_shape``: ``(window,)``, or ``(channels, window)`` whose
    channels are featurised alike and concatenated. ``numbers``: as in
    :func:`fitted_features`; with ``spec.deconvolve`` they must carry a whisker.
    """
    if spec.deconvolve or spec.cross_channel:
        return _whisker_features(spec, x, speed_mps, spec.numbers() if numbers is None
                                 else numbers)  # fmt: skip
    if x.ndim == 2:
        return jax.vmap(lambda c: window_features(spec, c, speed_mps, numbers))(x).reshape(-1)
    if spec.kind == "paper":
        return paper_features(x)
    return fitted_features(spec, x, speed_mps, numbers)


def _whisker_features(spec: FeatureSpec, x, speed_mps, num: Numbers):
    """Features with the whisker divided out and/or across channels (see the spec)."""
    xs = x if x.ndim == 2 else x[None]
    plain = replace(
        spec,
        deconvolve=False,
        floor_match=False,
        extend_edges=False,
        cross_channel=False,
        channels=1,
    )
    base = None
    ext = spec.extend_edges
    if spec.deconvolve and spec.floor_match:
        xs = through_filter(xs, num.recolour, ext) + matched_noise(xs, num.dither)
        base = through_filter(xs, num.to_base, ext)
    elif spec.deconvolve:
        xs = through_filter(xs, num.recolour, ext)
        base = through_filter(x if x.ndim == 2 else x[None], num.to_base, ext)
    if spec.kind == "paper":
        return jax.vmap(paper_features)(xs).reshape(-1)
    parts = [jax.vmap(lambda c: fitted_features(plain, c, speed_mps, num))(xs).reshape(-1)]
    if spec.deconvolve:
        edges = octave_edges(spec.window, num.rate_hz, num.df_hz)
        parts.append(base_band_levels(base, num.rate_hz, edges).reshape(-1))
    if spec.cross_channel:
        pair = base if base is not None else xs - jnp.mean(xs, axis=-1, keepdims=True)
        parts.append(_cross_features(pair[0], pair[1]))
    return jnp.concatenate(parts)


def batch_features(structure: FeatureSpec, numbers: Numbers, windows, speeds):
    """Features of windows ``(n, *window_shape)`` with speeds ``(n,)``: traceable, for use
    inside compiled functions (``structure`` from :meth:`FeatureSpec.structure`)."""
    return jax.vmap(lambda w, v: window_features(structure, w, v, numbers))(windows, speeds)


#: Compiled once per spec structure and batch shape.
_batch_features = jax.jit(batch_features, static_argnums=0)


def compute_features(spec: FeatureSpec, windows, speeds=None, numbers: Numbers | None = None
                     ) -> jax.Array:  # fmt: skip
    """Features of a batch of windows, shape ``(n, spec.n_features)`` (float64).

    Args:
        spec: The feature settings.
        windows: Uniformly sampled windows at ``spec.rate_hz``, shape
            ``(n, *spec.window_shape)``.
        speeds: Robot speed per window (m/s); needed when ``spec.use_speed``.
        numbers: The spec's numbers (:meth:`FeatureSpec.numbers`), needed with a whisker
            for ``spec.deconvolve``; the spec's own by default.
    """
    windows = jnp.asarray(windows, dtype=float)
    if windows.shape[1:] != spec.window_shape:
        shape = ", ".join(map(str, ("n", *spec.window_shape)))
        raise ValueError(f"windows must have shape ({shape}), got {windows.shape}")
    if speeds is None:
        if spec.use_speed and spec.kind == "fitted":
            raise ValueError("these features need the robot speed (speed_mps) of each window")
        speeds = jnp.full(windows.shape[0], jnp.nan)
    speeds = jnp.broadcast_to(jnp.asarray(speeds, dtype=float), (windows.shape[0],))
    numbers = spec.numbers() if numbers is None else numbers
    feats = _batch_features(spec.structure(), numbers, windows, speeds)
    if not (spec.kind == "fitted" and spec.window_fit):
        return feats
    return jnp.concatenate([feats, jnp.asarray(window_fit_features(spec, windows))], axis=1)


def window_fit_features(spec: FeatureSpec, windows) -> np.ndarray:
    """The ``window_fit`` part of the features, shape ``(n, channels × 4)`` (zeros for
    a spec without it): per channel, a damped oscillation fitted to each window by
    :func:`whiskerid.fit.fit_windows`. A window whose fit fails gives zeros and ``ok = 0``.
    """
    windows = np.asarray(windows, dtype=float)
    n = windows.shape[0]
    if not (spec.kind == "fitted" and spec.window_fit) or n == 0:
        return np.zeros((n, 0 if not spec.window_fit else spec.channels * N_WINDOW_FIT))
    from ..fit import fit_windows  # the fit package loads only for models that use it

    flat = windows.reshape(-1, spec.window)
    fits = fit_windows(flat, rate_hz=spec.rate_hz)
    ok = np.asarray(fits.ok)
    rms = np.maximum(flat.std(axis=1), _EPS)
    with np.errstate(invalid="ignore", divide="ignore"):
        parts = np.stack([np.asarray(fits.damped_frequency_hz) * 2 / spec.rate_hz,
                          np.asarray(fits.zeta),
                          np.log(np.asarray(fits.amplitude) / rms + _EPS),
                          ok.astype(float)], axis=1)  # fmt: skip
    parts = np.where(ok[:, None] & np.isfinite(parts), parts, 0.0)
    parts[:, 3] = ok
    return parts.reshape(n, -1)
