"""Which line rings in a recording: its strongest line (of the first difference), the lowest
strong line a release is searched at, and the samples' scale, resolution and clipped runs.

:mod:`._release` finds decays at the line chosen here; :func:`steady_line` reads it too.
"""

import numpy as np

from ._signal import _interpolate


def normalised_samples(y) -> np.ndarray | None:
    """``y`` scaled by a power of two (exactly, so equal samples stay equal and a
    converter's steps stay uniform) to at most 1 in magnitude; None if it is not finite.
    Every threshold of the detector is relative, so its answer does not depend on the
    units; the scaling keeps squares and variances of a huge signal (volts × 1e300) finite.
    """
    y = np.asarray(y, dtype=float)
    if y.size == 0 or not np.all(np.isfinite(y)):
        return None
    peak = float(np.max(np.abs(y)))
    if peak == 0.0:
        return y.copy()
    return np.ldexp(y, -int(np.frexp(peak)[1]))


def dominant_frequency(t: np.ndarray, y: np.ndarray) -> float | None:
    """Frequency (Hz) of the largest spectral peak away from DC, interpolated; None if flat.

    The spectrum is that of the first difference, which weights a line by its frequency: a
    hold, a bend or a drift puts most of its power at low frequencies, where it would
    otherwise beat the ringing. The difference also lifts white noise towards Nyquist, and
    a short, strongly damped decay in a long quiet record spreads its energy thinly over
    the whole record's spectrum. So when the whole record's largest peak does not stand
    clear of white noise's expected level (from the record's own noise), its halves,
    quarters, ... (down to 64 samples) are searched, and the peak that stands clearest there
    wins; where none does, the whole record's largest. (Only then: in a short stretch a
    bend or a release step can stand out as a low "line" that is not a ringing.)
    """
    n = y.size
    if n < 16 or not (np.all(np.isfinite(y)) and np.all(np.isfinite(t))):
        return None
    dt = float(np.median(np.diff(t)))
    d = np.diff(np.interp(t[0] + dt * np.arange(n), t, y))  # uniform grid for the FFT
    # white noise of σ has a first difference of √2 σ: its level from the median, so that
    # the ringing (however long) does not count as noise
    sigma = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2.0)
    # never below a converter's rounding (a quiet stretch can sit on one code)
    sigma = max(sigma, 2.0 * quantum(y) / np.sqrt(12.0))
    # padded by half its length on each side: a decay at the record's very start (or end)
    # is then not under the window's taper
    (f,), (snr,) = _clearest_peaks(np.pad(d, d.size // 2)[None], dt, sigma, d.size * dt)
    if not np.isfinite(f):
        return None
    m = d.size // 2
    while snr < _CLEAR and m >= 64:
        stretches = np.lib.stride_tricks.sliding_window_view(np.pad(d, m // 2), m)[:: m // 2]
        fs, ss = _clearest_peaks(stretches, dt, sigma)
        k = int(np.argmax(ss))
        if ss[k] >= _CLEAR and ss[k] > snr:
            f, snr = fs[k], ss[k]
        m //= 2
    return float(f)


#: A spectral peak this many times the noise's expected amplitude is a line, not noise.
_CLEAR = 5.0


def _clearest_peaks(d, dt, sigma, span_s=None):
    """For each row of ``d`` (stretches of a first difference): the largest peak of its
    windowed spectrum, interpolated, and its ratio to white noise's expected level there;
    the largest *clear* peak (ratio ≥ 5) if the largest is not. NaN and 0 for a flat row.
    ``span_s``: the signal's own length in a zero-padded row (the row's length if None)."""
    rows, n = d.shape
    window = np.hanning(n)
    spec = np.abs(np.fft.rfft((d - d.mean(axis=1, keepdims=True)) * window, axis=1))
    freqs = np.fft.rfftfreq(n, dt)
    span_s = n * dt if span_s is None else span_s
    spec[:, freqs < max(3.0 / span_s, 1.0)] = 0.0  # below: drift and holds, not ringing
    floor = sigma * np.sqrt(2.0 * np.sum(window**2)) * np.abs(np.sin(np.pi * freqs * dt))
    ratio = spec / np.maximum(floor, 1e-300)
    clear = ratio >= _CLEAR
    top = np.argmax(spec, axis=1)
    top_clear = np.argmax(np.where(clear, spec, 0.0), axis=1)
    r = np.arange(rows)
    i = np.where(~clear[r, top] & clear.any(axis=1), top_clear, top)
    f = np.full(rows, np.nan)
    snr = np.zeros(rows)
    for j in np.flatnonzero(spec[r, i] > 0):
        k = i[j]
        f[j] = (_interpolate(spec[j], k)[0] if 0 < k < spec.shape[1] - 1 else k) / (n * dt)
        snr[j] = ratio[j, k]
    return f, snr


def clipped_mask(y: np.ndarray, *, min_run: int = 2) -> np.ndarray:
    """Samples at the record's extreme values in runs of at least ``min_run``, or at an
    extreme met three times or more by a signal that spans many converter steps: a
    converter's rails. A ringing signal passes its extremes once; clipping holds them (and at
    a few samples per period, a clipped ringing meets the rail once per period)."""
    mask = np.zeros(y.size, bool)
    q = max(quantum(y), 1e-300)
    for extreme in (np.max(y), np.min(y)):
        at = y == extreme
        if np.count_nonzero(at) < min_run or np.all(at):
            continue
        # the level of the rest of the record (a long hold at the rail is most of it)
        median = float(np.median(y[~at]))
        if np.count_nonzero(at) >= 3 and abs(extreme - median) > 100 * q:
            mask |= at
            continue
        # runs of the extreme: where ``at`` switches on and off
        edges = np.flatnonzero(np.diff(np.concatenate([[0], at.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start >= min_run:
                mask[start:stop] = True
    return mask


def quantum(y: np.ndarray) -> float:
    """Half the smallest step between distinct sample values (a converter's resolution
    shows as one; continuous data give a negligible one)."""
    steps = np.diff(np.unique(y))
    return 0.5 * float(steps.min()) if steps.size else 0.0


def lowest_strong_line(t: np.ndarray, y: np.ndarray, f: float) -> float:
    """The frequency (Hz) that decays are searched at: ``f`` (the first difference's
    strongest line, :func:`dominant_frequency`), or a lower line that is stronger in the
    signal itself.

    The first difference weights a line by its frequency, so a higher mode (the second
    bending mode at 6.27 f_1 in an accelerometer's record, or a clamp's rattle ringing at
    hundreds of hertz once a period) can win it while the whisker's motion is the first
    mode's. A higher mode decays faster and is struck again by every rattle, so decays
    searched at it split one release into dozens. A lower line wins when it is a *line*
    (a local maximum of the windowed spectrum standing three times above the spectrum's
    median within ±25 % of its frequency: a hold's step or a drift rises smoothly towards
    DC and has none), rings at least 32 cycles over the record, and is larger there than
    the spectrum at ``f``.
    """
    n = y.size
    dt = float(np.median(np.diff(t)))
    span = n * dt
    u = np.interp(t[0] + dt * np.arange(n), t, y)
    x = np.arange(n, dtype=float)
    u = u - np.polyval(np.polyfit(x, u, 1), x)
    spec = np.abs(np.fft.rfft(u * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, dt)
    k_f = int(np.argmin(np.abs(freqs - f)))
    at_f = float(np.max(spec[max(0, k_f - 1) : k_f + 2]))
    # at least 32 cycles in the record, so that ±25 % of a line's frequency spans 16 bins
    # of the spectrum (in a short record a hold's step or a tremor makes "peaks" of a few)
    cand = np.flatnonzero((freqs >= max(32.0 / span, 1.0)) & (freqs < f / 1.5))
    cand = cand[(cand > 0) & (cand < spec.size - 1)]
    cand = cand[(spec[cand] >= spec[cand - 1]) & (spec[cand] >= spec[cand + 1])]
    cand = cand[spec[cand] > at_f]
    best, best_amp = f, 0.0
    for k in cand[np.argsort(spec[cand])[::-1]][:20]:
        near = (freqs >= 0.75 * freqs[k]) & (freqs <= 1.25 * freqs[k])
        if spec[k] < np.max(spec[near]) or spec[k] < 3.0 * np.median(spec[near]):
            continue
        if spec[k] > best_amp:
            best, best_amp = float(_interpolate(spec, k)[0] / (n * dt)), float(spec[k])
    return best
