"""Is what a fit leaves white? The residual's spectrum against the sensor's own noise spectrum.

The lag-1 autocorrelation of the residuals is a poor whiteness measure for a decay: a misfit
at the whisker's own frequency ``f`` sampled at ``f_s`` moves it by at most ``cos(2πf/f_s)``
times its share of the variance, and the sensor's noise itself need not be white (an
accelerometer's digital filter, a resampled clock: the real cantilever's noise has lag-1
0.14–0.36). "White" here means *indistinguishable from the sensor noise*: the residual's
power spectral density near each fitted mode, where a model error lives, against the
noise's density at the same frequencies.

**Spectra.** Welch's average of Hann-windowed periodograms, segments of :data:`PERIODS`
periods of the lowest mode (at least 64 samples), half overlapping, each segment's mean and
slope removed; non-uniform samples are first interpolated onto their median step. For
Gaussian noise each bin is a ``χ²_ν/ν`` variable with ``ν ≈ 1.89K`` (``K`` segments; Hann
with half overlap), and a band of ``B`` bins carries about ``ν·B/2`` degrees of freedom
(neighbouring Hann bins are correlated; 2 rather than the window's noise bandwidth of 1.5
bins gives pulls of the ratio with sd 0.96–0.99 on simulated coloured noise, AR(1) 0.5).

**The noise reference.** From a quiet stretch of the same recording (the hold before the
release, the rest after the decay) with the same segments, when it holds one; otherwise from
the residual's own spectrum in flanks beside the band, ``w`` to ``3w`` from the line on both
sides (their median, corrected to a mean), where the model has no signal to leave: the noise
is taken smooth in frequency across the band. Flanks that meet another fitted mode's band
are left out.

**The ratio.** ``ρ = mean residual PSD within ±w of the line / mean reference PSD there``
(``w =`` :data:`HALF_WIDTH` ``· f``). Under a model that describes the decay ``ρ ≈ 1`` and
``ρ`` is at most an ``F(ν_r, ν_ref)`` variable; its p-value and rough 1σ are reported. It
is a diagnostic, not a status rule: it says how much of the misfit stands above the noise,
and where.
"""

import numpy as np

from .._data import median, spectral_window
from .._numerics import f_sf

#: Welch segment length in periods of the lowest fitted mode.
PERIODS = 32
#: Half-width of a mode's band, as a fraction of its frequency.
HALF_WIDTH = 0.125
#: Fewest samples per segment.
MIN_SEGMENT = 64
#: A band is called white when its F-test p-value is at least this.
P_WHITE = 1e-3


def welch_psd(x, dt: float, nseg: int) -> tuple[np.ndarray, np.ndarray, int]:
    """One-sided PSD by Welch (Hann, half overlap, mean and slope removed per segment).

    Returns:
        ``(f, psd, K)``: frequencies (Hz), density (units²/Hz) and the number of segments.
    """
    x = np.asarray(x, dtype=float)
    step = max(nseg // 2, 1)
    starts = np.arange(0, x.size - nseg + 1, step)
    w = spectral_window(nseg, True)[0]  # kept per length, read-only
    s = np.arange(nseg) - (nseg - 1) / 2
    if starts.size:  # every segment at once (one FFT call, not one per segment)
        segs = np.lib.stride_tricks.sliding_window_view(x, nseg)[starts]
        segs = segs - segs.mean(axis=1, keepdims=True) - np.outer(segs @ s, s) / (s @ s)
        acc = np.sum(np.abs(np.fft.rfft(segs * w, axis=1)) ** 2, axis=0)
    else:
        acc = np.zeros(nseg // 2 + 1)
    psd = 2 * dt * acc / (max(starts.size, 1) * np.sum(w**2))
    return np.fft.rfftfreq(nseg, dt), psd, int(starts.size)


def _uniform(t, r):
    t, r = np.asarray(t, float), np.asarray(r, float)
    steps = np.diff(t)
    dt = float(median(steps))
    if np.all(np.abs(steps - dt) <= 1e-6 * abs(dt)):  # np.allclose's test, its cost less
        return r, dt
    return np.interp(t[0] + dt * np.arange(t.size), t, r), dt


def _dof(k_segments: int, n_bins: int) -> float:
    return max(1.89 * k_segments * n_bins / 2.0, 1.0)


def spectral_whiteness(t, residual, lines_hz, *, quiet=None) -> dict:
    """The residual's PSD near each line against the noise's (see the module docstring).

    Args:
        t: Sample times (s).
        residual: The fit's residual at ``t`` (data minus model, any units).
        lines_hz: Frequencies of the fitted modes (Hz).
        quiet: Samples of a quiet stretch of the same recording at the same rate, or None.

    Returns:
        ``{"reference": "quiet" | "flanks", "segment_s", "bands": [...], "worst_ratio",
        "white"}``; each band has ``f_hz``, ``half_width_hz``, ``ratio``, ``ratio_std``,
        ``p_value``, ``dof`` and ``white``. A band the recording cannot resolve (too short,
        or above the Nyquist frequency) is left out.
    """
    r, dt = _uniform(t, residual)
    lines = sorted(float(f) for f in lines_hz if 0 < f < 0.5 / dt)
    out = {"reference": "flanks", "segment_s": None, "bands": [], "worst_ratio": None,
           "white": None}  # fmt: skip
    if not lines:
        return out
    nseg = max(MIN_SEGMENT, round(PERIODS / (lines[0] * dt)))
    if r.size < 2 * nseg:
        nseg = r.size // 2
    if nseg < MIN_SEGMENT:
        return out
    f, p, k = welch_psd(r, dt, nseg)
    ref_psd = None
    if quiet is not None and np.size(quiet) >= nseg:
        _, ref_psd, kq = welch_psd(quiet, dt, nseg)
        out["reference"] = "quiet"
    out["segment_s"] = nseg * dt
    half = [HALF_WIDTH * g for g in lines]
    for g, w in zip(lines, half, strict=True):
        band = np.abs(f - g) <= w
        if band.sum() < 1:
            continue
        nb = int(band.sum())
        if ref_psd is not None:
            ref, nu_ref = float(ref_psd[band].mean()), _dof(kq, nb)
        else:
            flank = (np.abs(f - g) > w) & (np.abs(f - g) <= 3 * w) & (f > 0)
            for h, wh in zip(lines, half, strict=True):
                if h != g:
                    flank &= np.abs(f - h) > wh
            if flank.sum() < 3:
                continue
            nf = int(flank.sum())
            nu_ref = _dof(k, nf)
            # the median of χ²_ν/ν is about (1 − 2/(9ν))³ of its mean
            nu_bin = _dof(k, 1) * 2.0
            ref = float(median(p[flank])) / (1 - 2 / (9 * nu_bin)) ** 3
            nu_ref *= 2 / np.pi  # a median is less efficient than a mean
        nu_r = _dof(k, nb)
        ratio = float(p[band].mean() / max(ref, 1e-300))
        pval = float(f_sf(ratio, nu_r, nu_ref))
        out["bands"].append({
            "f_hz": g, "half_width_hz": w, "ratio": ratio,
            "ratio_std": ratio * float(np.sqrt(2 / nu_r + 2 / nu_ref)),
            "p_value": pval, "dof": [nu_r, nu_ref], "white": bool(pval >= P_WHITE),
        })  # fmt: skip
    if out["bands"]:
        out["worst_ratio"] = max(b["ratio"] for b in out["bands"])
        out["white"] = all(b["white"] for b in out["bands"])
    return out


def residual_spectra(cal, obs) -> list[dict]:
    """:func:`spectral_whiteness` of every recording of a calibration, at its fitted modes'
    frequencies (``f1_hz``, ``f2_hz`` …), against each recording's quiet stretch when it has
    one."""
    names = ["f1_hz"] + [f"f{k}_hz" for k in range(2, 32)]
    lines = [float(cal.params[k]["value"]) for k in names if k in cal.params]
    return [
        spectral_whiteness(t, y - m, lines, quiet=getattr(o, "quiet", None))
        for (t, y, m), o in zip(cal.curves, obs, strict=True)
    ]
