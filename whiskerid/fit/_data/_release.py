"""Where the free decays in a recording start and end: release detection for plucks and taps.

A free decay is the only part of a pluck recording that the free-vibration model describes.
Before the release the whisker is at rest, held (with the hand's drift and tremor), being
bent, or being struck; after the next pluck starts it is none of its business either. The
detector finds each decay from the data alone, with no whisker model, so it works for any
whisker and sampling rate (aliased modes included):

1. The dominant observed frequency ``f`` of the record (aliased or not; from the spectrum of
   the first difference, so that holds and drifts do not win) sets the time scale, one period
   ``P``. A high-pass (the record minus its moving average over ``P``) and the moving maximum
   of its magnitude give a ringing envelope; where it stands above the noise (or above a
   quarter of its peak, in a record that rings throughout) the record rings. A hold does not.
   The search runs at the record's lowest strong line (:func:`._ringing.lowest_strong_line`)
   where that is a real line below ``f``: the first difference favours a higher mode or a
   rattle, and a decay found at one is cut wherever that mode's beating dips.
2. From the strongest ringing not yet explained, one or two damped sinusoids plus an offset
   and a drift are fitted (variable projection: frequencies and decay rates nonlinear, the
   rest linear) to a stretch that is surely free decay: from one period after the ringing's
   maximum for as long as it rings (at most 20 periods, at least 40 samples). A stretch whose
   fit does not stand clearly above its residuals, or whose line is not the record's, is not
   a decay.
3. The decay's start is found by walking back from there, half a period at a time and then
   sample by sample, for as long as the model fitted on what is already accepted *predicts*
   the data to within a few residual scales plus a tenth of the oscillation: before a
   release the signal stops following the decaying oscillation extrapolated backwards (a
   held whisker does not oscillate, a struck one was at rest). Its end is found walking
   forward the same way, the rates fitted again each time the stretch doubles (the next
   pluck's bending departs from the prediction). The rest of the record is searched again,
   so every pluck in a file is found.
4. The first samples accepted that the motion before them predicts as well (a hold, a rest
   or a moving hand: a line through the preceding samples within the noise) are dropped: a
   held whisker leaves with zero velocity, so the last held sample meets the decay to second
   order and would otherwise start it (ζ many σ off on a strongly damped whisker).
5. Samples clipped at the converter's rails (runs of the extreme value, or an extreme met
   three times by a signal spanning many converter steps) are left out: the decay starts
   after the last clipped sample.

6. A decay whose line does not rise at its start (its amplitude by less than :data:`RISE`
   beyond the noise, and its phase by less than 60°) continues the one before and is joined
   to it: one release is one decay, whatever rides on it.

A recording that starts after the release gives a decay starting at its first sample. Every
step costs time linear in the samples (moving filters by running sums and maxima, the walk
forward by normal equations grown chunk by chunk, a stretch refused once is not tried again
period by period), and a line at the Nyquist frequency is no decay.
"""

from dataclasses import dataclass, replace

import numpy as np

from .._numerics import lm_least_squares as least_squares
from .._numerics import single_blas_thread
from ._ringing import (
    clipped_mask,
    dominant_frequency,
    lowest_strong_line,
    normalised_samples,
    quantum,
)

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


@single_blas_thread
def find_decays(t: np.ndarray, y: np.ndarray) -> list[Decay]:
    """The free decays in a recording, in time order (see the module docstring).

    Args:
        t: Sample times (s), increasing.
        y: Samples in any units.

    Returns:
        The decays found; empty when the record holds no ringing above its noise.
    """
    t = np.asarray(t, dtype=float)
    y = normalised_samples(y)
    if y is None:
        return []
    dt = float(np.median(np.diff(t)))
    f = dominant_frequency(t, y)
    if f is None or f * dt > 0.5 - 2.0 / y.size:
        # nothing rings, or a line at the Nyquist frequency: its samples alternate in sign
        # whatever its phase, so neither a decay rate nor a release can be measured on it
        return []
    low = lowest_strong_line(t, y, f)
    decays = _search(t, y, low, dt)
    if not decays and low != f:
        # a "line" below the ringing that rings nothing (a train of plucks' comb, a strongly
        # damped decay's broad hump): the first difference's line it is
        decays = _search(t, y, f, dt)
    return decays


def _search(t, y, f, dt):
    """The decays ringing at ``f`` (see :func:`find_decays`), in time order."""
    period = max(2, round(1.0 / (f * dt)))
    clipped = clipped_mask(y)
    env, threshold = _envelope(y, period)
    active = (env > threshold) | clipped
    decays: list[Decay] = []
    todo = [(0, y.size)]
    while todo:
        lo, hi = todo.pop()
        if hi - lo < 6 * period or not np.any(active[lo:hi]):
            continue
        anchor = lo + int(np.argmax(np.where(active[lo:hi], env[lo:hi], -np.inf)))
        d, tested_until = _decay_in(t, y, clipped, active, f, anchor, lo, hi)
        if d is None:
            # not a decay here: look on either side of the stretch that was tried (the
            # search resumes after it, so a record that rings without decaying, e.g. a
            # signal toggling at the Nyquist frequency, costs one attempt per stretch
            # tried, not one per period)
            todo += [(lo, max(lo, anchor - period)), (max(tested_until, anchor + period), hi)]
            continue
        decays.append(d)
        i0 = int(np.searchsorted(t, d.start_s))
        i1 = int(np.searchsorted(t, d.end_s, side="right"))
        todo += [(lo, i0), (i1, hi)]
    return _join_continuations(t, y, sorted(decays, key=lambda d: d.start_s))


def _join_continuations(t, y, decays):
    """Decays in time order, each later one that does not *rise* joined to the one before.

    The walk forward ends a decay where its model stops predicting the data (a light
    damping that drifts, a higher mode's beating, a glitch); the rest of the record is then
    searched again, and the same ringing is found again as a "decay" of its own. A release
    or a tap puts energy in: the line's amplitude just after it stands clearly above the
    amplitude just before it, or its phase jumps. A continuation's does neither.
    """
    out = decays[:1]
    for d in decays[1:]:
        f = 0.5 * (out[-1].frequency_hz + d.frequency_hz)
        if _rises(t, y, out[-1].start_s, out[-1].end_s, d.start_s, f):
            out.append(d)
        else:
            out[-1] = replace(out[-1], end_s=max(out[-1].end_s, d.end_s))
    return out


#: A line this much larger just after a decay's start than just before it has been struck.
RISE = 1.3


def _line(t, y, f, i0, i1):
    """Complex amplitude (referred to ``t = 0``) of the line at ``f`` fitted with an offset
    and a slope to samples ``[i0, i1)``, and the fit's residual RMS."""
    tt = t[i0:i1]
    w = 2 * np.pi * f * tt
    a = np.stack([np.ones_like(tt), tt - tt[0], np.cos(w), np.sin(w)], axis=1)
    coef, *_ = np.linalg.lstsq(a, y[i0:i1], rcond=None)
    r = y[i0:i1] - a @ coef
    return complex(coef[2], -coef[3]), float(np.sqrt(np.mean(r**2)))


def _rises(t, y, prev_start_s, prev_end_s, start_s, f):
    """Whether the line at ``f`` is struck at ``start_s`` (a decay's start; the decay before
    it spans ``prev_start_s`` to ``prev_end_s``): its amplitude over the two periods from one
    period after it against the two periods ending one period before it, or before the
    previous decay's end if that is earlier (a start found late, after a tap, would
    otherwise compare the tap's own ringing with itself), beyond the amplitudes' noise; or
    its phase turns by more than 60° (a tap out of phase). Too little record to tell: a
    rise."""
    dt = float(np.median(np.diff(t)))
    period = max(2, round(1.0 / (f * dt)))
    s = int(np.searchsorted(t, start_s))
    b1 = min(s, int(np.searchsorted(t, prev_end_s, side="right"))) - period
    if b1 - 2 * period < int(np.searchsorted(t, prev_start_s)):
        b1 = s - period  # the decay before is too short: just before this one's start
    b0, a0, a1 = b1 - 2 * period, s + period, s + 3 * period
    if b0 < 0 or a1 > t.size or 2 * period < 8:
        return True
    cb, rb = _line(t, y, f, b0, b1)
    ca, ra = _line(t, y, f, a0, a1)
    noise = 4.0 * max(rb, ra) * np.sqrt(2.0 / (2 * period))
    if abs(ca) > RISE * abs(cb) + noise:
        return True
    if min(abs(ca), abs(cb)) > 2.0 * noise:
        turn = abs(np.angle(ca / cb))
        return bool(turn > np.pi / 3)
    return False


def _moving(fn, x, width):
    """``fn`` (np.max or np.mean) over a centred window of ``width`` samples (edges held),
    in ``O(n)`` whatever the width."""
    pad = width // 2
    xp = np.pad(x, (pad, width - 1 - pad), mode="edge")
    if fn is np.mean:
        c = np.concatenate([[0.0], np.cumsum(xp - xp[0])])
        return (c[width:] - c[:-width]) / width + xp[0]
    return _moving_max(xp, width)


def _moving_max(x, width):
    """The maxima of the ``len(x) − width + 1`` windows of ``width`` samples (van Herk /
    Gil–Werman): within blocks of ``width``, running maxima from the left ``g`` and from the
    right ``h``; a window starting at ``i`` spans at most two blocks, so its maximum is
    ``max(h[i], g[i + width − 1])``."""
    n = x.size
    blocks = -(-n // width)
    xb = np.full(blocks * width, -np.inf)
    xb[:n] = x
    xb = xb.reshape(blocks, width)
    g = np.maximum.accumulate(xb, axis=1).ravel()
    h = np.maximum.accumulate(xb[:, ::-1], axis=1)[:, ::-1].ravel()
    m = n - width + 1
    return np.maximum(h[:m], g[width - 1 : width - 1 + m])


def _envelope(y, period):
    """The ringing envelope (moving maximum over a period of the signal minus its moving
    average) and the level above which it counts as ringing."""
    hp = y - _moving(np.mean, y, period)
    env = _moving(np.max, np.abs(hp), period)
    noise = max(1.4826 * np.median(np.abs(hp - np.median(hp))), quantum(y))
    peak = float(np.max(env))
    # A record that rings from start to end has no quiet part to measure the noise on (the
    # "noise" is then the ringing itself): a quarter of the peak always counts as ringing.
    return env, min(max(8.0 * noise, 0.02 * peak), 0.25 * peak)


# --------------------------------------------------------------------------- the decay model
def _columns(t, t0, freqs, rates):
    tau = t - t0
    cols = [np.ones_like(t), tau]
    for f, s in zip(freqs, rates, strict=True):
        e = np.exp(-s * tau)
        cols += [e * np.cos(2 * np.pi * f * tau), e * np.sin(2 * np.pi * f * tau)]
    return np.stack(cols, axis=1)


def _coefficients(t, y, t0, freqs, rates):
    """The decay model's columns at ``t`` and its linear part fitted to ``(t, y)``."""
    a = _columns(t, t0, freqs, rates)
    scale = np.maximum(np.linalg.norm(a, axis=0), 1e-300)
    coef, *_ = np.linalg.lstsq(a / scale, y, rcond=None)
    return a, coef / scale


def _linear_fit(t, y, t0, freqs, rates):
    """Residuals of the decay model with its linear part fitted to ``(t, y)``."""
    a, coef = _coefficients(t, y, t0, freqs, rates)
    return y - a @ coef


def _predict(t, y, fit, at, t0, freqs, rates):
    """The decay model fitted on indices ``fit`` (a slice), predicting indices ``at``:
    returns the misfit there and the oscillation's RMS amplitude there."""
    _, coef = _coefficients(t[fit], y[fit], t0, freqs, rates)
    b = _columns(t[at], t0, freqs, rates)
    misfit = y[at] - b @ coef
    oscillation = b[:, 2:] @ coef[2:]
    return misfit, float(np.sqrt(np.mean(oscillation**2)))


def _fit_tail(t, y, f0, *, t0=None, start=None):
    """Frequencies and decay rates of one or two damped sinusoids fitted to ``(t, y)``
    (from ``start = (freqs, rates)`` when given, else from ``f0`` and the spectrum)."""
    t0 = t[0] if t0 is None else t0
    span = t[-1] - t[0]
    if start is not None:
        n = len(start[0])
        x0 = np.concatenate([np.asarray(start[0], float), np.asarray(start[1], float)])
        x, _ = least_squares(lambda x: _linear_fit(t, y, t0, x[:n], np.abs(x[n:])), x0,
                             max_nfev=100 * x0.size)  # fmt: skip
        return x[:n], np.abs(x[n:])
    best = None
    for n_lines in (1, 2):
        freqs0 = [f0] if n_lines == 1 else [f0, _second_peak(t, y, f0)]
        if freqs0[-1] is None:
            break
        x0 = np.array([*freqs0, *[1.0 / max(span, 1e-6)] * n_lines])

        def resid(x, n=n_lines):
            return _linear_fit(t, y, t0, x[:n], np.abs(x[n:]))

        x, r = least_squares(resid, x0, max_nfev=200 * x0.size)
        if best is None or np.sum(r**2) < 0.9 * best[2]:
            best = (x[:n_lines], np.abs(x[n_lines:]), float(np.sum(r**2)))
    return best[0], best[1]


def _second_peak(t, y, f0):
    r = _linear_fit(t, y, t[0], [f0], [1.0 / max(t[-1] - t[0], 1e-6)])
    f = dominant_frequency(t, r)
    return None if f is None or abs(f - f0) < 2.0 / (t[-1] - t[0]) else f


def _robust_rms(r):
    return max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-300)


def _decay_in(t, y, clipped, active, f, anchor, lo, hi):
    """The decay that rings at ``anchor`` at the record's dominant frequency ``f``, searched
    within ``[lo, hi)``, and the index up to which the record was tried: ``(None, index)``
    if no decay rings there."""
    period = max(2, round(1.0 / (f * float(np.median(np.diff(t))))))
    ta = min(anchor + period, hi - 4 * period)
    if ta < lo:
        return None, anchor + period
    clipped_after = np.flatnonzero(clipped[ta:hi])
    if clipped_after.size:  # ringing at the rails: the decay starts after the last clip
        ta = ta + int(clipped_after[-1]) + 1
    # the tail: up to 20 periods, and no further than the ringing lasts (a pluck that
    # follows soon must not enter the fit of this one's frequencies)
    quiet = np.flatnonzero(~active[ta:hi])
    ring_end = ta + int(quiet[0]) if quiet.size else hi
    tb = min(hi, ta + 20 * period, max(ring_end + period, ta + 4 * period, ta + 40))
    if tb - ta < max(4 * period, 40):  # too few samples to tell a ringing from noise
        return None, anchor + period
    seg = slice(ta, tb)
    # seeded with the record's frequency: a stretch's own spectrum can favour a higher mode
    freqs, rates = _fit_tail(t[seg], y[seg], f)
    order = np.argsort(np.abs(np.log(np.abs(freqs) / f + 1e-300)))  # the record's line first
    freqs, rates = np.abs(freqs[order]), rates[order]
    resid = _linear_fit(t[seg], y[seg], t[ta], freqs, rates)
    sigma = max(_robust_rms(resid), quantum(y))
    model = y[seg] - resid
    if np.max(np.abs(model - np.median(model))) < 5 * sigma or np.var(model) < 3 * sigma**2:
        return None, tb  # nothing rings above the noise
    if not abs(np.log(freqs[0] / f + 1e-300)) < np.log(1.25):
        return None, tb  # a bend or a knock, not the whisker ringing at its frequency
    start = _walk_back(t, y, clipped, period, ta, lo, freqs, rates, sigma)
    end = _walk_forward(t, y, period, start, ta, tb, hi, freqs, rates, sigma)
    before = np.flatnonzero(clipped[lo:start])
    clipped_until = float(t[lo + before[-1]]) if before.size else None
    decay = Decay(
        start_s=float(t[start]),
        end_s=float(t[end - 1]),
        frequency_hz=float(freqs[0]),
        clipped_until_s=clipped_until,
        from_start=start == 0,
    )
    return decay, end


def _explains(misfit, oscillation, sigma):
    """Whether a predicted stretch matches: within a few noise scales plus a tenth of the
    oscillation (frequencies and rates fitted on the tail are not exact, so the misfit of a
    true continuation grows with its amplitude; a hold or a rest misses by the whole of it)."""
    return np.sqrt(np.mean(misfit**2)) <= TOLERANCE * sigma + 0.1 * oscillation


def _walk_back(t, y, clipped, period, ta, lo, freqs, rates, sigma):
    """Earliest index from which the decay model, fitted on what is already accepted, keeps
    predicting the data going back from ``ta`` (half a period at a time, then by samples),
    less the first samples that what came before predicts as well (:func:`_past_the_hold`)."""
    width = 8 * period
    half = max(1, period // 2)
    s = ta
    while s - half >= lo and not np.any(clipped[s - half : s]):
        misfit, osc = _predict(t, y, slice(s, s + width), slice(s - half, s), t[ta], freqs, rates)
        if not _explains(misfit, osc, sigma):
            break
        s -= half
    i, misses = s - 1, 0
    while i >= lo and not clipped[i]:
        misfit, osc = _predict(t, y, slice(i + 1, i + 1 + width), slice(i, i + 1), t[ta], freqs,
                               rates)  # fmt: skip
        if _explains(misfit, osc, sigma):
            misses, s = 0, i
        else:
            misses += 1
            if misses == 2:
                break
        i -= 1
    if i < lo or clipped[i]:  # the record (or the clipping) ends the walk, not a hold
        return s
    return _past_the_hold(y, s, lo, period, sigma)


#: Noise scales within which a sample continues what came before it.
HOLD_TOLERANCE = 3.0


def _past_the_hold(y, s, lo, period, sigma):
    """The first index from ``s`` on that the record before it does not predict.

    Near a release the decay and the hold (or a rest before a tap) meet smoothly: a held
    whisker leaves with zero velocity, so the decay extrapolated back departs from the hold
    only as ``½ω²x₀δ²``, and the last held sample (up to a sample period before the
    release) passes the walk back's test. A held sample in the fit pulls the decay towards
    the hold (ζ several σ off for a strongly damped or a fast whisker), and a sample that
    the hold explains carries no information the decay needs: so samples are dropped from
    the start while the samples before it lie on a straight line to within the noise (a
    hold with its drift, a rest, a moving hand: not the decay itself, where the walk back
    can stop early) and that line predicts it within a few noise scales. A quarter period
    after a release the whisker has moved by its whole deflection, so at most that many
    samples are dropped.
    """
    for _ in range(period // 4 + 1):
        before = y[max(lo, s - max(8, period // 2)) : s]
        if before.size < 3:
            break
        x = np.arange(-before.size, 0, dtype=float)
        coef = np.polyfit(x, before, 1)
        spread = np.sqrt(np.sum((before - np.polyval(coef, x)) ** 2) / (before.size - 2))
        if spread > 2.0 * sigma:  # not a hold or a rest: the walk back stopped in the decay
            break
        # the line's own uncertainty at the next sample (its leverage) widens the test
        leverage = 1.0 / x.size + x.mean() ** 2 / np.sum((x - x.mean()) ** 2)
        if abs(y[s] - coef[1]) > HOLD_TOLERANCE * sigma * np.sqrt(1.0 + leverage):
            break
        s += 1
    return s


def _walk_forward(t, y, period, start, ta, tb, hi, freqs, rates, sigma):
    """One past the last index that the decay model, fitted on what is already accepted,
    keeps predicting (half a period at a time). Its frequencies and decay rates are fitted
    again each time the accepted stretch doubles: a long, lightly damped ringing drifts in
    phase away from rates estimated on its first periods.

    The linear part is fitted from normal equations accumulated chunk by chunk (the columns
    do not change between refits), so the walk costs ``O(n)``, not one fit of the whole
    accepted stretch per chunk."""
    chunk = max(2, period // 2)
    e = tb
    refit_at = 2 * (e - start)
    gram = _Gram(t, y, t[ta], freqs, rates, start, e)
    while e < hi:
        if e - start >= refit_at:
            freqs, rates = _fit_tail(t[start:e], y[start:e], float(freqs[0]), t0=t[ta],
                                     start=(freqs, rates))  # fmt: skip
            refit_at = 2 * (e - start)
            gram = _Gram(t, y, t[ta], freqs, rates, start, e)
        c = min(chunk, hi - e)
        b = _columns(t[e : e + c], t[ta], freqs, rates)
        coef = gram.solve()
        misfit = y[e : e + c] - b @ coef
        osc = float(np.sqrt(np.mean((b[:, 2:] @ coef[2:]) ** 2)))
        if not _explains(misfit, osc, sigma):
            break
        gram.add(b, y[e : e + c])
        e += c
    return e


class _Gram:
    """``AᵀA`` and ``Aᵀy`` of the decay model's columns over a growing stretch."""

    def __init__(self, t, y, t0, freqs, rates, i0, i1):
        a = _columns(t[i0:i1], t0, freqs, rates)
        self.ata = a.T @ a
        self.aty = a.T @ y[i0:i1]

    def add(self, a, y):
        self.ata += a.T @ a
        self.aty += a.T @ y

    def solve(self):
        """The least-squares coefficients (columns scaled to unit norm first)."""
        d = np.sqrt(np.maximum(np.diag(self.ata), 1e-300))
        coef, *_ = np.linalg.lstsq(self.ata / np.outer(d, d), self.aty / d, rcond=None)
        return coef / d


def steady_line(t: np.ndarray, y: np.ndarray) -> float | None:
    """The frequency (Hz) of a steady line that carries the record, or None.

    A sine base excitation shows one line whose amplitude stays the same from the first
    quarter of the record to the last; a free decay's line shrinks. The line must explain
    most of each quarter's variance and keep its amplitude within 10 %.
    """
    t = np.asarray(t, dtype=float)
    y = normalised_samples(y)
    if y is None:
        return None
    f = dominant_frequency(t, y)
    if f is None or y.size < 64 or f * float(np.median(np.diff(t))) > 0.5 - 2.0 / y.size:
        return None  # a line at the Nyquist frequency is no drive either (samples alternate)
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
