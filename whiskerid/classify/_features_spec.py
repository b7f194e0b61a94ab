"""The settings of the feature pipelines (:class:`FeatureSpec`, written into model files)
and their physical numbers (:class:`Numbers`, traced arguments of the compiled features).
"""

from dataclasses import asdict, dataclass, replace
from typing import Literal, NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._choices import FEATURE_KINDS

FeatureKind = Literal["fitted", "paper"]


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
        # The spatial band edges, here too: computed in compiled code from traced ends, the
        # outer ones move by an ulp from model to model, and at the fastest and slowest
        # training speeds the Nyquist and 2Δf bins lie exactly on them.
        edges = jnp.asarray(np.geomspace(self.spatial_lo, self.spatial_hi,
                                         self.n_spatial_bands + 1))  # fmt: skip
        if not self.deconvolve:
            empty = jnp.zeros((0,), dtype=jnp.complex128)
            return Numbers(*plain, empty, empty, jnp.zeros((0,)), edges)
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
            return Numbers(*plain, jnp.asarray(recolour), jnp.asarray(base), jnp.zeros((0,)),
                           edges)  # fmt: skip
        # the base motion is read from the recoloured window, floor matched
        base = reference.to_base(padded, self.rate_hz)
        dither = whisker.dither(reference, padded, self.rate_hz)
        return Numbers(*plain, jnp.asarray(recolour), jnp.asarray(base), jnp.asarray(dither),
                       edges)  # fmt: skip


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
    spatial_edges: Float[Array, " edges"]  # log-spaced, spatial_lo to spatial_hi (cycles/m)


#: Window-fit features per channel: damped frequency, ζ, log amplitude, ok.
N_WINDOW_FIT = 4
#: Cross-channel features: coherence in four bands, ellipse (cos 2θ, sin 2θ, axis ratio),
#: log power ratio.
N_CROSS = 8
_DEFAULT = FeatureSpec()
