"""Where the free decays in a recording start and end: release detection for plucks and taps.

A free decay is the only part of a pluck recording that the free-vibration model describes.
Before the release the whisker is at rest, held (with the hand's drift and tremor), being
bent, or being struck; after the next pluck starts it is none of its business either. The
detector finds each decay from the data alone, with no whisker model, so it works for any
whisker and sampling rate (aliased modes included):

1. The dominant observed frequency ``f`` of the record (aliased or not) sets the time scale,
   one period ``P``. A high-pass (the record minus its moving average over ``P``) and the
   moving maximum of its magnitude give a ringing envelope; where it stands above the noise
   are *events* (a hold does not ring, so holds are not events).
2. For each event, a sum of one or two damped sinusoids plus an offset and a drift is fitted
   (variable projection: frequencies and decay rates nonlinear, the rest linear) to a stretch
   that is surely free decay: from one period after the envelope's maximum.
3. The decay's start is found by walking back from there, half a period at a time and then
   sample by sample, for as long as the model (its linear part refitted on each stretch)
   explains the data to within a few times the stretch's residual scale: before a release
   the signal stops following the decaying oscillation extrapolated backwards (a held
   whisker does not oscillate, a struck one was at rest). Its end is found walking forward
   the same way (the next pluck's bending departs from the rest level).
4. Samples clipped at the converter's rails (runs of the extreme value) are left out: the
   decay starts after the last clipped sample.

A recording that starts after the release gives a decay starting at its first sample.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares as _scipy_lsq

#: Residual scales (robust RMS of the tail fit) within which a stretch is "still the decay".
TOLERANCE = 4.0


@dataclass(frozen=True)
class Decay:
    """One free decay found in a recording.

    Attributes:
        start_s: Time of its first sample (s): the release, or the first unclipped sample.
        end_s: Time of its last sample (s).
        frequency_hz: Dominant observed frequency (aliased if the sampling aliases it).
        clipped_until_s: Time of the last sample clipped at the rails before ``start_s``,
            or None.
        from_start: Whether the recording starts during this decay (release not recorded).
    """

    start_s: float
    end_s: float
    frequency_hz: float
    clipped_until_s: float | None = None
    from_start: bool = False

    def describe(self) -> str:
        """One line for reports."""
        how = (
            "the recording starts during the decay"
            if self.from_start
            else "after the last clipped sample"
            if self.clipped_until_s is not None
            else "release detected"
        )
        return f"{self.start_s:.4f} s to {self.end_s:.4f} s ({how})"


def find_decays(t: np.ndarray, y: np.ndarray) -> list[Decay]:
    """The free decays in a recording, in time order (see the module docstring).

    Args:
        t: Sample times (s), increasing.
        y: Samples in any units.

    Returns:
        The decays found; empty when the record holds no ringing above its noise.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    dt = float(np.median(np.diff(t)))
    f = dominant_frequency(t, y)
    if f is None:
        return []
    period = max(2, round(1.0 / (f * dt)))
    clipped = clipped_mask(y)
    events = _events(y, period, clipped)
    decays: list[Decay] = []
    lo = 0
    for k, (a, b) in enumerate(events):
        hi = events[k + 1][0] if k + 1 < len(events) else y.size
        d = _decay_in(t, y, clipped, period, a, b, lo, hi)
        if d is not None:
            decays.append(d)
            lo = int(np.searchsorted(t, d.end_s, side="right"))
        else:
            lo = b
    return decays


def dominant_frequency(t: np.ndarray, y: np.ndarray) -> float | None:
    """Frequency (Hz) of the largest spectral peak away from DC, interpolated; None if flat."""
    n = y.size
    if n < 16:
        return None
    dt = float(np.median(np.diff(t)))
    yy = np.interp(t[0] + dt * np.arange(n), t, y)  # uniform grid for the FFT
    # The first difference weights a line by its frequency: a hold, a bend or a drift puts
    # most of its power at low frequencies, where it would otherwise beat the ringing.
    yy = np.diff(yy)
    n = yy.size
    spec = np.abs(np.fft.rfft((yy - np.mean(yy)) * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, dt)
    low = max(3.0 / (n * dt), 1.0)  # below: drift and holds, not ringing
    spec[freqs < low] = 0.0
    i = int(np.argmax(spec))
    if spec[i] <= 0:
        return None
    if 0 < i < spec.size - 1:
        a, b, c = np.log(spec[i - 1 : i + 2] + 1e-300)
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den < 0 else 0.0
        return float((i + shift) / (n * dt))
    return float(freqs[i])


def clipped_mask(y: np.ndarray, *, min_run: int = 2) -> np.ndarray:
    """Samples at the record's extreme values in runs of at least ``min_run``: a converter's
    rails. A ringing signal passes its extremes once; clipping holds them."""
    mask = np.zeros(y.size, bool)
    for extreme in (np.max(y), np.min(y)):
        at = y == extreme
        if np.count_nonzero(at) < min_run:
            continue
        run_start = None
        for i in range(y.size + 1):
            if i < y.size and at[i]:
                run_start = i if run_start is None else run_start
            elif run_start is not None:
                if i - run_start >= min_run:
                    mask[run_start:i] = True
                run_start = None
    return mask


def _moving(fn, x, width):
    """``fn`` (np.max or np.mean) over a centred window of ``width`` samples."""
    pad = width // 2
    xp = np.pad(x, (pad, width - 1 - pad), mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(xp, width)
    return fn(windows, axis=1)


def _events(y, period, clipped):
    """Index ranges ``[a, b)`` where the ringing envelope stands above the noise."""
    hp = y - _moving(np.mean, y, period)
    env = _moving(np.max, np.abs(hp), period)
    noise = 1.4826 * np.median(np.abs(hp - np.median(hp)))
    peak = float(np.max(env))
    if peak <= 0:
        return []
    above = (env > max(8.0 * noise, 0.02 * peak)) | clipped
    idx = np.flatnonzero(above)
    if idx.size == 0:
        return []
    events, a, prev = [], idx[0], idx[0]
    for i in idx[1:]:
        if i - prev > 3 * period:  # quiet for three periods: a new event
            events.append((int(a), int(prev) + 1))
            a = i
        prev = i
    events.append((int(a), int(prev) + 1))
    return [(a, b) for a, b in events if b - a >= 2 * period]


# --------------------------------------------------------------------------- the decay model
def _columns(t, t0, freqs, rates):
    tau = t - t0
    cols = [np.ones_like(t), tau]
    for f, s in zip(freqs, rates, strict=True):
        e = np.exp(-s * tau)
        cols += [e * np.cos(2 * np.pi * f * tau), e * np.sin(2 * np.pi * f * tau)]
    return np.stack(cols, axis=1)


def _linear_fit(t, y, t0, freqs, rates):
    a = _columns(t, t0, freqs, rates)
    scale = np.maximum(np.linalg.norm(a, axis=0), 1e-300)
    coef, *_ = np.linalg.lstsq(a / scale, y, rcond=None)
    return y - (a / scale) @ coef


def _fit_tail(t, y, f0):
    """Frequencies and decay rates of one or two damped sinusoids fitted to ``(t, y)``."""
    t0 = t[0]
    span = t[-1] - t[0]
    best = None
    for n_lines in (1, 2):
        freqs0 = [f0] if n_lines == 1 else [f0, _second_peak(t, y, f0)]
        if freqs0[-1] is None:
            break
        x0 = np.array([*freqs0, *[1.0 / max(span, 1e-6)] * n_lines])

        def resid(x, n=n_lines):
            return _linear_fit(t, y, t0, x[:n], np.abs(x[n:]))

        fit = _scipy_lsq(resid, x0, method="lm", max_nfev=200 * x0.size)
        r = fit.fun
        if best is None or np.sum(r**2) < 0.9 * best[2]:
            best = (fit.x[:n_lines], np.abs(fit.x[n_lines:]), float(np.sum(r**2)))
    return best[0], best[1]


def _second_peak(t, y, f0):
    r = _linear_fit(t, y, t[0], [f0], [1.0 / max(t[-1] - t[0], 1e-6)])
    f = dominant_frequency(t, r)
    return None if f is None or abs(f - f0) < 2.0 / (t[-1] - t[0]) else f


def _robust_rms(r):
    return max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-300)


def _decay_in(t, y, clipped, period, a, b, lo, hi):
    """The decay of event ``[a, b)``, searched within ``[lo, hi)``; None if it does not ring."""
    hp = np.abs(y[a:b] - _moving(np.mean, y[a:b], period))
    anchor = a + int(np.argmax(hp))
    ta = min(anchor + period, hi - 4 * period)
    tb = min(hi, ta + 20 * period)
    if ta < lo or tb - ta < 4 * period:
        return None
    seg = slice(ta, tb)
    if np.any(clipped[seg]):
        ta = ta + int(np.flatnonzero(clipped[seg])[-1]) + 1
        seg = slice(ta, tb)
        if tb - ta < 4 * period:
            return None
    f0 = dominant_frequency(t[seg], y[seg]) or 1.0 / (period * np.median(np.diff(t)))
    freqs, rates = _fit_tail(t[seg], y[seg], f0)
    sigma = _robust_rms(_linear_fit(t[seg], y[seg], t[ta], freqs, rates))
    start = _walk_back(t, y, clipped, period, ta, lo, freqs, rates, sigma)
    end = _walk_forward(t, y, period, start, ta, hi, freqs, rates, sigma)
    before = np.flatnonzero(clipped[lo:start])
    clipped_until = float(t[lo + before[-1]]) if before.size else None
    return Decay(
        start_s=float(t[start]),
        end_s=float(t[end - 1]),
        frequency_hz=float(freqs[0]),
        clipped_until_s=clipped_until,
        from_start=start == 0,
    )


def _fits(t, y, i, j, check, t0, freqs, rates, sigma):
    """Whether the model refitted on ``[i, j)`` explains samples ``check`` within tolerance."""
    r = _linear_fit(t[i:j], y[i:j], t0, freqs, rates)
    return np.sqrt(np.mean(r[check] ** 2)) <= TOLERANCE * sigma


def _walk_back(t, y, clipped, period, ta, lo, freqs, rates, sigma):
    """Earliest index from which the decay model explains the data back from ``ta``."""
    width = 8 * period
    half = max(1, period // 2)
    s = ta
    while s - half >= lo and not np.any(clipped[s - half : s]):
        i = s - half
        if not _fits(t, y, i, i + width, slice(0, half), t[ta], freqs, rates, sigma):
            break
        s = i
    # sample by sample: stop at two consecutive samples off the model
    i, misses = s - 1, 0
    while i >= lo and not clipped[i]:
        r = _linear_fit(t[i : i + width], y[i : i + width], t[ta], freqs, rates)
        if abs(r[0]) > TOLERANCE * sigma:
            misses += 1
            if misses == 2:
                break
        else:
            misses, s = 0, i
        i -= 1
    return s


def _walk_forward(t, y, period, start, ta, hi, freqs, rates, sigma):
    """One past the last index that the decay model (from ``start``) explains."""
    chunk = max(2, period // 2)
    e = min(hi, ta + 4 * period)
    while e < hi:
        c = min(chunk, hi - e)
        check = slice(e - start, e - start + c)
        if not _fits(t, y, start, e + c, check, t[ta], freqs, rates, sigma):
            break
        e += c
    return e


def steady_line(t: np.ndarray, y: np.ndarray) -> float | None:
    """The frequency (Hz) of a steady line that carries the record, or None.

    A sine base excitation shows one line whose amplitude stays the same from the first
    quarter of the record to the last; a free decay's line shrinks. The line must explain
    most of each quarter's variance and keep its amplitude within 10 %.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    f = dominant_frequency(t, y)
    if f is None or y.size < 64:
        return None
    amps = []
    for part in np.array_split(np.arange(y.size), 4):
        tt, yy = t[part], y[part]
        a = np.stack([np.ones_like(tt), tt - tt[0], np.cos(2 * np.pi * f * tt),
                      np.sin(2 * np.pi * f * tt)], axis=1)  # fmt: skip
        coef, *_ = np.linalg.lstsq(a, yy, rcond=None)
        r = yy - a @ coef
        detrended = yy - a[:, :2] @ coef[:2]
        if np.sum(r**2) > 0.5 * np.sum(detrended**2):
            return None
        amps.append(np.hypot(coef[2], coef[3]))
    return f if min(amps[0], amps[-1]) >= 0.9 * max(amps[0], amps[-1]) else None
