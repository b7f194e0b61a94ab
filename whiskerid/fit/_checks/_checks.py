"""What a converged fit must still pass before its numbers are called ``ok``, and
uncertainties that stay honest when the residuals are not white noise.

A least-squares fit converges to *something* whatever the data: a held segment taken for a
decay, a sine fitted as a pluck, the wrong whisker's record. The checks here look at what the
fit left behind and at what it found, each with a name, a threshold and a sentence:

* ``correlated-residuals``: residuals with lag-1 autocorrelation above 0.5 are not noise but
  an unmodelled signal; the white-noise 1σ is then too small (it is replaced, see below);
* ``residual-peak``: a spectral line in the residuals far above their noise floor (a mode,
  a drive or a ringing the model does not explain);
* ``at-bound``: ζ at a bound of its range;
* ``zeta-large``: ζ above 0.2, implausible for a whisker (coil springs and thin beams ring
  with ζ of a few percent);
* ``far-from-nominal``: f_1 outside 0.4–2.5 times the record's (EI outside 0.16–6.25
  times): the record is probably not this whisker's;
* ``imprecise``: f_1 known to worse than 0.5 % or ζ to worse than 10 % (1σ);
* ``aliased``: f_1 and ``rate − f_1`` look alike in the samples of a free decay; the fitted
  one is above the Nyquist frequency of the fastest decay recording, or its alias is nearer
  the record's f_1 (the choice rests on the start, not the data);
* ``mode-1-weak``: a free decay explained by a higher mode while mode 1 carries under a fifth
  of its RMS: a pluck or tap rings mostly in mode 1, so the fit has probably taken the data's
  main line for an aliased higher mode (f_1 off by the mode ratio).

When the residuals are correlated, the covariance ``s²(JᵀJ)⁻¹`` assumes information that is
not there (each sample counted as independent). The heteroskedasticity-and-autocorrelation
consistent (HAC, Newey–West) sandwich ``(JᵀJ)⁻¹ (Σ_l w_l Γ_l) (JᵀJ)⁻¹``, with ``Γ_l`` the
lag-``l`` autocovariance of the per-sample scores ``J_t r_t`` within each recording and
Bartlett weights ``w_l = 1 − l/(L+1)`` up to the lag ``L`` where the residuals' autocorrelation
has died out, is then reported instead (each σ never below its white-noise value), and the
report says so.
"""

import numpy as np

from ...io import timestamp_rate
from .._data import fast_length, line_fit, median, quantum, spectral_window
from .._linear import ZETA_MAX

#: Lag-1 autocorrelation of the residuals above which they are not treated as white noise.
LAG1_MAX = 0.5
#: ζ above this is implausible for a whisker.
ZETA_PLAUSIBLE = 0.2
#: f_1 outside this range of the record's nominal (ratio) means a wrong record.
F1_RATIO = (0.4, 2.5)
#: A decay's first mode must carry at least this share of the largest mode's RMS.
MODE1_SHARE = 0.2
#: A residual line counts only where it holds at least this share of the data's power in its
#: bin (-40 dB).
SIGNAL_SHARE = 1e-4
#: Relative 1σ of f_1 and of ζ above which a fit is imprecise.
F1_REL_STD, ZETA_REL_STD = 0.005, 0.10


def lag1(r: np.ndarray) -> float:
    """Lag-1 autocorrelation of ``r`` about its mean."""
    rc = r - r.mean()
    return float(np.sum(rc[1:] * rc[:-1]) / max(np.sum(rc**2), 1e-300))


def peak_reference(t: np.ndarray, y: np.ndarray | None = None) -> tuple:
    """What :func:`residual_peak` reads of the recording alone, not of the residuals: the
    median step, the uniform grid, the window, and with the data ``y`` the rounding floor
    of its converter and the data's own periodogram (a calibration computes these while
    its compiled program runs)."""
    n = np.size(t)
    dt = float(median(np.diff(t)))
    grid = t[0] + dt * np.arange(n)
    window = spectral_window(n, True)[0]  # kept per length, read-only (as the start's spectra)
    if y is None:
        return dt, grid, window, None, None
    y = np.asarray(y, dtype=float)
    step = 2.0 * quantum(y)
    # the median of an exponential bin of mean q²/12 Σw² is ln 2 times that
    rounding = np.log(2.0) * step**2 / 12.0 * float(np.sum(window**2))
    return dt, grid, window, rounding, _periodogram(np.interp(grid, t, y), window)


def residual_peak(
    t: np.ndarray, r: np.ndarray, y: np.ndarray | None = None, *, data: tuple | None = None
) -> tuple[float, float] | None:
    """The strongest line left in the residuals as ``(frequency Hz, power / noise floor)``,
    or None when no bin stands out of white noise.

    For white noise the periodogram's bins are exponentially distributed; the largest of
    ``N`` exceeds ``median · (ln N + 8)/ln 2`` with probability about ``e⁻⁸``. The noise
    floor is never taken below the rounding of the converter that produced ``y`` (its step
    ``q``: white noise of variance ``q²/12``): a decay that has rung down below one step
    sits on one code, its residuals are nearly constant and the median would put the floor
    far under the rounding that the data cannot resolve (a clean simulated pluck then showed
    a "line" of a five-hundredth of a code at the record's lowest frequency).

    ``data``: :func:`peak_reference` of ``(t, y)``, when already computed.
    """
    n = r.size
    if n < 64:
        return None
    dt, grid, window, rounding, p_data = peak_reference(t, y) if data is None else data
    p = _periodogram(np.interp(grid, t, r), window)
    floor = float(median(p))
    if rounding is not None:
        floor = max(floor, rounding)
    if floor <= 0:
        return None
    ratio = p / floor  # bin k + 1 is k + 1 cycles in the record
    if p_data is not None:
        # A line is left by the model only where the residual holds a share of the data's
        # own power at that frequency: an unmodelled mode, a drive or hum is (nearly) all
        # of the data there. A misfit 40 dB under the data at every frequency (a noiseless
        # simulation fitted with fewer modes than made it, whose noise floor is zero) is
        # not a line the data show.
        ratio = np.where(p >= SIGNAL_SHARE * p_data, ratio, 0.0)
    i = int(np.argmax(ratio))
    if ratio[i] < (np.log(p.size) + 8.0) / np.log(2.0):
        return None
    return (i + 1) / (n * dt), float(ratio[i])


def _periodogram(x: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Hann periodogram without the zero-frequency bin, of ``x`` less its straight line.
    An offset and a drift are the model's nuisances, not lines; through the window a ramp
    (or a constant stretch, a decay rung down onto its offset) fills the lowest bins and
    would read as a line at a cycle or two per record."""
    s = np.linspace(-1.0, 1.0, x.size)
    slope, intercept = line_fit(s, x)
    x = x - (slope * s + intercept)
    return np.abs(np.fft.rfft(x * window))[1:] ** 2


def lag_below(r: np.ndarray, limit: float):
    """First lag from which the residuals' autocorrelation (by FFT) stays below ``limit`` in
    magnitude at every later lag; ``n`` when it never does. ``r`` is one residual vector
    (an int is returned) or rows of them (``m × n``: an array of ``m`` lags, by one FFT call)."""
    rows = np.atleast_2d(r)
    n = rows.shape[1]
    rc = rows - rows.mean(axis=1, keepdims=True)
    # Zero-padded to at least 2n (no wrap-around: the linear autocorrelation), to a length
    # of small prime factors: 2n itself has a large one for most n (158 988 samples:
    # 2n = 2³·3·13 249), where the transform falls back to a several times slower algorithm
    # (0.93 s of a 1.4 s calibration of 159 k samples).
    m = fast_length(2 * n)
    f = np.fft.rfft(rc, m, axis=1)
    acf = np.fft.irfft(f * np.conj(f), m, axis=1)[:, :n]
    acf = acf / np.maximum(acf[:, :1], 1e-300)
    # the lag after the last one at or above the limit (NaN counts as above), 0 if none:
    # where the running maximum of the tail drops below it
    above = ~(np.abs(acf) < limit)
    last = n - 1 - np.argmax(above[:, ::-1], axis=1)
    lags = np.where(above.any(axis=1), last + 1, 0)
    return int(lags[0]) if np.ndim(r) == 1 else lags


def hac_lag(r: np.ndarray) -> int:
    """Lag after which the residuals' autocorrelation stays below 0.1 in magnitude."""
    return int(min(max(lag_below(r, 0.1), 1), r.size // 4))


def hac_covariance(
    blocks: list[tuple[np.ndarray, np.ndarray, bool]], bread: np.ndarray
) -> tuple[np.ndarray, int]:
    """Newey–West covariance from ``(J, r, correlated)`` row blocks and ``bread = (JᵀJ)⁺``.

    Rows of different blocks are independent; within a block marked ``correlated`` the
    scores are summed with Bartlett weights up to :func:`hac_lag` of its residuals.

    Cost linear in the rows: the Bartlett-weighted sum of lagged products is a sum of outer
    products of moving sums (:func:`bartlett_meat`), ``O(n p²)`` for ``n`` rows and ``p``
    parameters whatever the lag, where summing the lags one by one costs ``O(n L p²)``.

    Returns:
        The covariance and the largest lag used.
    """
    p = bread.shape[0]
    meat = np.zeros((p, p))
    max_lag = 0
    for jac, r, correlated in blocks:
        scores = jac * r[:, None]
        if not correlated:
            meat += scores.T @ scores
            continue
        lag = hac_lag(r)
        max_lag = max(max_lag, lag)
        meat += bartlett_meat(scores, lag)
    return bread @ meat @ bread, max_lag


def bartlett_meat(scores: np.ndarray, lag: int) -> np.ndarray:
    """``Γ_0 + Σ_{l=1}^{L} (1 − l/(L+1)) (Γ_l + Γ_lᵀ)`` of the rows ``s_t`` of ``scores``,
    ``Γ_l = Σ_t s_{t+l} s_tᵀ``, in ``O(n p²)``.

    Derivation: the Bartlett weight is the overlap of two boxes of ``L + 1`` samples,
    ``(L + 1 − |t − u|)₊ = #{k : t, u ∈ [k, k + L]}`` over every window start ``k`` from
    ``−L`` to ``n − 1`` (windows hanging over either end included). So
    ``Σ_{t,u} (1 − |t−u|/(L+1))₊ s_t s_uᵀ = Σ_k B_k B_kᵀ / (L + 1)`` with ``B_k`` the sum of
    the scores in window ``k``: one moving sum (from a cumulative sum) and one Gram matrix.
    The cumulative sum is taken of the scores less their mean (added back exactly through
    the windows' sample counts), so that its rounding does not grow with ``n``.
    """
    n, p = scores.shape
    width = int(lag) + 1
    if width == 1:  # no lag (white residuals, the usual case): Γ_0 itself
        return scores.T @ scores
    mean = scores.mean(axis=0)
    c = np.zeros((n + 1, p))
    np.cumsum(scores - mean, axis=0, out=c[1:])
    # window k covers rows max(k, 0) .. min(k + width, n) - 1, for k = -(width-1) .. n-1:
    # its ends are c[1..n] then c[n] repeated, less c[0] repeated then c[0..n-1] (slices and
    # repeats, not a gather of n + L rows by index: a third of a warm fit's score tests)
    pad = width - 1
    hi = np.concatenate([c[1:], np.broadcast_to(c[n], (pad, p))]) if pad else c[1:]
    lo = np.concatenate([np.broadcast_to(c[0], (pad, p)), c[:n]]) if pad else c[:n]
    counts = np.minimum(np.arange(1, n + width), n) - np.maximum(np.arange(-pad, n), 0)
    boxes = hi - lo + counts[:, None] * mean
    return boxes.T @ boxes / width


#: A sandwich 1σ this much above the white-noise one is reported instead of it.
SANDWICH_MARGIN = 1.1


def robust_covariance(
    blocks: list[tuple[np.ndarray, np.ndarray, bool]], bread: np.ndarray, cov_white: np.ndarray
) -> tuple[np.ndarray, str]:
    """The covariance to report and a sentence saying which it is.

    ``s²(JᵀJ)⁻¹`` assumes every residual has the same variance. A recording whose noise is
    the converter's rounding breaks that: once a decay has rung down to less than a step,
    the samples sit on one code and their residuals are nearly constant, so ``s²``
    averages the rounding variance of the ringing samples (which carry the information)
    with the near-zero residuals of the rest, and the 1σ comes out several times too small.
    The sandwich ``(JᵀJ)⁻¹ (Σ s_t s_tᵀ) (JᵀJ)⁻¹`` of the scores ``s_t = J_t r_t`` (White's
    heteroskedasticity-consistent estimate, with Newey–West lags in the blocks marked
    correlated, :func:`hac_covariance`; scaled by ``n/(n − p)``) weighs each residual where
    it falls. It replaces the white-noise covariance when it has lags or raises a 1σ by more
    than ``SANDWICH_MARGIN`` (each σ never below its white-noise value); otherwise the
    white-noise covariance stands (the two agree within their own scatter).
    """
    cov, lag = hac_covariance(blocks, bread)
    n = sum(r.size for _, r, _ in blocks)
    cov = no_smaller_than(cov * n / max(n - bread.shape[0], 1), cov_white)
    if lag > 0:
        return cov, (
            f"HAC (Newey-West, Bartlett weights to lag {lag}; never below the white-noise "
            "1-sigma): the residuals are correlated"
        )
    if np.any(np.diag(cov) > SANDWICH_MARGIN**2 * np.diag(cov_white)):
        return cov, (
            "sandwich (heteroskedasticity-consistent, White; never below the white-noise "
            "1-sigma): the residuals' spread changes along the recording"
        )
    return cov_white, "white noise: s^2 (J^T J)^-1"


def no_smaller_than(cov: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """``cov`` with each standard deviation raised to at least ``floor``'s, its correlations
    kept. A truncated HAC sum can fall below the white-noise variance when the residuals'
    correlation oscillates; correlated residuals never make a fit more certain than white
    noise of the same size would."""
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    sd_floor = np.sqrt(np.maximum(np.diag(floor), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.nan_to_num(cov / np.outer(sd, sd))
    np.fill_diagonal(corr, 1.0)
    s = np.maximum(sd, sd_floor)
    return corr * np.outer(s, s)


def check_fit(
    params: dict,
    per_rec: list[dict],
    f1_nominal_hz: float,
    *,
    decay_rates_hz=(),
    f1_expected_hz: float | None = None,
) -> dict[str, str]:
    """The failed checks of a converged fit, name → sentence (see the module docstring).

    For ``aliased``: ``decay_rates_hz`` are the sampling rates of the free-decay recordings,
    ``f1_expected_hz`` the f_1 the user expects (a given start; the record's by default).
    """
    out: dict[str, str] = {}
    worst = max(per_rec, key=lambda r: r["lag1_autocorr"])
    if worst["lag1_autocorr"] > LAG1_MAX:
        out["correlated-residuals"] = (
            f"the residuals of {worst['name']} are correlated (lag-1 autocorrelation "
            f"{worst['lag1_autocorr']:.2f}): the model misses part of the signal; the "
            "uncertainties allow for it (HAC), the values may be biased"
        )
    peaks = [(r["name"], r["residual_peak"]) for r in per_rec if r.get("residual_peak")]
    if peaks:
        name, (f, ratio) = max(peaks, key=lambda x: x[1][1])
        out["residual-peak"] = (
            f"a line at {f:.4g} Hz is left in the residuals of {name} ({10 * np.log10(ratio):.0f} "
            "dB above their noise floor): an unmodelled mode, drive or ringing (check the "
            "excitation, --modes and where the decay starts)"
        )
    weak = [r for r in per_rec if r["excitation"] == "decay" and len(r.get("modal_rms", [])) > 1
            and r["modal_rms"][0] < MODE1_SHARE * max(r["modal_rms"])]  # fmt: skip
    if weak:
        r = weak[0]
        k = int(np.argmax(r["modal_rms"]))
        out["mode-1-weak"] = (
            f"the fit explains {r['name']} with mode {k + 1} and leaves mode 1 almost silent: "
            "a free decay rings mostly in mode 1, so the data's main line is probably mode 1 "
            "and the fit took it for an aliased higher mode; give --f1-start near that line's "
            "frequency (unaliased) or check the record"
        )
    zeta = params["zeta"]
    if not 1e-5 < zeta["value"] < 0.98 * ZETA_MAX:
        out["at-bound"] = f"zeta = {zeta['value']:.3g} is at a bound of its range"
    elif zeta["value"] > ZETA_PLAUSIBLE:
        out["zeta-large"] = (
            f"zeta = {zeta['value']:.3g} is implausibly large for a whisker (above "
            f"{ZETA_PLAUSIBLE}): check where the decay starts and the excitation"
        )
    f1 = params["f1_hz"]
    ratio = f1["value"] / f1_nominal_hz
    if not F1_RATIO[0] <= ratio <= F1_RATIO[1]:
        out["far-from-nominal"] = (
            f"f1 = {f1['value']:.4g} Hz is {ratio:.2g} times the record's {f1_nominal_hz:.4g} "
            "Hz: is the record this whisker's?"
        )
    expected = f1_nominal_hz if f1_expected_hz is None else f1_expected_hz
    alias = aliased(f1["value"], expected, decay_rates_hz)
    if alias is not None:
        out["aliased"] = (
            f"f1 = {f1['value']:.4g} Hz and {alias:.4g} Hz are aliases of each other at "
            f"{max(decay_rates_hz):.4g} Hz: the samples of a free decay cannot tell them apart, "
            f"and the fitted one lies above the Nyquist frequency or further from {expected:.4g} "
            "Hz (the record's f1, or the start given); record faster "
            "(the ADS1115 converts at up to 860 SPS) or give --f1-start at the true f1"
        )
    rel_f1 = f1["std"] / abs(f1["value"])
    rel_z = zeta["std"] / max(abs(zeta["value"]), 1e-300)
    if not (rel_f1 <= F1_REL_STD and rel_z <= ZETA_REL_STD):
        out["imprecise"] = (
            f"the data determine f1 to {100 * rel_f1:.2g} % and zeta to {100 * rel_z:.2g} % "
            "(1 sigma): record a longer or cleaner decay"
        )
    return out


def aliased(f1_hz: float, f1_expected_hz: float, rates_hz) -> float | None:
    """The alias ``rate − f_1`` that free decays sampled at ``rates_hz`` cannot tell from
    ``f1_hz``, when the fit's choice between them rests on nothing the data say: ``f1_hz``
    above the Nyquist frequency of the fastest recording (the samples place a line below
    it), or the alias nearer (in ratio) to the f_1 expected, ``f1_expected_hz``. None
    otherwise, and for no recordings.
    """
    if len(rates_hz) == 0:
        return None
    rate = float(max(rates_hz))
    alias = abs(rate - f1_hz)
    if alias <= 0:
        return None
    above = f1_hz > rate / 2
    nearer = abs(np.log(alias / f1_expected_hz)) < abs(np.log(f1_hz / f1_expected_hz))
    return alias if (above or nearer) else None


def decay_sampling_rates_hz(observations) -> list[float]:
    """Sampling rates (Hz, :func:`whiskerid.io.timestamp_rate`) of the free-decay
    observations."""
    return [timestamp_rate(o.t, where=o.name) for o in observations if o.excitation == "decay"]


def moments(obs) -> list[tuple[float, float]]:
    """Each recording's mean and standard deviation (what a calibration's per-recording
    report reads of the data alone; computed while its compiled program runs)."""
    return [(float(np.mean(o.y)), float(np.std(o.y))) for o in obs]


def data_side(obs) -> tuple[list, list[float]]:
    """What the checks read of the recordings alone (:func:`peak_reference` of each, the free
    decays' sampling rates, :func:`decay_sampling_rates_hz`): a calibration computes it while its
    compiled program runs."""
    return [peak_reference(o.t, o.y) for o in obs], decay_sampling_rates_hz(obs)
