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

from dataclasses import asdict, dataclass, replace
from functools import partial
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._choices import FEATURE_KINDS

FeatureKind = Literal["fitted", "paper"]
_EPS = 1e-12


@dataclass(frozen=True)
class FeatureSpec:
    """What features to compute, for windows of ``window`` samples at ``rate_hz``.

    Attributes:
        kind: ``fitted`` or ``paper``.
        rate_hz: Sample rate of the windows (Hz).
        window: Samples per window.
        n_bands: Equal-width bands from 0 to Nyquist (fitted).
        n_peaks: Spectral peaks reported (dominant first) (fitted).
        modal_fit: Fit a resonance per window (fitted).
        octave_bands: Add absolute log power in octave bands (fitted). False by default
            so that model files written before it existed keep their features;
            :func:`whiskerid.train_classifier` turns it on when the speed is known.
        use_speed: Add speed-normalised features; windows then need a speed (fitted).
        n_spatial_bands: Log-spaced spatial-frequency bands (fitted, with speed).
        spatial_lo: Lowest spatial frequency (cycles/m).
        spatial_hi: Highest spatial frequency (cycles/m).
        channels: Signals per window (e.g. six IMU axes); each channel gets the same
            features and the vectors are concatenated, channel by channel.
        deconvolve: Whisker-aware: each window is first put through the whisker's own
            transfer function (:class:`WhiskerResponse`), recoloured to the model's
            reference whisker, and (fitted) the base-motion band levels in dB are added
            per channel. The numbers then need a whisker (:meth:`numbers`).
        cross_channel: Add features of the two channels together (fitted, two channels):
            coherence in four bands, orientation (``cos 2θ``, ``sin 2θ``) and axis ratio of
            the motion ellipse, and the log power ratio of the channels.
        window_fit: Add, per channel, a damped oscillation fitted to the window in the
            time domain (:func:`whiskerid.fit.fit_windows`, all windows at once): its damped
            frequency (over Nyquist), ζ, log amplitude over the window's RMS and the fit's
            ``ok`` flag (fitted). Computed on the host, next to the compiled features.
        floor_match: With ``deconvolve``: raise every window's noise floor, recoloured to
            the reference whisker, to the level the average whisker of a span around the
            reference would give it (:meth:`WhiskerResponse.floor_gain`), by adding noise
            shaped to make up the difference (seeded by the window's content, so the
            features stay a function of the window). A recording of another whisker,
            recoloured, has its floor (ADC noise, quantisation, the error of timestamp
            jitter) raised wherever it responds more weakly than the reference; with the
            floor matched, training and use see the same floor.
        extend_edges: With ``deconvolve``: filter each window extended at both ends by
            half a window of its own continuation (a linear predictor fitted to it,
            :func:`extend_window`), tapered to zero, instead of by zeros. A zero-extended
            window steps at its edges, and dividing out a whisker (a second derivative
            around its resonance) turns the steps into spikes that the reference
            whisker's resonance rings: they raise the envelope's kurtosis, the crest
            factor and the high bands of every window of another whisker, never of the
            training whisker's own (recoloured to itself by the identity). False by
            default so that model files written before it existed keep their features;
            :func:`whiskerid.train_classifier` turns it on.
        alias_slope: With ``deconvolve``: the weight ``(f/f_m)^α`` of a bin's aliases in
            the whiskers' transfer functions (:attr:`WhiskerResponse.alias_slope`). 0, the
            base motion flat across the aliases, by default so that model files written
            before it existed keep their features; :func:`whiskerid.train_classifier` sets
            :data:`whiskerid.classify.ALIAS_SLOPE`.
    """

    kind: FeatureKind = "fitted"
    rate_hz: float = 200.0
    window: int = 200
    n_bands: int = 16
    n_peaks: int = 3
    modal_fit: bool = False
    octave_bands: bool = False
    use_speed: bool = False
    n_spatial_bands: int = 10
    spatial_lo: float = 10.0
    spatial_hi: float = 330.0
    channels: int = 1
    deconvolve: bool = False
    cross_channel: bool = False
    window_fit: bool = False
    floor_match: bool = False
    extend_edges: bool = False
    alias_slope: float = 0.0

    def __post_init__(self):
        if self.kind not in FEATURE_KINDS:
            raise ValueError(
                f"features must be one of {', '.join(FEATURE_KINDS)}; got {self.kind!r}"
            )
        if self.window < 16:
            raise ValueError(f"a window needs at least 16 samples, not {self.window}")
        if not self.rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, not {self.rate_hz!r}")
        if not 0 < self.spatial_lo < self.spatial_hi:
            raise ValueError("need 0 < spatial_lo < spatial_hi")
        if self.channels < 1:
            raise ValueError(f"channels must be at least 1, not {self.channels}")
        if self.deconvolve and self.channels > 2:
            raise ValueError("whisker-aware features take one or two Hall sensors, "
                             f"not {self.channels} channels")  # fmt: skip
        if self.floor_match and not self.deconvolve:
            raise ValueError("floor_match needs whisker-aware features (deconvolve)")
        if self.extend_edges and not self.deconvolve:
            raise ValueError("extend_edges needs whisker-aware features (deconvolve)")
        if not (np.isfinite(self.alias_slope) and self.alias_slope >= 0):
            raise ValueError(f"alias_slope must be a number ≥ 0, not {self.alias_slope!r}")
        if self.cross_channel and self.channels != 2:
            raise ValueError("cross-channel features need exactly two channels")

    @property
    def n_features(self) -> int:
        """Length of the feature vector (all channels)."""
        n = self.channels * self._per_channel()
        if self.kind == "fitted" and self.deconvolve:
            n += self.channels * (len(self.octave_edges()) - 1)
        n += N_CROSS if self.kind == "fitted" and self.cross_channel else 0
        return n + (self.channels * N_WINDOW_FIT if self.kind == "fitted" and self.window_fit
                    else 0)  # fmt: skip

    @property
    def window_shape(self) -> tuple[int, ...]:
        """Shape of one window: ``(window,)``, or ``(channels, window)``."""
        return (self.window,) if self.channels == 1 else (self.channels, self.window)

    def _per_channel(self) -> int:
        if self.kind == "paper":
            return self.window
        n = 6 + self.n_bands + 2 + 6 + 2 + self.n_bands // 2 + 6 + 3 * self.n_peaks + 2
        n += 5 if self.modal_fit else 0
        n += len(self.octave_edges()) - 1 if self.octave_bands else 0
        return n + (self.n_spatial_bands + 4 if self.use_speed else 0)

    def octave_edges(self) -> tuple[float, ...]:
        """Edges (Hz) of the octave bands: ``Δf, 2Δf, 4Δf, …``, closed at Nyquist."""
        df, nyq = self.rate_hz / self.window, self.rate_hz / 2
        edges = [df]
        while 2 * edges[-1] < nyq * (1 - 1e-9):
            edges.append(2 * edges[-1])
        return (*edges, nyq)

    def to_dict(self) -> dict:
        """JSON-able form (model files)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "FeatureSpec":
        """Inverse of :meth:`to_dict`; unknown keys are refused."""
        known = set(cls.__dataclass_fields__)
        extra = set(d) - known
        if extra:
            raise ValueError(f"unknown feature settings {sorted(extra)}")
        return cls(**d)

    def structure(self) -> "FeatureSpec":
        """This spec with its physical numbers (:class:`Numbers`) set to the defaults: what
        a compiled feature function depends on, and its cache key."""
        return replace(self, rate_hz=_DEFAULT.rate_hz, spatial_lo=_DEFAULT.spatial_lo,
                       spatial_hi=_DEFAULT.spatial_hi,
                       alias_slope=_DEFAULT.alias_slope)  # fmt: skip

    def numbers(self, whisker=None, reference=None) -> "Numbers":
        """The physical numbers of this spec, as float64 arrays (traced when jitted).

        The bin frequencies and spacing and the reciprocal of Nyquist are computed here, on
        the host, with correctly rounded divisions: compiled code divides by a traced
        number through an inexact reciprocal, and the features would move in their last
        digit against those of a spec whose numbers are constants.

        Args:
            whisker: The :class:`WhiskerResponse` that recorded the windows; needed when
                ``deconvolve``.
            reference: The whisker the windows are recoloured to (a model's training
                whisker); ``whisker`` by default.
        """
        n = self.window
        freqs = np.arange(n // 2 + 1, dtype=np.float64) / np.float64(1.0 / self.rate_hz * n)
        values = (self.rate_hz, self.rate_hz / n, freqs[1:], 2.0 / self.rate_hz,
                  self.spatial_lo, self.spatial_hi)  # fmt: skip
        plain = [jnp.asarray(v, dtype=jnp.float64) for v in values]
        if not self.deconvolve:
            empty = jnp.zeros((0,), dtype=jnp.complex128)
            return Numbers(*plain, empty, empty, jnp.zeros((0,)))
        if whisker is None:
            raise ValueError(
                "whisker-aware features need the whisker that recorded the windows (a "
                "calibrated whisker record)"
            )
        reference = whisker if reference is None else reference
        whisker = replace(whisker, alias_slope=self.alias_slope)
        reference = replace(reference, alias_slope=self.alias_slope)
        padded = np.fft.rfftfreq(2 * n, 1.0 / self.rate_hz)
        recolour = whisker.recolour(reference, padded, self.rate_hz)
        if not self.floor_match:
            base = whisker.to_base(padded, self.rate_hz)
            return Numbers(*plain, jnp.asarray(recolour), jnp.asarray(base), jnp.zeros((0,)))
        # the base motion is read from the recoloured window, floor matched
        base = reference.to_base(padded, self.rate_hz)
        dither = whisker.dither(reference, padded, self.rate_hz)
        return Numbers(*plain, jnp.asarray(recolour), jnp.asarray(base), jnp.asarray(dither))


class Numbers(NamedTuple):
    """The physical numbers of a :class:`FeatureSpec`: no shape depends on them, so they
    are traced arguments of the compiled feature functions, not compile-time constants."""

    rate_hz: Float[Array, ""]
    df_hz: Float[Array, ""]
    freqs_hz: Float[Array, " bins"]
    per_nyquist: Float[Array, ""]
    spatial_lo: Float[Array, ""]
    spatial_hi: Float[Array, ""]
    recolour: Array  # (bins of a 2×window FFT, channels, channels), complex; empty if unused
    to_base: Array  # the same shape: codes to base acceleration (m/s²)
    dither: Array  # (bins of a 2×window FFT, channels): floor-matching noise; empty if unused


#: Window-fit features per channel: damped frequency, ζ, log amplitude, ok.
N_WINDOW_FIT = 4
#: Cross-channel features: coherence in four bands, ellipse (cos 2θ, sin 2θ, axis ratio),
#: log power ratio.
N_CROSS = 8
_COHERENCE_BANDS = 4
_DEFAULT = FeatureSpec()


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
        s_edges = jnp.geomspace(num.spatial_lo, num.spatial_hi, spec.n_spatial_bands + 1)
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


def through_filter(xs, response, extend: bool = False):
    """Windows ``(channels, n)`` through a per-bin channel matrix ``(bins, ch, ch)`` given
    on the grid of a ``2n``-point FFT. The channels' means are removed first.

    Args:
        xs: The windows.
        response: The filter, per bin.
        extend: Extend each window by half a window of its own continuation at each
            end, tapered to zero (:func:`extend_window`), and keep the filtered middle; else
            pad with zeros (a linear, not circular, filter of the window alone, which
            steps at the window's edges).
    """
    n = xs.shape[-1]
    x = xs - jnp.mean(xs, axis=-1, keepdims=True)
    lead = n // 2 if extend else 0
    x = extend_window(x) if extend else x
    spec = jnp.fft.rfft(x, 2 * n, axis=-1)
    y = jnp.fft.irfft(jnp.einsum("bij,jb->ib", response, spec), 2 * n, axis=-1)
    return y[:, lead : lead + n]


#: Order of the linear predictor that extends a window at its edges (:func:`extend_window`):
#: a few resonances' worth of poles.
EXTEND_ORDER = 12
#: Its ridge, relative to the mean diagonal of the normal equations: keeps the predictor's
#: poles inside the unit circle on noisy windows.
EXTEND_RIDGE = 1e-3


def extend_window(x) -> jax.Array:
    """Windows ``(channels, n)`` (zero mean) with ``m = n // 2`` samples added at each end,
    shape ``(channels, n + 2m)``: each channel's continuation by a linear predictor of
    order :data:`EXTEND_ORDER` fitted to the window itself (forward and backward, least
    squares with a ridge), clipped to the window's largest magnitude and tapered to zero
    by a half cosine. A whisker's window is a few lightly damped resonances, which such a
    predictor carries on across the edge; through a ``2n``-point circular filter the
    joins of the extension lie half a window from the window, where filters of a
    whisker's response have rung down."""
    n = x.shape[-1]
    m, p = n // 2, min(EXTEND_ORDER, n // 4)
    lags = jnp.arange(1, p + 1)[None, :]
    fwd_rows = jnp.arange(p, n)[:, None] - lags  # x[t] from x[t−1] … x[t−p]
    bwd_rows = jnp.arange(0, n - p)[:, None] + lags  # x[t] from x[t+1] … x[t+p]
    taper = 0.5 * (1 + jnp.cos(jnp.pi * jnp.arange(1, m + 1) / (m + 1)))  # 1 → 0

    def one(c):
        a_mat = jnp.concatenate([c[fwd_rows], c[bwd_rows]])
        b_vec = jnp.concatenate([c[p:], c[: n - p]])
        gram = a_mat.T @ a_mat
        ridge = EXTEND_RIDGE * jnp.trace(gram) / p + _EPS
        coef = jnp.linalg.solve(gram + ridge * jnp.eye(p), a_mat.T @ b_vec)

        def step(state, _):
            nxt = state @ coef
            return jnp.concatenate([nxt[None], state[:-1]]), nxt

        _, after = jax.lax.scan(step, c[::-1][:p], None, length=m)
        _, before = jax.lax.scan(step, c[:p], None, length=m)
        lim = jnp.max(jnp.abs(c))
        after, before = jnp.clip(after, -lim, lim), jnp.clip(before, -lim, lim)
        return jnp.concatenate([(before * taper)[::-1], c, after * taper])

    return jax.vmap(one)(x)


def base_band_levels(base, rate_hz, edges) -> jax.Array:
    """Mean-square base acceleration in each band ``[edges[k], edges[k+1])`` in dB re
    1 (m/s²)²: the Hann-windowed periodogram summed over the band's bins (``base``:
    samples on the last axis)."""
    n = base.shape[-1]
    w = jnp.hanning(n)
    x = base - jnp.mean(base, axis=-1, keepdims=True)
    spec = jnp.fft.rfft(x * w, axis=-1)
    power = 2 * jnp.abs(spec) ** 2 / (jnp.sum(w**2) * n)  # mean square per bin
    f = jnp.fft.rfftfreq(n, 1.0 / rate_hz)
    inside = (f[None, :] >= edges[:-1, None]) & (f[None, :] < edges[1:, None])
    inside = inside.at[-1].set(inside[-1] | (f == edges[-1]))
    return 10 * jnp.log10(power @ inside.T.astype(power.dtype) + 1e-20)


def rerecorded(windows, response, floor_shape, *, extend: bool, seed: int) -> np.ndarray:
    """Windows ``(n, *window_shape)`` as another whisker would have recorded the same base
    motion (:meth:`WhiskerResponse.rerecord`): each through ``response`` (per bin of a
    ``2 × window``-point FFT, ``(bins, channels, channels)``; ``extend`` as in
    :func:`through_filter`), plus white noise shaped by ``floor_shape`` (``(bins,
    channels)``) times the window's own floor (:func:`noise_floor`), drawn from ``seed``.
    """
    x = jnp.asarray(windows, dtype=float)
    many = x if x.ndim == 3 else x[:, None]
    key = jax.random.PRNGKey(seed)
    out = _rerecorded(many, jnp.asarray(response), jnp.asarray(floor_shape), extend, key)
    return np.asarray(out if x.ndim == 3 else out[:, 0])


@partial(jax.jit, static_argnums=3)
def _rerecorded(xs, response, floor_shape, extend, key):
    n = xs.shape[-1]
    filtered = jax.vmap(lambda w: through_filter(w, response, extend))(xs)
    white = jax.random.normal(key, (*xs.shape[:-1], 2 * n), dtype=xs.dtype)
    shaped = jnp.fft.irfft(jnp.fft.rfft(white, axis=-1) * floor_shape.T, 2 * n, axis=-1)
    return filtered + shaped[..., :n] * jnp.sqrt(jax.vmap(noise_floor)(xs))[..., None]


#: Percentile of a window's own power spectrum taken as its noise floor: most bins of a
#: whisker's window hold the resonance, the texture or the drivetrain; the quietest fifth
#: holds little but the floor.
FLOOR_PERCENTILE = 20.0


def noise_floor(xs) -> jax.Array:
    """Per channel, the noise floor of windows ``(channels, n)`` as a per-sample variance
    (codes²): the :data:`FLOOR_PERCENTILE` th percentile of the Hann-windowed power
    spectrum (bins 1 … n/2, normalised so that white noise reads its variance), divided by
    that percentile of the exponential distribution a noise bin's power follows, so that
    white noise reads its variance."""
    n = xs.shape[-1]
    w = jnp.hanning(n)
    x = xs - jnp.mean(xs, axis=-1, keepdims=True)
    power = jnp.abs(jnp.fft.rfft(x * w, axis=-1)) ** 2 / jnp.sum(w**2)
    quantile = -np.log1p(-FLOOR_PERCENTILE / 100)
    return jnp.percentile(power[:, 1:], FLOOR_PERCENTILE, axis=-1) / quantile


def matched_noise(xs, dither) -> jax.Array:
    """Noise that lifts the floor of windows ``(channels, n)`` by ``dither²`` times their
    own floor (:func:`noise_floor`), shaped per bin of a ``2n``-point FFT. Seeded by the
    window's content: the same window always gets the same noise."""
    n = xs.shape[-1]
    seed = jax.lax.bitcast_convert_type(jnp.sum(xs).astype(jnp.float32), jnp.uint32)
    key = jax.random.fold_in(jax.random.PRNGKey(0), seed)
    white = jax.random.normal(key, (xs.shape[0], 2 * n), dtype=xs.dtype)
    shaped = jnp.fft.irfft(jnp.fft.rfft(white, axis=-1) * dither.T, 2 * n, axis=-1)[:, :n]
    return shaped * jnp.sqrt(noise_floor(xs))[:, None]


def _cross_features(a, b):
    """Coherence in four equal bands (Welch within the window), the motion ellipse and the
    log power ratio of two zero-mean channels."""
    n = a.shape[-1]
    seg = max(n // 4, 8)
    hop = seg // 2
    starts = range(0, n - seg + 1, hop)
    w = jnp.hanning(seg)
    fa = jnp.stack([jnp.fft.rfft(a[s : s + seg] * w) for s in starts])
    fb = jnp.stack([jnp.fft.rfft(b[s : s + seg] * w) for s in starts])
    saa = jnp.mean(jnp.abs(fa) ** 2, axis=0)[1:]
    sbb = jnp.mean(jnp.abs(fb) ** 2, axis=0)[1:]
    sab = jnp.mean(fa * jnp.conj(fb), axis=0)[1:]
    coh = jnp.abs(sab) ** 2 / jnp.maximum(saa * sbb, _EPS)
    weight = saa + sbb
    bands = jnp.array_split(jnp.arange(coh.shape[0]), _COHERENCE_BANDS)
    coh_b = [jnp.sum(coh[i] * weight[i]) / jnp.maximum(jnp.sum(weight[i]), _EPS) for i in bands]
    caa, cbb, cab = jnp.mean(a * a), jnp.mean(b * b), jnp.mean(a * b)
    two_theta = jnp.arctan2(2 * cab, caa - cbb)
    root = jnp.sqrt((caa - cbb) ** 2 + 4 * cab**2)
    big, small = 0.5 * (caa + cbb + root), 0.5 * (caa + cbb - root)
    ratio = jnp.sqrt(jnp.maximum(small, 0.0) / jnp.maximum(big, _EPS))
    power_ratio = jnp.log(caa + _EPS) - jnp.log(cbb + _EPS)
    return jnp.stack([*coh_b, jnp.cos(two_theta), jnp.sin(two_theta), ratio, power_ratio])


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
