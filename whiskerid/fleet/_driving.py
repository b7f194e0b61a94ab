"""A whisker's f_1 and ζ from driving data, with no pluck: output-only identification.

While the robot drives, the whisker's signal is its response to the base's motion, which the
terrain excites over a broad band: ``S_y(f) = |H(f)|² S_b(f)``, with ``H`` the deflection per
unit base acceleration (near the first mode ``H ∝ 1/(1 − (f/f_1)² + 2iζ f/f_1)``: the
base-motion model the classifier divides out) and ``S_b`` the base acceleration's spectrum,
unknown but smooth on the scale of the resonance only *on average*: each terrain and speed
shapes it (a wheel's contact patch nulls the wavelengths it spans, at ``f = v/patch``;
joints, ripples and the motor add lines). So, as operational modal analysis does, the
identification leans on many stretches of driving rather than on one:

1. the drive is cut into blocks (each recording, or each :data:`BLOCK_S` of it); each
   block's spectrum is Welch's average of Hann windows of :data:`SEGMENT_S`;
2. narrow lines (the motor's tone, periodic textures) are masked: bins more than
   :data:`LINE_FACTOR` times the running median over ``±max(1 Hz, 2ζf_1)`` (wider than
   the resonance, so that its peak is never taken for a line), and two bins either side;
3. each block's log-spectrum over ``[0.8, 1.25] f_1`` is fitted by
   ``log S = log|H(f; f_1, ζ)|² + c_0 + c_1 x + c_2 x²`` (``x = ln(f/f_1)``: the base's
   spectrum, smooth over the band) with a Cauchy loss (scale 0.5 in ln): a null of the
   base's spectrum is an outlier, not a narrower peak;
4. the drive's ζ is the median of the blocks' (robust to the blocks whose terrain shapes
   the band), its f_1 that of one fit of every block's bins at once (f_1 and ζ shared,
   each block its own base spectrum, the same loss), started from the medians; the 1σ of
   both are the medians' standard errors from the blocks' spread, ``1.253 · 1.4826 MAD /
   √n``. The block fits are repeated once with the band centred on the median f_1 (a
   whisker whose f_1 moved keeps its peak in the middle of the band).

A drive is a *session* of the whisker's health log (``FLEET/health.csv``, the fleet table's
columns; each block takes a pluck's place), which ``whiskerid fleet check`` reads beside
the pluck sessions as a history of its own: a drive's values are compared with earlier
drives, not with plucks (the two estimates need not agree to the last percent).
"""

import datetime
import math
from dataclasses import dataclass, field

import numpy as np

#: Length of each Welch window (s): 0.1 Hz bins resolve a resonance of half-width ζf_1.
SEGMENT_S = 10.0
#: Blocks longer than this are cut (s); each block gets its own fit.
BLOCK_S = 60.0
#: Band fitted, relative to f_1.
BAND = (0.8, 1.25)
#: Bins this many times above the running median are lines, not resonance.
LINE_FACTOR = 3.0
#: Scale of the Cauchy loss on the log-spectrum's residuals.
LOSS_SCALE = 0.5
#: Order of the polynomial (in ln f) standing for the base's spectrum over the band.
ORDER = 2


@dataclass
class DriveFit:
    """What :func:`identify_driving` found.

    Attributes:
        status: ``ok``, or why not (``too short``, ``no resonance``).
        f1_hz, f1_std: First natural frequency and its 1σ (Hz).
        zeta, zeta_std: Its damping ratio and 1σ.
        blocks: Per block: ``name``, ``f1_hz``, ``zeta``, ``status``.
        seconds: Driving time used (s).
    """

    status: str
    f1_hz: float = math.nan
    f1_std: float = math.nan
    zeta: float = math.nan
    zeta_std: float = math.nan
    blocks: list[dict] = field(default_factory=list)
    seconds: float = 0.0


def _blocks(signals, rate_hz: float, block_s: float):
    """Cut each signal into blocks of at most ``block_s`` (the last at least half)."""
    n = round(block_s * rate_hz)
    for name, y in signals:
        y = np.asarray(y, dtype=float)
        starts = list(range(0, max(y.size - n // 2, 1), n))
        for k, a in enumerate(starts):
            piece = y[a : a + n] if k < len(starts) - 1 else y[a:]
            yield (f"{name}[{k}]" if len(starts) > 1 else name), piece


def block_spectrum(y, rate_hz: float, *, segment_s: float = SEGMENT_S):
    """Welch's spectrum of one block (Hann windows, half overlap, linear trend removed).

    Returns:
        ``(f, P)`` (Hz, signal units² per Hz).
    """
    from scipy.signal import welch

    nseg = min(round(segment_s * rate_hz), y.size)
    return welch(y, fs=rate_hz, nperseg=nseg, noverlap=nseg // 2, window="hann",
                 detrend="linear")  # fmt: skip


def line_mask(f, p, f1_hz: float, zeta: float) -> np.ndarray:
    """True where a bin is not a narrow line (see the module docstring)."""
    from scipy.ndimage import median_filter

    df = float(f[1] - f[0])
    half = max(1.0, 2 * zeta * f1_hz)
    med = median_filter(p, size=2 * int(half / df) + 1, mode="nearest")
    line = p >= LINE_FACTOR * med
    return ~(np.convolve(line, np.ones(5), "same") > 0)


def fit_block(f, p, f1_hz: float, zeta: float) -> tuple[float, float, str]:
    """f_1 and ζ of one block's spectrum, from the start ``f1_hz``, ``zeta`` (the record's).

    Returns:
        ``(f1, zeta, status)``; status ``ok`` or why not.
    """
    from scipy.optimize import least_squares

    keep = (f > BAND[0] * f1_hz) & (f < BAND[1] * f1_hz) & (p > 0)
    keep &= line_mask(f, p, f1_hz, zeta)
    if keep.sum() < 4 * (ORDER + 3):
        return math.nan, math.nan, "too few bins"
    ff, lp = f[keep], np.log(p[keep])
    x = np.vander(np.log(ff / f1_hz), ORDER + 1)

    def shape(f1, z):
        return -np.log((1 - (ff / f1) ** 2) ** 2 + (2 * z * ff / f1) ** 2)

    def residual(th):
        return lp - shape(th[0], math.exp(th[1])) - x @ th[2:]

    c0 = np.linalg.lstsq(x, lp - shape(f1_hz, zeta), rcond=None)[0]
    lo = [BAND[0] * f1_hz, math.log(1e-3)] + [-np.inf] * (ORDER + 1)
    hi = [BAND[1] * f1_hz, math.log(0.5)] + [np.inf] * (ORDER + 1)
    r = least_squares(residual, np.r_[f1_hz, math.log(zeta), c0], bounds=(lo, hi),
                      loss="cauchy", f_scale=LOSS_SCALE,
                      x_scale=np.r_[0.01 * f1_hz, 0.1, np.ones(ORDER + 1)])  # fmt: skip
    f1, z = float(r.x[0]), float(math.exp(r.x[1]))
    at_edge = not (lo[0] < f1 < hi[0]) or not (1e-3 < z < 0.5)
    if not r.success or at_edge or not (BAND[0] * f1_hz * 1.02 < f1 < BAND[1] * f1_hz / 1.02):
        return f1, z, "no resonance in the band"
    return f1, z, "ok"


def fit_joint(spectra, f1_hz: float, zeta: float) -> tuple[float, float, bool]:
    """f_1 and ζ shared by every block, each block with its own smooth base spectrum (the
    Cauchy loss over all bins: a null or a line in one block weighs little)."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    data = []
    for f, p in spectra:
        keep = (f > BAND[0] * f1_hz) & (f < BAND[1] * f1_hz) & (p > 0)
        keep &= line_mask(f, p, f1_hz, zeta)
        if keep.sum() >= 4 * (ORDER + 3):
            data.append((f[keep], np.log(p[keep]), np.vander(np.log(f[keep] / f1_hz), ORDER + 1)))
    if not data:
        return math.nan, math.nan, False
    k = ORDER + 1

    def residual(th):
        f1, z = th[0], math.exp(th[1])
        out = []
        for b, (ff, lp, x) in enumerate(data):
            shape = -np.log((1 - (ff / f1) ** 2) ** 2 + (2 * z * ff / f1) ** 2)
            out.append(lp - shape - x @ th[2 + b * k : 2 + (b + 1) * k])
        return np.concatenate(out)

    start = [f1_hz, math.log(zeta)]
    sparsity = lil_matrix((sum(d[0].size for d in data), 2 + k * len(data)), dtype=int)
    row = 0
    for b, (ff, lp, x) in enumerate(data):
        shape = -np.log((1 - (ff / f1_hz) ** 2) ** 2 + (2 * zeta * ff / f1_hz) ** 2)
        start += list(np.linalg.lstsq(x, lp - shape, rcond=None)[0])
        sparsity[row : row + ff.size, :2] = 1
        sparsity[row : row + ff.size, 2 + b * k : 2 + (b + 1) * k] = 1
        row += ff.size
    lo = [BAND[0] * f1_hz, math.log(1e-3)] + [-np.inf] * (k * len(data))
    hi = [BAND[1] * f1_hz, math.log(0.5)] + [np.inf] * (k * len(data))
    r = least_squares(residual, start, bounds=(lo, hi), loss="cauchy", f_scale=LOSS_SCALE,
                      jac_sparsity=sparsity, x_scale="jac")  # fmt: skip
    f1, z = float(r.x[0]), math.exp(float(r.x[1]))
    inside = BAND[0] * f1_hz * 1.02 < f1 < BAND[1] * f1_hz / 1.02 and 1e-3 < z < 0.5
    return f1, z, bool(r.success and inside)


def _median_and_error(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    med = float(np.median(v))
    if v.size < 3:
        return med, math.nan
    mad = 1.4826 * float(np.median(np.abs(v - med)))
    return med, 1.2533 * mad / math.sqrt(v.size)


def identify_driving(
    signals,
    rate_hz: float,
    f1_hz: float,
    zeta: float,
    *,
    block_s: float = BLOCK_S,
    min_blocks: int = 3,
) -> DriveFit:
    """f_1 and ζ of a whisker from its driving signals (see the module docstring).

    Args:
        signals: ``(name, samples)`` pairs: one channel at ``rate_hz`` (codes or volts),
            each a stretch of driving (a recording).
        rate_hz: Sample rate (Hz).
        f1_hz: Start value of f_1 (the whisker's record or last calibration, Hz).
        zeta: Start value of ζ.
        block_s: Longest block (s); a recording is cut into blocks of this length.
        min_blocks: Fewest usable blocks for a value with a 1σ.

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
        spectra.append((name, *block_spectrum(y, rate_hz)))
    centre = f1_hz
    for _ in range(2):  # the second pass centres the band on what the first found
        fits = [(name, *fit_block(f, p, centre, zeta)) for name, f, p in spectra]
        good = [(f1, z) for _, f1, z, s in fits if s == "ok"]
        if not good:
            break
        centre = float(np.median([f1 for f1, _ in good]))
    blocks = [{"name": n, "f1_hz": f1, "zeta": z, "status": s} for n, f1, z, s in
              (fits if spectra else [])]  # fmt: skip
    good = [b for b in blocks if b["status"] == "ok"]
    if len(good) < min_blocks:
        why = "too short" if len(spectra) < min_blocks else "no resonance"
        return DriveFit(why, blocks=blocks, seconds=seconds)
    f1, f1_std = _median_and_error([b["f1_hz"] for b in good])
    z, z_std = _median_and_error([b["zeta"] for b in good])
    # f_1 from all blocks' bins at once (a peak's place is shared, each block's base its
    # own); ζ stays the blocks' median: the joint fit's peak width takes up what the
    # blocks' bases leave over (measured: f_1 closer, ζ 10-30 % high on simulated drives)
    f1_j, _, ok = fit_joint([(f, p) for _, f, p in spectra], f1, z)
    if ok:
        f1 = f1_j
    return DriveFit("ok", f1, f1_std, z, z_std, blocks, seconds)


def health_row(whisker: str, session: str, fit: DriveFit, files: list[str]) -> dict:
    """The health log's row of one drive (the fleet table's columns; blocks as plucks)."""
    from ._table import COLUMNS

    row = {c: "" for c in COLUMNS}
    ok = [b for b in fit.blocks if b["status"] == "ok"]
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
        checks=f"{fit.seconds:.0f} s of driving, {len(ok)} of {len(fit.blocks)} blocks used",
        n_plucks=len(fit.blocks),
        f1_plucks=";".join(f"{b['f1_hz']:.10g}" for b in fit.blocks),
        zeta_plucks=";".join(f"{b['zeta']:.10g}" for b in fit.blocks),
        f1_pluck_sd=f"{sd([b['f1_hz'] for b in ok]):.4g}",
        zeta_pluck_sd=f"{sd([b['zeta'] for b in ok]):.4g}",
        pluck_status=";".join("ok" if b["status"] == "ok" else "outlier" for b in fit.blocks),
        files=";".join(files),
        fitted_at=datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    )
    return row
