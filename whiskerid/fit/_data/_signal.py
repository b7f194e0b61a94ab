"""Spectra and spectral peaks of recorded or simulated signals (NumPy; host-side helpers).

Timestamps from a Pi are not uniform; :func:`resample_uniform` puts a signal on a
uniform grid by linear interpolation before any FFT.
"""

import functools
from dataclasses import dataclass

import numpy as np


def line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """``(slope, intercept)`` of the least-squares line through ``(x, y)``, in closed form:
    ``slope = Σ(x − x̄)(y − ȳ) / Σ(x − x̄)²`` (what ``np.polyfit(x, y, 1)`` returns, to
    rounding, without its Vandermonde matrix and SVD: a start search fits several lines per
    recording)."""
    x_mean = x.mean()  # once (it was taken twice: a start search fits several lines a fit)
    xc = x - x_mean
    y_mean = y.mean()
    sxx = float(xc @ xc)
    slope = float(xc @ (y - y_mean)) / sxx if sxx > 0 else 0.0  # one distinct x: flat
    return slope, float(y_mean) - slope * float(x_mean)


def median(x) -> np.floating:
    """``np.median(x)`` of a 1-D float array, the same number to the last bit, in an eighth
    to a half of its time (a warm calibration takes about ten medians; ``np.median``'s
    generic path, for any axis and ``out``, cost 20–40 µs each): the same partition (the two
    middle order statistics, and the last, where a NaN would sort) and the same mean of the
    middle ones, ``(a + b) / 2``, or the middle one alone. Anything else, and data holding
    a NaN, go to ``np.median`` itself."""
    a = np.asarray(x)
    n = a.size
    if a.ndim != 1 or n == 0 or a.dtype.kind != "f":
        return np.median(a)
    h = n // 2
    part = np.partition(a, (h - 1, h, n - 1) if n > 1 else (0,))
    if part[-1] != part[-1]:  # a NaN: np.median's own answer (and warning, if it gives one)
        return np.median(a)
    return part[h] if n % 2 else (part[h - 1] + part[h]) / 2


def resample_uniform(
    t: np.ndarray, x: np.ndarray, rate_hz: float | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Linear interpolation of ``x(t)`` onto a uniform grid.

    Args:
        t: Increasing sample times (s).
        x: Samples.
        rate_hz: Grid rate; the median rate of ``t`` by default.

    Returns:
        ``(t_uniform, x_uniform, rate_hz)``.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if rate_hz is None:
        rate_hz = 1.0 / float(median(np.diff(t)))
    n = int(np.floor((t[-1] - t[0]) * rate_hz)) + 1
    tu = t[0] + np.arange(n) / rate_hz
    return tu, np.interp(tu, t, x), rate_hz


def amplitude_spectrum(
    x: np.ndarray, rate_hz: float, *, window: str = "hann"
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum of a uniformly sampled signal (mean removed).

    A sinusoid of amplitude ``A`` on a bin centre reads ``A``: the window's coherent gain is
    divided out.

    Returns:
        ``(frequencies_hz, amplitudes)``.
    """
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    w, w_sum = spectral_window(x.size, window == "hann")
    spec = np.abs(np.fft.rfft(x * w)) * 2.0 / w_sum
    return np.fft.rfftfreq(x.size, 1.0 / rate_hz), spec


@functools.lru_cache(maxsize=64)
def fast_length(n: int) -> int:
    """The smallest ``m >= n`` whose prime factors are 2, 3 and 5: a length NumPy's FFT
    transforms in ``O(m log m)`` with a small constant (a length with a large prime factor
    goes through Bluestein's algorithm, several times slower)."""
    best = 1 << max(0, (n - 1).bit_length())  # a power of two is always smooth enough
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35  # the smallest power-of-two multiple of p35 that reaches n
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


@functools.lru_cache(maxsize=32)
def spectral_window(n: int, hann: bool) -> tuple[np.ndarray, float]:
    """A Hann (or flat) window of ``n`` samples and its sum, read-only, kept per length: a
    calibration's start search takes two spectra of each recording, its checks a
    periodogram of the recording and Welch segments of the residual, and ``np.hanning``'s
    cosines cost as much as the FFT."""
    w = np.hanning(n) if hann else np.ones(n)
    w.setflags(write=False)
    return w, w.sum()


@dataclass(frozen=True)
class Peak:
    """A spectral peak: interpolated frequency (Hz) and amplitude."""

    frequency_hz: float
    amplitude: float


def find_peaks(
    freqs: np.ndarray,
    amps: np.ndarray,
    *,
    n: int = 3,
    min_separation_hz: float = 0.0,
    min_relative: float = 1e-3,
) -> list[Peak]:
    """The ``n`` largest local maxima, with parabolic sub-bin interpolation (log amplitude).

    Args:
        freqs: Bin frequencies (Hz), uniform.
        amps: Amplitudes per bin.
        n: How many peaks to return at most.
        min_separation_hz: Peaks closer than this to a larger one are dropped.
        min_relative: Peaks below this fraction of the largest peak are dropped (the largest
            local maximum, not the largest bin: a windowed transient or a drift can leave
            more in the lowest bins than in any peak).

    Returns:
        Peaks by decreasing amplitude.
    """
    amps = np.asarray(amps, dtype=float)
    inner = np.arange(1, amps.size - 1)
    is_max = (amps[inner] > amps[inner - 1]) & (amps[inner] >= amps[inner + 1])
    idx = inner[is_max]
    idx = idx[amps[idx] >= min_relative * amps[idx].max()] if idx.size else idx
    idx = idx[np.argsort(amps[idx])[::-1]]
    df = freqs[1] - freqs[0]
    peaks: list[Peak] = []
    for i in idx:
        f, a = _interpolate(amps, i)
        f = freqs[0] + f * df
        if all(abs(f - p.frequency_hz) >= min_separation_hz for p in peaks):
            peaks.append(Peak(float(f), float(a)))
        if len(peaks) == n:
            break
    return peaks


def _interpolate(amps: np.ndarray, i: int) -> tuple[float, float]:
    """Vertex of the parabola through the log amplitudes of bins ``i−1, i, i+1``."""
    y0, y1, y2 = np.log(np.maximum(amps[i - 1 : i + 2], 1e-300))
    denom = y0 - 2 * y1 + y2
    shift = 0.0 if denom == 0 else 0.5 * (y0 - y2) / denom
    return i + shift, float(np.exp(y1 - 0.25 * (y0 - y2) * shift))


def dominant_peaks(
    t: np.ndarray,
    x: np.ndarray,
    *,
    n: int = 3,
    min_separation_hz: float = 2.0,
    min_relative: float = 1e-3,
) -> list[Peak]:
    """Largest spectral peaks of a (possibly non-uniformly) sampled signal.

    Resampled onto a uniform grid at the median rate, Hann-windowed; see :func:`find_peaks`
    for ``n``, ``min_separation_hz`` and ``min_relative``. A short transient (a pluck) has
    window ripple a few per cent of its peak: ask for ``min_relative`` above that.
    """
    _, xu, rate = resample_uniform(t, x)
    freqs, amps = amplitude_spectrum(xu, rate)
    return find_peaks(
        freqs, amps, n=n, min_separation_hz=min_separation_hz, min_relative=min_relative
    )
