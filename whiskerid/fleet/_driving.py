"""A whisker's f_1 and ζ from driving data, with no pluck: output-only identification.

While the robot drives, the whisker's signal is its response to the base's motion, which the
terrain excites over a broad band: ``S_y(f) = |H(f)|² S_b(f)``, with ``H`` the deflection per
unit base acceleration (near the first mode ``H ∝ 1/(1 − (f/f_1)² + 2iζ f/f_1)``: the
base-motion model the classifier divides out) and ``S_b`` the base acceleration's spectrum,
unknown and, within one stretch of driving, *not* smooth on the scale of the resonance. A
wheeled robot's base motion has two features the width of the peak (``2ζf_1`` ≈ 2–5 Hz):

* an **echo**: the rear wheels ride the front's profile ``τ = L/v`` later (``L`` the
  wheelbase), so the spectrum is rippled by ``|a + b e^{-2πifτ}|² ∝ 1 + r cos(2πfτ)``, a
  period ``v/L`` of 0.5–2 Hz at walking speeds and a depth of a factor of several;
* a **null**: the contact patch averages the ground over its length, so the spectrum has a
  ``sinc²(f·patch/v)`` factor, a null at ``f = v/patch`` that walks through f_1 as the
  speed changes (filled a little by what does not pass the patch, the drivetrain).

A resonance fitted with a smooth base takes both for the peak's shape: its f_1 is off by
several percent in a minute whose null sits near f_1, and ten minutes' median scatters by
0.8 % (1σ 0.25–1.6 %; measured on simulated drives). So each block's base spectrum is
modelled with both (their parameters found in the data, not given):

1. the drive is cut into blocks (each recording, or each :data:`BLOCK_S` of it); each
   block's spectrum is Welch's average of Hann windows of :data:`SEGMENT_S`;
2. narrow lines (the motor's tone, periodic textures) are masked: bins more than
   :data:`LINE_FACTOR` times the running median over ``±``:data:`LINE_HALF_HZ` (wider
   than a line's few bins, narrower than any resonance's half-width ``ζf_1``, so that the
   peak's top is never taken for a line whatever the start ζ), and two bins either side;
3. the echo's delay τ is the peak of the cepstrum of the block's whole log-spectrum
   (:func:`echo_delay`: the ripple runs over every frequency, the resonance over a few Hz);
4. each block's log-spectrum over ``[0.8, 1.25] f_1``, widened to ``±6ζf_1`` (six
   half-widths, :data:`WINGS`) for a broad peak, is fitted by
   ``ln S = −ln|1 − (f/f_1)² + 2iζf/f_1|² + ln(1 + r cos 2πfτ) + ln(sinc²(fa) + ε)
   + c_0 + c_1 x + c_2 x²`` (``x = ln(f/f_1)``), τ refined, the null's crossing time ``a``
   started from a grid of places (:data:`NULLS`, and none), with a Cauchy loss (scale 0.5
   in ln) against what is left (a line the mask missed); a first pass with a smooth base
   centres the band on the whisker's f_1 as it is now;
5. the drive's f_1 and ln ζ are the medians of the blocks', their 1σ ``c_n s/√m``
   (:func:`combine_blocks`): ``s`` the standard deviation of the ``m`` inlier blocks (a
   block more than :data:`OUTLIER_MADS` robust σ from the median is left out of it, the
   robust σ being ``1.4826 MAD`` with its small-sample factor, :func:`mad_factor`) and
   ``c_n`` the standard deviation of ``(median − truth)/(s/√m)`` for ``n`` normal blocks
   (1.37 for ten: the median's lower efficiency and the spread's own uncertainty at
   ``m − 1`` degrees of freedom). The blocks are independent stretches of driving, so their
   spread holds the base's leftovers as well as the periodogram's noise. (The earlier
   ``1.253 · 1.4826 MAD/√n`` looked the same, but a ten-value MAD is so uncertain that the
   errors over it scattered by 1.34 even for normal blocks.) ζ's 1σ also carries
   :data:`ZETA_SYSTEMATIC`, a bias all blocks share.

A drive is a *session* of the whisker's health log (``FLEET/health.csv``, the fleet table's
columns; each block takes a pluck's place), which ``whiskerid fleet check`` reads beside
the pluck sessions as a history of its own: a drive's values are compared with earlier
drives, not with plucks (the two estimates need not agree to the last percent).
"""

import datetime
import math
from dataclasses import dataclass, field, replace

import numpy as np

#: Length of each Welch window (s): 0.1 Hz bins resolve a resonance of half-width ζf_1.
SEGMENT_S = 10.0
#: Blocks longer than this are cut (s); each block gets its own fit.
BLOCK_S = 60.0
#: Band fitted, relative to f_1.
BAND = (0.8, 1.25)
#: Bins this many times above the running median are lines, not resonance.
LINE_FACTOR = 3.0
#: Half-width (Hz) of that running median: a line's Hann main lobe is ±2 bins (±0.2 Hz),
#: a resonance's half-width ``ζf_1`` at least 0.3 Hz (ζ 0.01 at 30 Hz), over which its
#: median is within 1.3 times its top. (A window scaled with the start ζ, ``±2ζf_1``, was
#: up to four half-widths of a whisker whose ζ is half the start's: the peak's top was
#: masked as a line and ζ came out 10–25 % high on such drives.)
LINE_HALF_HZ = 0.5
#: Scale of the Cauchy loss on the log-spectrum's residuals.
LOSS_SCALE = 0.5
#: Order of the polynomial (in ln f) standing for the base's spectrum over the band.
ORDER = 2
#: Delays of the base motion's echo searched (s): a wheelbase over the speed.
ECHO_S = (0.3, 4.0)
#: A block further than this many robust σ (:func:`robust_sigma`) from the drive's median
#: f_1 or ln ζ is an outlier: left out of the spread behind the drive's 1σ (the value, a
#: median, hardly moves), and marked ``outlier`` in the health log (kept out of the blocks'
#: spread that ``fleet check`` reads).
OUTLIER_MADS = 5.0
#: ζ's bias that every block shares, so that their spread cannot show it (relative). With
#: the band fixed at :data:`BAND`, a broad peak's wings reached the band's edges, where the
#: smooth base took them: ζ 0.08 read 16–29 % low (independent drives,
#: ``benchmarks/driving_damping_bias.py``). With the band widened to :data:`WINGS`
#: half-widths, over f_1 20.5–75 Hz and ζ 0.02–0.08 the cells' mean errors are −5.2 … +6.6 %
#: (rms 4.2 %; ζ 0.02 reads about 6 % high: the 10 s Hann window's leakage widens a narrow
#: peak). It is not corrected (its size depends on the base); the 1σ of ζ carries it in
#: quadrature.
ZETA_SYSTEMATIC = 0.04
#: Half-widths ``ζf_1`` the fitted band reaches either side of f_1 at least (the quick
#: look's ζ; :func:`band_for`): with :data:`BAND` alone a broad peak's wings reached the
#: band's edges, where the smooth base took them, and ζ read low.
WINGS = 6.0
#: Start places of the contact patch's null searched, relative to f_1.
NULLS = tuple(np.linspace(0.7, 1.5, 9))
#: Fewest blocks a drive needs (a 1σ from fewer has no finite spread, see
#: :func:`combine_blocks`); with :data:`BLOCK_S`, 240 s of driving.
MIN_BLOCKS = 4
#: A drive's peak must beat the smooth base alone by this much in the median block:
#: ``2Δcost/s²`` (:func:`peak_strength`: the robust cost's drop when the quick look's
#: resonance, searched over the band, is added to the smooth base, over the residuals'
#: robust variance; about a χ² of two degrees of freedom searched over the band where there
#: is no peak). White noise and a railed sensor gave 0–5 a block, drives of ζ 0.02–0.08
#: 14–700, and a two-axle robot whose contact patch's null sits near f_1 in half its
#: minutes (which the smooth base cannot follow) a median of 8–30.
PEAK_MIN = 6.0
#: The blocks' f_1 must agree within this fraction of the peak's half-width ``ζf_1`` (their
#: robust σ): a resonance's blocks scattered by 0.05–0.35 of it on simulated drives, fits to
#: noise by 0.5–1 and more.
SPREAD_MAX = 1.0
#: Where else a peak is searched for (relative to the record's f_1): a whisker whose f_1
#: moved out of :data:`BAND` must not be read at the band's edge.
WIDE = (0.5, 2.0)


@dataclass
class DriveFit:
    """What :func:`identify_driving` found.

    Attributes:
        status: ``ok``, or why not: ``too short``, ``no resonance`` (fewer than half the
            blocks fitted), or one of :func:`drive_status`'s.
        f1_hz, f1_std: First natural frequency and its 1σ (Hz).
        zeta, zeta_std: Its damping ratio and 1σ.
        blocks: Per block: ``name``, ``f1_hz``, ``zeta``, ``status``, ``peak`` (the
            strength of the quick look's peak in it, :func:`peak_strength`).
        seconds: Driving time used (s).
        f1_dof, zeta_dof: Degrees of freedom of the 1σ (inlier blocks less one): a z-score
            against it has t-like tails (the 1σ already holds their spread).
    """

    status: str
    f1_hz: float = math.nan
    f1_std: float = math.nan
    zeta: float = math.nan
    zeta_std: float = math.nan
    blocks: list[dict] = field(default_factory=list)
    seconds: float = 0.0
    f1_dof: int = 0
    zeta_dof: int = 0


def _blocks(signals, rate_hz: float, block_s: float):
    """Cut each signal into blocks of at most ``block_s`` (the last at least half)."""
    n = round(block_s * rate_hz)
    for name, y in signals:
        y = np.asarray(y, dtype=float)
        starts = list(range(0, max(y.size - n // 2, 1), n))
        for k, a in enumerate(starts):
            piece = y[a : a + n] if k < len(starts) - 1 else y[a:]
            yield (f"{name}[{k}]" if len(starts) > 1 else name), piece


def driving_blocks(seconds, rate_hz: float, block_s: float = BLOCK_S) -> int:
    """How many blocks :func:`identify_driving` gets from recordings of these lengths (s):
    blocks of ``block_s`` (the last at least half of it), each at least two Welch windows."""
    n = 0
    for s in seconds:
        size = round(s * rate_hz)
        y = np.zeros(max(size, 0))
        n += sum(p.size >= 2 * SEGMENT_S * rate_hz for _, p in _blocks([("", y)], rate_hz, block_s))
    return n


def block_spectrum(y, rate_hz: float, *, segment_s: float = SEGMENT_S):
    """Welch's spectrum of one block (Hann windows, half overlap, linear trend removed).

    Returns:
        ``(f, P)`` (Hz, signal units² per Hz).
    """
    from scipy.signal import welch

    nseg = min(round(segment_s * rate_hz), y.size)
    return welch(y, fs=rate_hz, nperseg=nseg, noverlap=nseg // 2, window="hann",
                 detrend="linear")  # fmt: skip


def line_mask(f, p) -> np.ndarray:
    """True where a bin is not a narrow line (see the module docstring)."""
    from scipy.ndimage import median_filter

    df = float(f[1] - f[0])
    half = max(LINE_HALF_HZ, 5 * df)
    med = median_filter(p, size=2 * int(half / df) + 1, mode="nearest")
    line = p >= LINE_FACTOR * med
    return ~(np.convolve(line, np.ones(5), "same") > 0)


def echo_delay(f, p) -> float:
    """The delay (s) of the base motion's strongest echo: the peak of the cepstrum of the
    log-spectrum (5–95 % of the band up to Nyquist, its 4 Hz running median removed) at
    quefrencies of :data:`ECHO_S`. A two-axle robot's rear wheels ride the front's profile
    ``L/v`` later, which ripples the spectrum as ``1 + r cos(2πfL/v)``."""
    from scipy.ndimage import median_filter

    df = float(f[1] - f[0])
    m = (f > 0.05 * f[-1]) & (f < 0.95 * f[-1]) & (p > 0)
    lp = np.log(p[m])
    lp = np.clip(lp - median_filter(lp, size=int(4.0 / df) | 1, mode="nearest"), -2, 2)
    n = 1 << max(16, int(lp.size).bit_length() + 4)
    c = np.abs(np.fft.rfft(lp * np.hanning(lp.size), n))
    q = np.fft.rfftfreq(n, df)
    k = (q > ECHO_S[0]) & (q < ECHO_S[1])
    return float(q[k][np.argmax(c[k])])


def peak_strength(f, p, centre_hz: float, f1_hz: float, zeta: float) -> float:
    """How far a resonance at ``f1_hz``, ``zeta`` beats the smooth base alone over the band
    about ``centre_hz``: ``2Δcost/s²`` (see :data:`PEAK_MIN`); 0 with too few bins."""
    from scipy.optimize import least_squares

    keep = (f > BAND[0] * centre_hz) & (f < BAND[1] * centre_hz) & (p > 0) & line_mask(f, p)
    if keep.sum() < 4 * (ORDER + 3) or not (f1_hz > 0 and zeta > 0):
        return 0.0
    ff, lp = f[keep], np.log(p[keep])
    x = np.vander(np.log(ff / centre_hz), ORDER + 1)

    def robust(y):
        c = least_squares(lambda c: y - x @ c, np.linalg.lstsq(x, y, rcond=None)[0],
                          loss="cauchy", f_scale=LOSS_SCALE)  # fmt: skip
        return c.cost, c.fun

    base_cost, _ = robust(lp)
    peak_cost, res = robust(lp - _block_model(ff, f1_hz, zeta, 0.0, 1.0, 0.0, 1.0))
    s = 1.4826 * float(np.median(np.abs(res)))
    return max(0.0, 2 * (base_cost - peak_cost) / max(s * s, 1e-12))


def peak_elsewhere(spectra, f1_hz: float, rate_hz: float) -> tuple[float, float, float]:
    """The most prominent peak of the blocks' median log-spectrum in :data:`BAND` and
    outside it (within :data:`WIDE` of ``f1_hz``, below 0.95 Nyquist), lines masked.

    Prominence: the spectrum smoothed over ``±0.02 f1`` less its running median over
    ``±0.25 f1`` (in ln; a resonance of ζ stands out by about ``ln(1/4ζ²)``).

    Returns:
        ``(prominence in the band, prominence outside, where outside (Hz))``.
    """
    from scipy.ndimage import median_filter, uniform_filter1d

    f = spectra[0][1]
    logs = []
    for _, fb, pb in spectra:
        lp = np.where((pb > 0) & line_mask(fb, pb), np.log(np.maximum(pb, 1e-300)), np.nan)
        logs.append(lp)
    with np.errstate(all="ignore"):
        lp = np.nanmedian(np.array(logs), axis=0) if len(logs) > 1 else logs[0]
    ok = np.isfinite(lp)
    if ok.sum() < 10:
        return 0.0, 0.0, math.nan
    lp = np.interp(f, f[ok], lp[ok])
    df = float(f[1] - f[0])
    smooth = uniform_filter1d(lp, max(1, int(0.04 * f1_hz / df)) | 1, mode="nearest")
    prom = smooth - median_filter(lp, size=max(3, int(0.5 * f1_hz / df)) | 1, mode="nearest")
    band = (f > BAND[0] * f1_hz) & (f < BAND[1] * f1_hz)
    wide = (f > WIDE[0] * f1_hz) & (f < min(WIDE[1] * f1_hz, 0.95 * rate_hz / 2)) & (f > 1.0)
    out = wide & ~band
    inside = float(np.max(prom[band])) if band.any() else 0.0
    if not out.any():
        return inside, 0.0, math.nan
    k = int(np.argmax(np.where(out, prom, -np.inf)))
    return inside, float(prom[k]), float(f[k])


def _block_model(ff, f1, z, r, tau, a, floor):
    """ln of the block's spectrum less its smooth part: resonance, echo ripple, patch null."""
    return (-np.log((1 - (ff / f1) ** 2) ** 2 + (2 * z * ff / f1) ** 2)
            + np.log1p(r * np.cos(2 * np.pi * ff * tau))
            + np.log(np.sinc(ff * a) ** 2 + floor))  # fmt: skip


def band_for(zeta: float, f1_hz: float, rate_hz: float) -> tuple[float, float]:
    """The band fitted about f_1 (relative): :data:`BAND`, widened to ``±``:data:`WINGS`
    half-widths ``ζf_1`` where the peak is broad (at most 0.5–1.5 f_1, below 0.95 Nyquist)."""
    lo = max(min(BAND[0], 1 - WINGS * zeta), 0.5)
    hi = min(max(BAND[1], 1 + WINGS * zeta), 1.5, 0.95 * rate_hz / 2 / f1_hz)
    return lo, max(hi, min(BAND[1], 0.95 * rate_hz / 2 / f1_hz))


def fit_block(f, p, f1_hz: float, zeta: float, *, base: bool = True,
              band: tuple[float, float] = BAND) -> tuple[float, float, str]:  # fmt: skip
    """f_1 and ζ of one block's spectrum, from the start ``f1_hz``, ``zeta`` (the record's).

    The base's spectrum over the band is a quadratic in ``ln f`` times the echo ripple
    ``1 + r cos(2πfτ)`` (τ from :func:`echo_delay`, refined) times a contact patch's
    ``sinc²(fa) + ε`` (a box average over the patch, ``a`` its crossing time ``patch/v``;
    ``ε`` the part of the base's motion that does not pass the patch, the drivetrain's). The
    null's place is searched on a grid over the band and beyond (or none: ``a`` small).
    With ``base=False`` the echo and the null are left out (a quick first look).

    Returns:
        ``(f1, zeta, status)``; status ``ok`` or why not.
    """
    from scipy.optimize import least_squares

    keep = (f > band[0] * f1_hz) & (f < band[1] * f1_hz) & (p > 0)
    keep &= line_mask(f, p)
    if keep.sum() < 4 * (ORDER + 7):
        return math.nan, math.nan, "too few bins"
    ff, lp = f[keep], np.log(p[keep])
    x = np.vander(np.log(ff / f1_hz), ORDER + 1)
    tau = echo_delay(f, p)

    def residual(th):
        shape = _block_model(ff, th[0], math.exp(th[1]), math.tanh(th[2]), th[3], th[4],
                             math.exp(th[5]))  # fmt: skip
        return lp - shape - x @ th[6:]

    lo = [band[0] * f1_hz, math.log(1e-3), -3.0, ECHO_S[0], 0.0, -12.0] + [-np.inf] * (ORDER + 1)
    hi = [band[1] * f1_hz, math.log(0.5), 3.0, ECHO_S[1], 2 / f1_hz, 2.0] + [np.inf] * (ORDER + 1)
    tau = min(max(tau, ECHO_S[0] * 1.001), ECHO_S[1] * 0.999)
    best = None
    nulls = [*NULLS, 1e3] if base else [1e3]  # the null's place / f_1 (1e3: none)
    for null in nulls:
        th = np.r_[f1_hz, math.log(zeta), math.atanh(0.5 if base else 0.0), tau, 1 / (null * f1_hz),
                   math.log(0.05), np.zeros(ORDER + 1)]  # fmt: skip
        th[6:] = np.linalg.lstsq(x, residual(th), rcond=None)[0]
        free = np.ones(th.size, bool) if base else np.r_[True, True, False, False, False, False,
                                                            np.ones(ORDER + 1, bool)]  # fmt: skip

        def res_free(u, th=th, free=free):
            full = th.copy()
            full[free] = u
            return residual(full)

        bounds = (np.array(lo)[free], np.array(hi)[free])
        r = least_squares(res_free, th[free], bounds=bounds, loss="cauchy", f_scale=LOSS_SCALE,
                          max_nfev=200,
                          x_scale=np.r_[0.01 * f1_hz, 0.1, 0.3, 0.01 * tau, 0.01 * th[4] + 1e-9,
                                        np.ones(ORDER + 2)][free])  # fmt: skip
        if best is None or r.cost < best.cost:
            best = r
    f1, z = float(best.x[0]), float(math.exp(best.x[1]))  # f_1 and ln ζ are always free
    inside = band[0] * f1_hz * 1.02 < f1 < band[1] * f1_hz / 1.02 and 1.1e-3 < z < 0.45
    if not inside:
        return f1, z, "no resonance in the band"
    return f1, z, "ok"


#: Croux & Rousseeuw's (1992) small-sample factors making ``1.4826 MAD`` of ``n`` normal
#: values an unbiased σ, ``n`` = 2 … 9 (beyond, ``n/(n − 0.8)``).
_MAD_SMALL = {2: 1.196, 3: 1.495, 4: 1.363, 5: 1.206, 6: 1.200, 7: 1.140, 8: 1.129, 9: 1.107}


def mad_factor(n: int) -> float:
    """Factor making ``1.4826 · MAD`` of ``n`` normal values an unbiased σ (``n ≥ 2``)."""
    return _MAD_SMALL.get(n, n / (n - 0.8))


def robust_sigma(values) -> float:
    """``1.4826 · MAD · mad_factor(n)``: a σ of ``values`` that a few outliers hardly move."""
    v = np.asarray(values, dtype=float)
    mad = float(np.median(np.abs(v - np.median(v))))
    return 1.4826 * mad * mad_factor(v.size) if v.size > 1 else math.nan


#: Fewest blocks from which an outlier is ever left out: with fewer, a MAD is too often
#: small by chance (half the values close together) and a rejection leaves a spread that is
#: far too tight; every block is kept and a far one widens the 1σ.
MIN_FOR_OUTLIERS = 8
#: For ``n`` blocks: the standard deviation of ``(median − truth)/(s/√m)`` for normal
#: blocks, ``s`` the standard deviation of the ``m`` inliers (3·10⁵ Monte-Carlo draws per
#: ``n``; it holds the median's lower efficiency, the spread's own uncertainty and what
#: leaving outliers out does). Beyond 20 blocks, 1.25 (the median's large-``n`` factor
#: √(π/2) with what the spread adds).
_MEDIAN_SD = {4: 1.809, 5: 1.560, 6: 1.398, 7: 1.408, 8: 1.579, 9: 1.544, 10: 1.367,
              11: 1.404, 12: 1.314, 13: 1.344, 14: 1.291, 15: 1.318, 16: 1.273, 17: 1.304,
              18: 1.274, 19: 1.297, 20: 1.267}  # fmt: skip


def inliers(values) -> np.ndarray:
    """True for the values within :data:`OUTLIER_MADS` robust σ of their median (all of
    them with fewer than :data:`MIN_FOR_OUTLIERS` values)."""
    v = np.asarray(values, dtype=float)
    if v.size < MIN_FOR_OUTLIERS:
        return np.ones(v.size, bool)
    return np.abs(v - np.median(v)) <= OUTLIER_MADS * robust_sigma(v)


def combine_blocks(values) -> tuple[float, float, int]:
    """The drive's value, its 1σ and degrees of freedom from its blocks' values.

    The median (robust to a block that a null pulled off), with 1σ ``c_n s/√m``: ``s`` the
    standard deviation of the ``m`` inliers (:func:`inliers`), ``c_n`` the standard
    deviation of ``(median − truth)/(s/√m)`` for ``n`` normal blocks (1.37 for ten). The
    earlier ``1.253 · 1.4826 MAD/√n`` has the same mean but a ten-value MAD is so uncertain
    that its errors over the 1σ scattered by 1.34 for normal blocks (0.1 % beyond 7.8,
    not 3.3); ``s`` has ``ν = m − 1`` degrees of freedom, reported with the value (the
    errors over the 1σ scatter by 1, with t-like tails of about ν degrees of freedom).

    Returns:
        ``(value, sigma, dof)``; sigma NaN with fewer than 4 values.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 4:
        return (float(np.median(v)) if v.size else math.nan), math.nan, max(v.size - 1, 0)
    w = v[inliers(v)]
    scale = _MEDIAN_SD.get(v.size, 1.25)
    return float(np.median(v)), float(np.std(w, ddof=1)) / math.sqrt(w.size) * scale, w.size - 1


def identify_driving(
    signals,
    rate_hz: float,
    f1_hz: float,
    zeta: float,
    *,
    block_s: float = BLOCK_S,
    min_blocks: int = MIN_BLOCKS,
) -> DriveFit:
    """f_1 and ζ of a whisker from its driving signals (see the module docstring).

    Args:
        signals: ``(name, samples)`` pairs: one channel at ``rate_hz`` (codes or volts),
            each a stretch of driving (a recording).
        rate_hz: Sample rate (Hz).
        f1_hz: Start value of f_1 (the whisker's record or last calibration, Hz).
        zeta: Start value of ζ.
        block_s: Longest block (s); a recording is cut into blocks of this length.
        min_blocks: Fewest usable blocks for a value with a 1σ (at least 4: with ν = 2
            degrees of freedom or fewer the standard error's t has no finite spread).

    Returns:
        A :class:`DriveFit`.
    """
    if not (f1_hz > 0 and 0 < zeta < 1 and rate_hz > 0):
        raise ValueError(f"f1_hz {f1_hz!r}, zeta {zeta!r}, rate_hz {rate_hz!r} must be positive")
    if BAND[1] * f1_hz >= rate_hz / 2:
        raise ValueError(f"f1 {f1_hz:.4g} Hz is too close to Nyquist ({rate_hz / 2:.4g} Hz)")
    spectra = []
    seconds = 0.0
    for name, y in _blocks(signals, rate_hz, block_s):
        if y.size < 2 * SEGMENT_S * rate_hz:
            continue
        seconds += y.size / rate_hz
        if not np.all(np.isfinite(y)):
            raise ValueError(f"{name.split('[')[0]}: holds samples that are not finite")
        spectra.append((name, *block_spectrum(y, rate_hz)))
    if len(spectra) < min_blocks:
        return DriveFit("too short", seconds=seconds)
    centre = f1_hz
    # a quick look (a smooth base) centres the band on the whisker's f_1 as it is now
    quick = [fit_block(f, p, centre, zeta, base=False) for _, f, p in spectra]
    strength = [peak_strength(f, p, centre, f1, z) if s == "ok" else 0.0
                for (_, f, p), (f1, z, s) in zip(spectra, quick, strict=True)]  # fmt: skip
    good = [(f1, z) for (f1, z, s), g in zip(quick, strength, strict=True)
            if s == "ok" and g >= PEAK_MIN]  # fmt: skip
    start = zeta
    if good:  # and starts ζ there (the null and the ripple are searched from it)
        centre, start = (float(np.median(v)) for v in zip(*good, strict=True))
    band = band_for(start, centre, rate_hz)  # wide enough for a broad peak's wings
    fits = [(name, *fit_block(f, p, centre, start, band=band)) for name, f, p in spectra]
    blocks = [{"name": n, "f1_hz": f1, "zeta": z, "status": s, "peak": g}
              for (n, f1, z, s), g in zip(fits, strength, strict=True)]  # fmt: skip
    good = [b for b in blocks if b["status"] == "ok"]
    if len(good) < max(min_blocks, len(blocks) / 2):
        return DriveFit("no resonance", blocks=blocks, seconds=seconds)
    f1, f1_std, f1_dof = combine_blocks([b["f1_hz"] for b in good])
    ln_z, ln_z_std, zeta_dof = combine_blocks([math.log(b["zeta"]) for b in good])
    z = math.exp(ln_z)  # ζ's blocks scatter in proportion (a geometric mean)
    fit = DriveFit("ok", f1, f1_std, z, math.nan, blocks, seconds, f1_dof, zeta_dof)
    if not (math.isfinite(f1_std) and math.isfinite(ln_z_std)):
        return replace(fit, status="too short")
    fit.zeta_std = z * math.hypot(ln_z_std, ZETA_SYSTEMATIC)
    fit.status = drive_status(fit, spectra, f1_hz, rate_hz)
    return fit


def drive_status(fit: DriveFit, spectra, f1_hz: float, rate_hz: float) -> str:
    """``ok``, or why a drive's combined value is not a whisker's resonance.

    * ``no resonance``: the drive's peak beats the smooth base by less than
      :data:`PEAK_MIN` in the median block;
    * ``identical blocks``: the blocks' values do not scatter at all (one recording given
      several times): a 1σ of 0 is never reported;
    * ``no consistent peak``: the blocks' f_1 scatter by more than :data:`SPREAD_MAX` of the
      peak's half-width (fits to noise, not to one resonance);
    * ``peak at the band's edge``: f_1 within 3 % of the edge of the band about the record's
      f_1 (the whisker's resonance may lie beyond it);
    * ``peak outside the band``: the spectrum's most prominent peak lies outside the band
      about the record's f_1 and stands out more than the one inside (the whisker changed
      beyond 0.8–1.25 of its record, or the record is another whisker's).
    """
    good = [b for b in fit.blocks if b["status"] == "ok"]
    if np.median([b["peak"] for b in fit.blocks]) < PEAK_MIN:
        return "no resonance"
    f1s = np.array([b["f1_hz"] for b in good])
    zs = np.array([b["zeta"] for b in good])
    if np.ptp(f1s) == 0 or np.ptp(zs) == 0 or not (fit.f1_std > 0 and fit.zeta_std > 0):
        return "identical blocks"
    inside, outside, _ = peak_elsewhere(spectra, f1_hz, rate_hz)
    if outside > max(inside, 1.0):
        return "peak outside the band"
    if robust_sigma(f1s[inliers(f1s)]) > SPREAD_MAX * fit.zeta * fit.f1_hz:
        return "no consistent peak"
    if not (BAND[0] * 1.03 < fit.f1_hz / f1_hz < BAND[1] / 1.03):
        return "peak at the band's edge"
    return "ok"


def drive_problem(fit: DriveFit) -> str:
    """A sentence for a drive whose status is not ``ok`` (for the command line)."""
    return {
        "too short": "too little driving for a 1-sigma",
        "no resonance": "no resonance peak stands out of the base's spectrum",
        "identical blocks": "its blocks are identical (the same recording more than once?)",
        "no consistent peak": "its blocks' peaks do not agree (noise, or no resonance in the band)",
        "peak at the band's edge": "f1 lies at the edge of 0.8-1.25 times the record's f1",
        "peak outside the band": "a stronger peak lies outside 0.8-1.25 times the record's f1",
    }.get(fit.status, fit.status)


def _outliers(blocks) -> set[int]:
    ok = [i for i, b in enumerate(blocks) if b["status"] == "ok"]
    out: set[int] = set()
    if len(ok) < 3:
        return out
    for key, fn in (("f1_hz", float), ("zeta", math.log)):
        keep = inliers([fn(blocks[i][key]) for i in ok])
        out |= {i for i, k in zip(ok, keep, strict=True) if not k}
    return out


def health_row(whisker: str, session: str, fit: DriveFit, files: list[str]) -> dict:
    """The health log's row of one drive (the fleet table's columns; blocks as plucks; a
    block far from the others, see :data:`OUTLIER_MADS`, marked ``outlier``)."""
    from ._table import COLUMNS

    row = {c: "" for c in COLUMNS}
    far = _outliers(fit.blocks)
    ok = [b for i, b in enumerate(fit.blocks) if b["status"] == "ok" and i not in far]
    sd = lambda v: float(np.std(v, ddof=1)) if len(v) > 1 else math.nan  # noqa: E731
    row.update(
        whisker=whisker,
        session=session,
        status=fit.status,
        f1_hz=f"{fit.f1_hz:.10g}",
        f1_std=f"{fit.f1_std:.4g}",
        zeta=f"{fit.zeta:.10g}",
        zeta_std=f"{fit.zeta_std:.4g}",
        uncertainty="blocks",
        checks=(
            f"{fit.seconds:.0f} s of driving, {len(ok)} of {len(fit.blocks)} blocks used; "
            f"1 sigma with {fit.f1_dof} (f1), {fit.zeta_dof} (zeta) degrees of freedom"
        ),
        n_plucks=len(fit.blocks),
        f1_plucks=";".join(f"{b['f1_hz']:.10g}" for b in fit.blocks),
        zeta_plucks=";".join(f"{b['zeta']:.10g}" for b in fit.blocks),
        f1_pluck_sd=f"{sd([b['f1_hz'] for b in ok]):.4g}",
        zeta_pluck_sd=f"{sd([b['zeta'] for b in ok]):.4g}",
        pluck_status=";".join(
            "ok" if b["status"] == "ok" and i not in far else "outlier"
            for i, b in enumerate(fit.blocks)
        ),
        files=";".join(files),
        fitted_at=datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    )
    return row
