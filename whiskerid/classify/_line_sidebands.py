"""A calibrated test for sidebands: two *lines* at ``f_c ± Δ``, phase-coupled to a carrier.

What the test's null is
-----------------------
A periodic modulation at ``Δ`` of a response at ``f_c`` (contact that opens and closes at
a texture's passing rate) puts two **lines** at ``f_c − Δ`` and ``f_c + Δ``: sinusoids
whose amplitude and phase hold over the whole recording. Random modulation (amplitude or
phase wandering within a band, a resonance struck at random, coloured noise) spreads power
into a **continuum** around the carrier, however symmetric its humps: the test counts
that as no sidebands. Its null is "at least one of ``f_c ± Δ`` holds no line", which
covers a carrier alone, a carrier with one side line, two unrelated lines, a resonance's
skirts and random modulation in a band.

Why this route
--------------
The earlier Welch test compared bin powers with a local floor: random modulation and a
resonance's skirts lift bins as much as lines do (its false-alarm rate was 3–10 times
``α`` on such recordings), and its side-bin choice lost half the sidebands that fell
between bins. This test asks instead whether a frequency holds a line, with the
**multitaper harmonic F-test** (Thomson 1982): with ``K`` Slepian tapers of half-bandwidth
``W = NW/T``, the tapers' transforms at ``f`` are regressed on their values at zero
frequency; ``F = (K − 1)|μ̂|² Σ U_k(0)² / Σ|y_k − μ̂ U_k(0)|²`` follows ``F(2, 2K − 2)``
when the spectrum is a continuum that varies little across ``±W``, *whatever its level or
shape*, and grows with a line's amplitude ``|μ|`` when there is one. The transforms are
zero-padded (a grid at most ``W/12`` apart), so that a line is tested at its frequency
whether or not it falls on a bin of the recording's own FFT.

The steps, for the recordings of one group:

1. **Carrier**: in each whole recording, the frequency of the largest ``F`` within
   ``carrier_tol_hz`` of the given carrier; its p-value (Šidák-corrected for the
   independent frequencies in that window; Fisher's method over the recordings) is
   ``carrier_p_value``. Sidebands are only reported around a significant carrier.
2. **Selection on the first halves**: for each offset ``Δ`` on the grid (from ``2W``, where
   the carrier's own band ends, to what fits between ``min_hz`` and Nyquist) each side's
   F-test p-values combine over the recordings (Fisher); ``Δ`` is the offset whose weaker
   side is strongest, and that weaker side is the one to test.
3. **Test on the second halves**: the weaker side's F-test at the chosen ``Δ``, on data the
   selection did not see, Fisher-combined over the recordings: ``p_value``. Under any null
   above it is uniform: either that side holds no line (the F-test's null), or it holds
   the one line and the other side, stronger in the first half, holds none, which the
   selection then had to prefer by chance.

Sidebands are **present** when ``carrier_p_value < α`` and ``p_value < α``. The **power**
reported is the chance the test finds sidebands of the level measured (the weaker side's
line-to-continuum ratio in the whole recordings) at the recordings' length, from the
non-central F distribution (the group pooled as one F-test, an approximation to Fisher's
method; the selection assumed right); ``length_80_s`` is the total length of recording at
which it reaches 80 %. Splitting costs the test half of the data (3 dB of line-to-noise
ratio) against one that could choose ``Δ`` without looking; in exchange no search over
``Δ`` needs correcting and no null's shape needs modelling.
"""

import functools

import numpy as np

#: The name ``whiskerid analyze`` reports as the sideband test used.
TEST_NAME = "multitaper line F-test, split (select on first halves, test on second)"
DEFAULT_NW = 2.0
PAD = 4  # zero padding: grid step at most 1/(4T) = W/(4 NW)


@functools.lru_cache(maxsize=16)
def _tapers(n: int, nw: float, k: int) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal.windows import dpss  # here: importing classify skips SciPy

    v = dpss(n, nw, k)
    return v, v.sum(axis=1)


def line_f(x: np.ndarray, nfft: int, nw: float = DEFAULT_NW, k: int | None = None):
    """Thomson's harmonic F statistic and the line's complex amplitude at each frequency
    of an ``nfft``-point grid (``rfft`` order).

    Returns:
        ``(F, mu)``: ``F ~ F(2, 2K − 2)`` where there is no line; ``|mu|`` is half a
        sinusoid's amplitude where there is one.
    """
    k = int(2 * nw) - 1 if k is None else k
    x = np.asarray(x, dtype=float)
    v, u0 = _tapers(x.size, float(nw), k)
    y = np.fft.rfft(v * (x - x.mean()), nfft, axis=1)
    uu = float(u0 @ u0)
    mu = (u0 @ y) / uu
    resid = np.sum(np.abs(y - mu[None, :] * u0[:, None]) ** 2, axis=0)
    return (k - 1) * np.abs(mu) ** 2 * uu / np.maximum(resid, 1e-300), mu


def line_f_at(x: np.ndarray, freqs_hz, rate_hz: float, nw: float = DEFAULT_NW,
              k: int | None = None):  # fmt: skip
    """:func:`line_f` at arbitrary frequencies (Hz), by direct transforms: ``(F, mu)``."""
    k = int(2 * nw) - 1 if k is None else k
    x = np.asarray(x, dtype=float)
    v, u0 = _tapers(x.size, float(nw), k)
    freqs = np.atleast_1d(np.asarray(freqs_hz, dtype=float))
    phase = np.exp(-2j * np.pi * np.outer(np.arange(x.size) / rate_hz, freqs))  # (n, m)
    y = (v * (x - x.mean())) @ phase  # (k, m)
    uu = float(u0 @ u0)
    mu = (u0 @ y) / uu
    resid = np.sum(np.abs(y - mu[None, :] * u0[:, None]) ** 2, axis=0)
    return (k - 1) * np.abs(mu) ** 2 * uu / np.maximum(resid, 1e-300), mu


#: Points of the local grids that refine a frequency between FFT bins.
REFINE = 17


def _log_sf(f: np.ndarray, k: int) -> np.ndarray:
    """``ln P(F(2, 2K − 2) > f)``."""
    return -(k - 1) * np.log1p(f / (k - 1))


def _fisher_p(log_ps: np.ndarray) -> np.ndarray:
    """Fisher's combination over axis 0 of log p-values: the combined p-values."""
    from scipy import stats

    log_ps = np.atleast_2d(log_ps)
    return stats.chi2.sf(-2 * np.sum(log_ps, axis=0), 2 * log_ps.shape[0])


def _power(lams: np.ndarray, k: int, alpha: float) -> float:
    """Power of the F-test pooled over recordings of non-centralities ``lams``."""
    from scipy import stats

    r = len(lams)
    d1, d2 = 2 * r, r * (2 * k - 2)
    crit = stats.f.isf(alpha, d1, d2)
    lam = float(np.sum(lams))
    return float(stats.ncf.sf(crit, d1, d2, lam)) if lam > 0 else float(alpha)


def line_sideband_test(series, rate_hz: float, carriers_hz, *, alpha: float = 0.01,
                       nw: float = DEFAULT_NW, min_hz: float = 2.0,
                       max_offset_hz: float | None = None,
                       carrier_tol_hz: float = 0.5) -> dict:  # fmt: skip
    """Test a group of recordings for sidebands (lines at ``f_c ± Δ``); see the module
    docstring for the null, the route and the steps.

    Args:
        series: The recordings, each a 1-D array sampled uniformly at ``rate_hz``.
        rate_hz: Sampling rate (Hz).
        carriers_hz: The carrier ``f_c`` (Hz), one for all or one per recording.
        alpha: Significance level of the verdict (and of the power).
        nw: Time–half-bandwidth product of the Slepian tapers (``2NW − 1`` of them).
        min_hz: Lowest frequency of a lower sideband (Hz): below it lie a recording's
            drift and the ground's slow undulation (with ``Δ ≈ f_c`` they would pair with
            the carrier's second harmonic, which is no sideband).
        max_offset_hz: Largest ``Δ`` tried (Hz); all that fit by default.
        carrier_tol_hz: How far from the given carrier its line is looked for (Hz); at
            most the smallest ``Δ``.

    Returns:
        A JSON-able dict: ``test`` (its name), ``present``, ``p_value``,
        ``carrier_p_value``, ``carrier_hz`` (the carrier found, mean over recordings),
        ``delta_hz``, ``side_tested`` (``"lower"`` or ``"upper"``), ``other_side_p``
        (the stronger side's p-value on the second halves), ``level_db`` (the side lines'
        mean power over the carrier's), ``power`` and ``length_80_s`` (see the module
        docstring; ``None`` when no side line is measured), ``recordings``,
        ``bandwidth_hz`` (``W`` of the halves), ``min_offset_hz``, ``alpha``.
    """
    xs = [np.asarray(x, dtype=float) for x in series]
    fcs = np.broadcast_to(np.asarray(carriers_hz, dtype=float), (len(xs),))
    k = int(2 * nw) - 1
    n_half = [x.size // 2 for x in xs]
    base = {"test": TEST_NAME, "recordings": len(xs), "alpha": alpha}
    if not xs or min(n_half) < 4 * nw:
        return {**base, "present": False, "p_value": 1.0, "carrier_p_value": 1.0,
                "delta_hz": None, "power": None,
                "reason": "recordings too short for the tapers"}  # fmt: skip
    nfft = 1 << int(np.ceil(np.log2(PAD * max(n_half))))
    df = rate_hz / nfft
    w_hz = nw * rate_hz / min(n_half)  # W of the shortest half
    d_min = int(np.ceil(2 * w_hz / df))
    tol = min(carrier_tol_hz, d_min * df)
    # 1. the carrier, on whole recordings (a grid twice as fine: the same frequencies)
    full = [line_f(x, 2 * nfft, nw, k) for x in xs]
    fc_hz, log_pc, mu_c = [], [], []
    for (f, _), fc, x in zip(full, fcs, xs, strict=True):
        j = np.arange(max(round((fc - tol) / df * 2), 1), round((fc + tol) / df * 2) + 1)
        j = j[j < f.size - 1]
        best = int(j[np.argmax(f[j])]) if j.size else max(min(round(fc / df * 2), f.size - 2), 1)
        # between the grid's points: the largest F on a local grid half a step either side
        local = best * df / 2 + np.linspace(-df / 4, df / 4, REFINE)
        fl, ml = line_f_at(x, local, rate_hz, nw, k)
        i = int(np.argmax(fl))
        fc_hz.append(float(local[i]))
        mu_c.append(abs(ml[i]))
        m = 1 + 2 * tol * x.size / rate_hz / (2 * nw)  # independent frequencies searched
        log_pc.append(min(0.0, float(_log_sf(fl[i], k)) + np.log(m)))
    ic = [round(f / df) for f in fc_hz]
    carrier_p = float(_fisher_p(np.array(log_pc))[0])
    base |= {"carrier_p_value": carrier_p, "carrier_hz": round(float(np.mean(fc_hz)), 4),
             "bandwidth_hz": round(w_hz, 4), "min_offset_hz": round(d_min * df, 4)}  # fmt: skip
    n_bins = nfft // 2 + 1
    top = n_bins - 1 - int(np.ceil(w_hz / df))
    d_max = min(min(c - int(np.ceil(min_hz / df)) for c in ic), top - max(ic))
    if max_offset_hz is not None:
        d_max = min(d_max, int(max_offset_hz / df))
    if d_max < d_min:
        return {**base, "present": False, "p_value": 1.0, "delta_hz": None, "power": None,
                "reason": "no room for sidebands between DC and Nyquist"}  # fmt: skip
    d = np.arange(d_min, d_max + 1)
    # 2. selection on the first halves: the offset whose weaker side is strongest
    first = [line_f(x[:n], nfft, nw, k)[0] for x, n in zip(xs, n_half, strict=True)]
    s_lo = -2 * np.sum([_log_sf(f[c - d], k) for f, c in zip(first, ic, strict=True)], axis=0)
    s_hi = -2 * np.sum([_log_sf(f[c + d], k) for f, c in zip(first, ic, strict=True)], axis=0)
    j = int(np.argmax(np.minimum(s_lo, s_hi)))
    # Δ between the grid's points: the best weaker side on a local grid, first halves only
    local = d[j] * df + np.linspace(-df, df, REFINE)
    halves = [x[:n] for x, n in zip(xs, n_half, strict=True)]
    lo = -2 * np.sum([_log_sf(line_f_at(h, f - local, rate_hz, nw, k)[0], k)
                      for h, f in zip(halves, fc_hz, strict=True)], axis=0)  # fmt: skip
    hi = -2 * np.sum([_log_sf(line_f_at(h, f + local, rate_hz, nw, k)[0], k)
                      for h, f in zip(halves, fc_hz, strict=True)], axis=0)  # fmt: skip
    i = int(np.argmax(np.minimum(lo, hi)))
    delta = float(local[i])
    sign = -1 if lo[i] <= hi[i] else 1
    # 3. test of that side on the second halves, at the frequencies fixed above
    weak, strong = [], []
    for x, n, f in zip(xs, n_half, fc_hz, strict=True):
        fs_, _ = line_f_at(x[n : 2 * n], [f + sign * delta, f - sign * delta], rate_hz, nw, k)
        weak.append(_log_sf(fs_[0], k))
        strong.append(_log_sf(fs_[1], k))
    p_value = float(_fisher_p(np.array(weak))[0])
    # level and power from the whole recordings
    side = []
    for x, f in zip(xs, fc_hz, strict=True):
        fw, mw = line_f_at(x, [f + sign * delta, f - sign * delta], rate_hz, nw, k)
        side.append((fw[0], abs(mw[0]), abs(mw[1])))
    nu2 = 2 * k - 2
    lam_full = np.array([max(2 * (f * (nu2 - 2) / nu2 - 1), 0.0) for f, _, _ in side])
    lam_test = lam_full * np.array([n / x.size for n, x in zip(n_half, xs, strict=True)])
    power = _power(lam_test, k, alpha) if lam_test.sum() > 0 else None
    total_s = sum(x.size for x in xs) / rate_hz
    side_pow = np.mean([(a**2 + b**2) / 2 for _, a, b in side])
    level = 10 * np.log10(max(side_pow, 1e-300) / max(np.mean(np.square(mu_c)), 1e-300))
    return {**base, "present": bool(carrier_p < alpha and p_value < alpha),
            "p_value": p_value, "delta_hz": round(delta, 4),
            "side_tested": "lower" if sign < 0 else "upper",
            "other_side_p": float(_fisher_p(np.array(strong))[0]),
            "level_db": round(float(level), 2),
            "power": None if power is None else round(power, 3),
            "length_80_s": _length_80(lam_test, k, alpha, total_s)}  # fmt: skip


def _length_80(lam_test: np.ndarray, k: int, alpha: float, total_s: float) -> float | None:
    """Total recording length (s) at which the pooled F-test's power reaches 80 %: the
    non-centrality grows in proportion to the length."""
    if lam_test.sum() <= 0 or _power(lam_test * 1e4, k, alpha) < 0.8:
        return None
    lo, hi = 1e-4, 1e4
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if _power(lam_test * mid, k, alpha) < 0.8 else (lo, mid)
    return round(float(hi * total_s), 2)
