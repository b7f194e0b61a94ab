"""Does a window show the whisker's resonance? The mode check of :func:`window_health`.

A whisker dragged over ground is a base-excited resonator: whatever the ground's spectrum,
the response is that spectrum times the whisker's transfer function, which stands out at its
first mode ``f1`` (tens of times its neighbourhood for ζ of a few per cent). A dead sensor's
electrical noise, white or gently coloured by the ADC's filter, has no such line: its
periodogram near ``f1`` is as high as around it.

The statistic is the **mode prominence**: ``log10`` of the mean periodogram (Hann taper,
mean removed) in a band of ±:data:`MODE_HALF_WIDTH` × ``f1`` (at least :data:`MIN_BINS`
bins) over the median periodogram of the *local floor*, the bins from ``f1/2`` to ``2 f1``
(capped at Nyquist) outside twice that band. For white noise the ratio is about
``1/ln 2`` (log10 ≈ 0.16): a mean of exponential bins over their median. The threshold is
the white-noise quantile :data:`MODE_QUANTILE` of the statistic for the window length, the
rate and the modes (Monte Carlo, fixed seed), so one noise window in a thousand passes it;
a window below it in every channel shows no response near the modes.

The modes are the calibrated whisker's where the model has one (the peak of its sampled
transfer function, aliases included), else the frequencies where the training windows'
median prominence is highest (their resonance, found from the data: :func:`training_modes`).
"""

import functools

import numpy as np

#: One white-noise window in 1/(1 − this) reaches the threshold.
MODE_QUANTILE = 0.999
#: Half-width of the band around a mode, as a share of its frequency (a whisker in contact
#: with the ground rings a little higher; another whisker of the span, a little lower).
MODE_HALF_WIDTH = 0.15
#: The band is at least this many bins either side of the mode (a Hann main lobe is 2).
MIN_BINS = 3
#: Frequencies whose training prominence is within this (log10) of the highest are modes.
MODE_SPREAD = 0.3
#: At most this many modes are found in training windows.
MAX_MODES = 4
#: A local floor of fewer bins is too noisy: the whole spectrum outside the band is used.
MIN_FLOOR_BINS = 8


def _masks(n: int, rate_hz: float, f: float) -> tuple[np.ndarray, np.ndarray]:
    """Band and local-floor masks over the ``rfft`` bins of ``n`` samples (DC excluded)."""
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    half = max(MODE_HALF_WIDTH * f, MIN_BINS * rate_hz / n)
    near = np.abs(freqs - f)
    band = (near <= half) & (freqs > 0)
    floor = (freqs >= f / 2) & (freqs <= 2 * f) & (near > 2 * half) & (freqs > 0)
    if floor.sum() < MIN_FLOOR_BINS:
        floor = (near > half) & (freqs > 0)
    return band, floor


def _periodogram(windows) -> np.ndarray:
    w = np.asarray(windows, dtype=float)
    d = w - w.mean(axis=-1, keepdims=True)
    return np.abs(np.fft.rfft(d * np.hanning(w.shape[-1]), axis=-1)) ** 2


def mode_prominence(windows, rate_hz: float, modes_hz) -> np.ndarray:
    """The highest prominence over ``modes_hz`` of each window and channel.

    Args:
        windows: ``(n, window)`` or ``(n, channels, window)``.
        rate_hz: Sample rate (Hz).
        modes_hz: Mode frequencies (Hz), each between DC and Nyquist.

    Returns:
        log10 band mean over floor median, shape ``(n, channels)``.
    """
    p = _periodogram(windows)
    return _prominence(p[:, None, :] if p.ndim == 2 else p, np.shape(windows)[-1], rate_hz,
                       modes_hz)  # fmt: skip


def _prominence(p: np.ndarray, n: int, rate_hz: float, modes_hz) -> np.ndarray:
    """:func:`mode_prominence` of periodograms ``(n, channels, bins)``."""
    tiny = np.finfo(float).tiny
    best = np.full(p.shape[:2], -np.inf)
    for f in modes_hz:
        band, floor = _masks(n, rate_hz, float(f))
        ratio = p[..., band].mean(-1) / (np.median(p[..., floor], axis=-1) + tiny)
        best = np.maximum(best, np.log10(ratio + tiny))
    return best


@functools.lru_cache(maxsize=16)
def _white(n: int, rate_hz: float, modes_hz: tuple[float, ...]) -> np.ndarray:
    """The prominence of 20 000 white-noise windows of ``n`` samples (fixed seed), sorted."""
    x = np.random.default_rng(1).standard_normal((20_000, n))
    return np.sort(mode_prominence(x, rate_hz, modes_hz)[:, 0])


def white_prominence(n: int, rate_hz: float, modes_hz: tuple[float, ...]) -> float:
    """The prominence that all but ``1 − MODE_QUANTILE`` of white-noise windows of ``n``
    samples stay below (about 0.7 for one mode at 46 Hz in 200 samples at 200 Hz, where
    the mean is about 0.16)."""
    return float(np.quantile(_white(n, rate_hz, tuple(modes_hz)), MODE_QUANTILE))


def white_detection(n: int, rate_hz: float, modes_hz: tuple[float, ...], floor: float) -> float:
    """Share of white-noise windows of ``n`` samples whose prominence is below ``floor``."""
    w = _white(n, rate_hz, tuple(modes_hz))
    return float(np.searchsorted(w, floor) / w.size)


def training_modes(windows, rate_hz: float) -> tuple[float, ...]:
    """Where the training windows (first channel) show their resonance: the frequencies
    (Hz) whose median prominence is within :data:`MODE_SPREAD` of the highest, thinned to
    one per band (at most :data:`MAX_MODES`), for when no calibrated whisker says where it
    is. One whisker gives one or two; recordings of several whiskers, a mode each."""
    w = np.asarray(windows, dtype=float)
    w = w[:, 0] if w.ndim == 3 else w
    n = w.shape[-1]
    df = rate_hz / n
    cand = np.arange(MIN_BINS + 1, n // 2 - MIN_BINS) * df
    if cand.size == 0:
        return (rate_hz / 4,)
    p = _periodogram(w)[:, None, :]
    score = np.array([np.median(_prominence(p, n, rate_hz, (f,))) for f in cand])
    modes: list[float] = []
    for k in np.argsort(score)[::-1]:
        if score[k] < score.max() - MODE_SPREAD or len(modes) == MAX_MODES:
            break
        f = float(cand[k])
        if all(abs(f - m) > MODE_HALF_WIDTH * max(f, m) for m in modes):
            modes.append(f)
    return tuple(sorted(modes))


def whisker_mode(whisker, rate_hz: float, window: int) -> float:
    """The frequency (Hz) below Nyquist where the whisker's sampled transfer function (first
    sensor, aliases folded in) peaks: where its recordings show it. Evaluated on the bins
    the whisker-aware features use (``2 × window`` samples), so nothing new is compiled."""
    freqs = np.fft.rfftfreq(2 * int(window), 1.0 / rate_hz)[1:]
    t = np.abs(np.asarray(whisker.transfer(freqs, rate_hz))[:, 0, 0])
    return float(freqs[int(np.argmax(t))])


def gain_ratio(other, own, rate_hz: float, window: int) -> float:
    """How much larger ``other``'s windows are than ``own``'s for the same ground: the
    ratio of the RMS of their sampled transfer functions (first sensor, amplifiers
    included) over the bins the features use, a flat base spectrum assumed (the amplitude
    range it scales is wide: :data:`whiskerid.io._health.RMS_MARGIN`)."""
    freqs = np.fft.rfftfreq(2 * int(window), 1.0 / rate_hz)[1:]
    t_other = np.abs(np.asarray(other.transfer(freqs, rate_hz))[:, 0, 0])
    t_own = np.abs(np.asarray(own.transfer(freqs, rate_hz))[:, 0, 0])
    return float(np.sqrt(np.sum(t_other**2) / np.sum(t_own**2)))
