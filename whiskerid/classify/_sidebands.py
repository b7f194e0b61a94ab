"""A statistical test for symmetric sidebands ``f_c ± Δ`` around a carrier line (Welch
spectra against a local floor).

Superseded: ``whiskerid analyze`` uses :func:`whiskerid.classify.line_sideband_test`. This
test is kept for comparison (``benchmarks/sideband_calibration.py``): on structured nulls
(random modulation in a band, free ringing, phase jitter) its p-values pile up at 1 and
``p < α`` comes up to 70 times as often as ``α``, and it loses most sidebands that fall
half-way between bins (its side-bin choice takes the largest floor ratio among neighbours,
then requires a power peak there).

Modulation of a response at ``f_c`` by a slower process of frequency ``Δ`` (contact that
opens and closes, stick–slip, a texture passing under the tip) puts two lines at
``f_c − Δ`` and ``f_c + Δ``: the paper's "dominant frequency sandwiched by two less
dominant components". A linear system driven at ``f_c`` has no such pair; two unrelated
lines falling symmetrically about the carrier by chance are the false alarm to control.

The test, on windows of a group of recordings:

1. **Spectra**: each window's Welch power spectrum (``k`` Hann segments of ``segment``
   samples, half overlapping). Under noise alone a bin's power is its mean times
   ``χ²_ν/ν`` with ``ν = 2k/(1 + 2ρ²(k − 1)/k)`` (``ρ = 0.167`` for half-overlapping
   Hann segments, Welch 1967).
2. **Local noise floor**: per bin, the median of the bins within ``±floor_bins`` (the
   bin and its two neighbours each side left out, so that a line does not lift its own
   floor), divided by the median of ``χ²_ν/ν``: the floor's mean. A bin's ratio ``R`` to
   it follows ``χ²_ν/ν`` under the null whatever the floor's shape (a whisker's
   resonance, a drivetrain's hump), as long as it varies slowly across ``±floor_bins``.
3. **A side** at ``c ± d`` bins counts only if it is a local maximum of the spectrum (the
   skirts of a broad resonance rise on both sides of its centre, but have no peaks); its
   statistic is the largest ``R`` of the three bins nearest ``c ± d`` (the carrier and
   ``Δ`` need not fall on bins), so its null tail is ``1 − (1 − P(χ²_ν/ν > R))³``.
   A pair's statistic is the smaller side; both sides exceed it with probability
   ``p = tail(s)²``.
4. **Selection and test on separate windows**: ``Δ`` is chosen on the even-numbered
   windows (largest mean log pair statistic over ``3 ≤ d`` bins up to what fits between
   DC and Nyquist), and tested on the odd-numbered ones, where it is fixed: the windows'
   ``p`` combine by Fisher's method (``−2 Σ ln p ~ χ²_{2m}``). With one window, the same
   window selects and tests, and ``p`` is Šidák-corrected for the number of offsets tried.
5. **Symmetry**: on the test windows, each side's peak is located by parabolic
   interpolation of the log power; the pair is symmetric when the mean ``|Δ₊ − Δ₋|`` is
   at most one bin.
6. **Consistency**: the share of test windows in which the pair is significant on its own
   (``p < 0.05``).

Sidebands are reported present when the combined ``p`` is below ``alpha``, the pair is
symmetric and at least half of the test windows show it.
"""

import numpy as np

#: Correlation of half-overlapping Hann segments (Welch 1967).
_HANN_OVERLAP_RHO = 0.167
MIN_OFFSET_BINS = 3  # the carrier's main lobe (Hann: ±2 bins) is not a sideband


def welch_dof(k: int) -> float:
    """Equivalent degrees of freedom of a Welch average of ``k`` half-overlapping Hann
    segments."""
    return 2 * k / (1 + 2 * _HANN_OVERLAP_RHO**2 * (k - 1) / k) if k > 1 else 2.0


def welch_power(x: np.ndarray, segment: int) -> tuple[np.ndarray, int]:
    """Welch power spectrum (arbitrary units) of ``x`` with Hann segments of ``segment``
    samples, half overlapping: ``(power, k)``."""
    hop = max(segment // 2, 1)
    starts = range(0, x.size - segment + 1, hop)
    w = np.hanning(segment)
    segs = np.stack([x[s : s + segment] for s in starts])
    segs = segs - segs.mean(axis=1, keepdims=True)
    power = np.mean(np.abs(np.fft.rfft(segs * w, axis=1)) ** 2, axis=0) / np.sum(w**2)
    return power, len(segs)


def floor_ratio(power: np.ndarray, dof: float, floor_bins: int) -> np.ndarray:
    """``R``: each bin's power over the local noise floor's mean (see the module
    docstring); ``χ²_ν/ν`` distributed under noise alone."""
    n = power.size
    offsets = np.concatenate([np.arange(-floor_bins, -2), np.arange(3, floor_bins + 1)])
    idx = np.arange(n)[:, None] + offsets[None, :]
    near = np.where((idx >= 1) & (idx < n), power[np.clip(idx, 0, n - 1)], np.nan)
    median = np.nanmedian(near, axis=1)
    from scipy import stats  # here, not at import: it costs a stream's start 0.5-4 s

    scale = stats.chi2.median(dof) / dof
    return power / np.maximum(median / scale, 1e-300)


def _side(ratio, power, j):
    """Best of the three bins nearest ``j``: ``(statistic, bin)``, 0 when not a peak."""
    n = ratio.size
    cand = [b for b in (j - 1, j, j + 1) if 1 <= b < n - 1]
    if not cand:
        return 0.0, j
    b = max(cand, key=lambda i: ratio[i])
    peak = power[b] >= power[b - 1] and power[b] >= power[b + 1]
    return (float(ratio[b]) if peak else 0.0), b


def _tail(s: float, dof: float) -> float:
    from scipy import stats

    single = stats.chi2.sf(s * dof, dof)
    return float(1 - (1 - single) ** 3)


def _pair(ratio, power, c, d, dof):
    lo, blo = _side(ratio, power, c - d)
    hi, bhi = _side(ratio, power, c + d)
    s = min(lo, hi)
    return s, (_tail(s, dof) ** 2 if s > 0 else 1.0), blo, bhi


def _interp_bin(power, b):
    """Parabolic peak position (bins) on log power."""
    if not 1 <= b < power.size - 1:
        return float(b)
    a, m, c = np.log(np.maximum(power[b - 1 : b + 2], 1e-300))
    den = a - 2 * m + c
    return float(b + (0.5 * (a - c) / den if den < 0 else 0.0))


def sideband_test(powers: np.ndarray, df_hz: float, carrier_hz: float, dof: float, *,
                  floor_hz: float = 5.0, alpha: float = 0.01, min_hz: float = 2.0,
                  max_offset_hz: float | None = None) -> dict:  # fmt: skip
    """Test windows' spectra for symmetric sidebands around ``carrier_hz``.

    Args:
        powers: Welch power spectra, shape ``(windows, bins)`` (bin ``k`` at ``k · df_hz``).
        df_hz: Bin spacing (Hz).
        carrier_hz: The carrier ``f_c`` (Hz).
        dof: Degrees of freedom of each bin (:func:`welch_dof`).
        floor_hz: Half-width of the local floor's neighbourhood (Hz), at least 8 bins.
        alpha: Significance level of the verdict.
        min_hz: Lowest frequency of a lower sideband (Hz). Below it lie a recording's
            drift and the ground's slow undulation, and with ``Δ ≈ f_c`` the carrier's
            second harmonic ``2f_c`` would pair with them (a harmonic is no sideband).
        max_offset_hz: Largest ``Δ`` tried (Hz); all that fit by default.

    Returns:
        A JSON-able dict: ``present``, ``p_value``, ``delta_hz`` (mean of the two sides'),
        ``asymmetry_hz`` (mean ``|Δ₊ − Δ₋|``), ``consistency`` (share of test windows
        significant alone), ``level_db`` (mean sideband power over the carrier's, dB),
        ``snr_db`` (over the floor), ``carrier_snr_db`` and ``carrier_p`` (the carrier bin
        against its floor), ``windows``.
    """
    powers = np.atleast_2d(np.asarray(powers, dtype=float))
    n_win, n_bins = powers.shape
    floor_bins = max(round(floor_hz / df_hz), 8)
    ratios = np.stack([floor_ratio(p, dof, floor_bins) for p in powers])
    c = round(carrier_hz / df_hz)
    d_max = min(c - max(int(np.ceil(min_hz / df_hz)), 2), n_bins - 2 - c)
    if max_offset_hz is not None:
        d_max = min(d_max, int(max_offset_hz / df_hz))
    carrier = [_side(r, p, c) for r, p in zip(ratios, powers, strict=True)]
    carrier_r = float(np.mean([s for s, _ in carrier]))
    out = {"carrier_hz": round(carrier_hz, 4), "windows": n_win,
           "carrier_snr_db": round(10 * np.log10(max(carrier_r, 1e-12)), 2),
           "carrier_p": _fisher([_tail(s, dof) if s > 0 else 1.0 for s, _ in carrier])}  # fmt: skip
    if d_max < MIN_OFFSET_BINS:
        return {**out, "present": False, "p_value": 1.0, "delta_hz": None,
                "asymmetry_hz": None, "consistency": 0.0, "level_db": None, "snr_db": None,
                "reason": "no room for sidebands between DC and Nyquist"}  # fmt: skip
    offsets = np.arange(MIN_OFFSET_BINS, d_max + 1)
    select = list(range(0, n_win, 2))
    test = list(range(1, n_win, 2)) or select
    score = [np.mean([np.log(max(_pair(ratios[w], powers[w], c, d, dof)[0], 1e-3))
                      for w in select]) for d in offsets]  # fmt: skip
    d = int(offsets[int(np.argmax(score))])
    pairs = [_pair(ratios[w], powers[w], c, d, dof) for w in test]
    ps = [p for _, p, _, _ in pairs]
    if test is select:  # one window: Šidák over the offsets tried
        ps = [float(1 - (1 - p) ** len(offsets)) for p in ps]
    p_value = _fisher(ps)
    c_pos = [_interp_bin(powers[w], b) for w, (_, b) in zip(test, [carrier[w] for w in test],
                                                                 strict=True)]  # fmt: skip
    d_lo = [cp - _interp_bin(powers[w], blo) for w, cp, (_, _, blo, _) in
            zip(test, c_pos, pairs, strict=True)]  # fmt: skip
    d_hi = [_interp_bin(powers[w], bhi) - cp for w, cp, (_, _, _, bhi) in
            zip(test, c_pos, pairs, strict=True)]  # fmt: skip
    asym = float(np.mean(np.abs(np.subtract(d_hi, d_lo)))) * df_hz
    side_power = np.mean([[powers[w, blo], powers[w, bhi]] for w, (_, _, blo, bhi) in
                          zip(test, pairs, strict=True)])  # fmt: skip
    carrier_power = np.mean([powers[w, b] for w, (_, b) in enumerate(carrier)])
    consistency = float(np.mean([p < 0.05 for p in ps]))
    symmetric = asym <= df_hz
    present = bool(p_value < alpha and symmetric and consistency >= 0.5)
    return {**out, "present": present, "p_value": p_value,
            "delta_hz": round(float(np.mean(d_lo + d_hi)) * df_hz, 4),
            "asymmetry_hz": round(asym, 4), "symmetric": bool(symmetric),
            "consistency": round(consistency, 3),
            "level_db": round(10 * np.log10(side_power / max(carrier_power, 1e-300)), 2),
            "snr_db": round(10 * np.log10(max(np.mean([s for s, _, _, _ in pairs]), 1e-12)), 2),
            }  # fmt: skip


def _fisher(ps) -> float:
    ps = np.clip(np.asarray(ps, dtype=float), 1e-300, 1.0)
    from scipy import stats

    return float(stats.chi2.sf(-2 * np.sum(np.log(ps)), 2 * ps.size)) if ps.size else 1.0
