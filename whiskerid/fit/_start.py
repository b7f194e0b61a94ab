"""Start values from the data: spectral peaks, aliases unfolded, envelope decay, release time,
and the grid over ``(κ, ζ)`` with the linear coefficients solved exactly (variable projection)."""

import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..model import Whisker
from . import _lsq as _lsq
from ._observation import Observation
from ._problem import ZETA_MAX, FitProblem, recording_design
from ._signal import amplitude_spectrum, find_peaks, resample_uniform


def unalias(f_obs_hz: float, rate_hz: float, f_nominal_hz: float, *, folds: int = 6) -> float:
    """The frequency, among ``|k·rate ± f_obs|``, closest (in ratio) to a nominal one."""
    cands = [abs(k * rate_hz + s * f_obs_hz) for k in range(folds + 1) for s in (-1, 1)]
    cands = [c for c in cands if c > 0]
    return min(cands, key=lambda c: abs(math.log(c / f_nominal_hz)))


def spectral_peaks(
    t: np.ndarray, y: np.ndarray, *, n: int = 3, window: str = "hann"
) -> tuple[list[float], float]:
    """Largest spectral peaks (Hz, sub-bin interpolated) and the median sample rate.

    ``window="hann"`` suits steady oscillations; ``"none"`` suits a decay that is over early
    in the record, which a Hann window (near zero at the ends) all but erases.
    """
    _, yu, rate = resample_uniform(t, y)
    freqs, amps = amplitude_spectrum(yu, rate, window=window)
    df = freqs[1] - freqs[0] if freqs.size > 1 else 1.0
    peaks = find_peaks(freqs, amps, n=n, min_separation_hz=3 * df)
    return [p.frequency_hz for p in peaks if p.frequency_hz > 0], rate


def envelope_zeta(t: np.ndarray, y: np.ndarray, f_obs_hz: float, f_true_hz: float) -> float | None:
    """ζ from the logarithmic decay of the signal's RMS envelope (None if not measurable).

    RMS over consecutive windows of about four periods of the observed (possibly aliased)
    frequency; windows near the noise floor are dropped; ``ζ = −slope/(2π f)``.
    """
    y = y - np.median(y)
    span = t[-1] - t[0]
    win = max(4.0 / max(f_obs_hz, 1e-9), 12 * float(np.median(np.diff(t))))
    n_win = int(span // win)
    if n_win < 3:
        return None
    edges = t[0] + win * np.arange(n_win + 1)
    idx = np.searchsorted(t, edges)
    rms = np.array(
        [np.sqrt(np.mean(y[a:b] ** 2)) if b > a else np.nan for a, b in itertools.pairwise(idx)]
    )
    mid = 0.5 * (edges[:-1] + edges[1:])
    floor = np.nanmin(rms)
    keep = np.isfinite(rms) & (rms > 4 * floor)
    # Use only the first run of windows above the floor (the decay, not later noise bumps).
    if keep.sum() < 2:
        return None
    first = np.flatnonzero(keep)
    run = first[: np.argmax(np.diff(np.concatenate([first, [first[-1] + 2]])) > 1) + 1]
    if run.size < 2:
        return None
    slope = np.polyfit(mid[run], np.log(rms[run]), 1)[0]
    zeta = -slope / (2 * np.pi * f_true_hz)
    return float(np.clip(zeta, 1e-4, 0.5)) if np.isfinite(zeta) else None


# --------------------------------------------------------------------------- start grid
_MAX_PROFILE_SAMPLES = 6000


_GRID_CHUNK = 64


def _kappa_from_f1(nominal: Whisker, f1_hz):
    beta1, length = float(nominal.beta[0]), float(nominal.length_m)
    return (2 * np.pi * np.asarray(f1_hz) * length**2 / beta1**2) ** 2


def start_values(
    problem: FitProblem,
    observations: list[Observation],
    nominal: Whisker,
    *,
    f1_hz: float | None = None,
) -> dict:
    """Start parameters: the best ``(κ, ζ)`` on a grid seeded by the data, with the linear
    coefficients solved exactly there.

    Args:
        problem: The fit problem.
        observations: Its recordings (for their spectra and envelopes).
        nominal: The record's whisker with the problem's number of modes.
        f1_hz: Centre of the search (the nominal f_1 by default).
    """
    f1_nom = f1_hz or float(nominal.natural_frequencies_hz[0])
    zeta_nom = float(np.mean(nominal.zeta))
    # f_1 is searched within a factor 2.5 of the nominal (a whisker's f_1 may be half or
    # twice its record's). At low sample rates a higher mode can alias onto the first
    # (e.g. f_2 = 645 Hz folds to 45 Hz at 200 Hz): each candidate is judged by the cost of
    # the whole multi-mode model, and near-ties are broken towards the nominal below.
    lo, hi = f1_nom / 2.5, f1_nom * 2.5
    f_cands = list(f1_nom * np.geomspace(1 / 2.5, 2.5, 33))
    z_cands = [zeta_nom * k for k in (0.25, 0.5, 1.0, 2.0, 4.0)]
    for o in observations:
        if o.excitation != "decay":
            continue
        # Both windows: a pluck that dies out within the first few percent of the record is
        # below the noise in the Hann-windowed spectrum (the start then rested on the grid
        # alone and picked an aliased higher mode in 5 of 200 seeded trials).
        yc = o.y - np.median(o.y)
        peaks, rate = spectral_peaks(o.t, yc)
        peaks = peaks + spectral_peaks(o.t, yc, window="none")[0]
        for fp in peaks:
            f_true = unalias(fp, rate, f1_nom)
            if not lo <= f_true <= hi:
                continue
            f_cands.append(f_true)
            z = envelope_zeta(o.t, o.y, fp, f_true)
            if z is not None:
                z_cands.append(z)
    z_cands = np.clip(np.unique(np.round(z_cands, 6)), 1e-4, 0.5)
    f_cands = np.asarray(f_cands)
    grid_f = np.repeat(f_cands, z_cands.size)
    grid_z = np.tile(z_cands, f_cands.size)
    # Profile on at most ~6000 samples per recording (every k-th sample: the model is
    # evaluated at the same instants, so decimation aliases model and data alike).
    steps = tuple(
        max(1, math.ceil(r.t.shape[0] / _MAX_PROFILE_SAMPLES)) for r in problem.recordings
    )
    log_kappa = np.log(_kappa_from_f1(nominal, grid_f))
    log_ei0 = math.log(float(nominal.EI))
    # The grid's length varies with the data: it is evaluated in chunks of a fixed length
    # (the last one padded), so that one compiled function serves every grid.
    n_grid = grid_f.size
    pad = -n_grid % _GRID_CHUNK
    log_kappa_p = np.pad(log_kappa, (0, pad), mode="edge")
    grid_z_p = np.pad(grid_z, (0, pad), mode="edge")
    costs, zeta_u = [], []
    for k in range(0, n_grid + pad, _GRID_CHUNK):
        chunk = slice(k, k + _GRID_CHUNK)
        c, z = _profile_grid(
            problem,
            steps,
            jnp.asarray(log_kappa_p[chunk]),
            jnp.asarray(grid_z_p[chunk]),
            jnp.asarray(log_ei0),
        )
        costs.append(np.asarray(c))
        zeta_u.append(np.asarray(z))
    costs = np.concatenate(costs)[:n_grid]
    zeta_u = np.concatenate(zeta_u)[:n_grid]
    costs = np.where(np.isfinite(costs), costs, np.inf)
    # Among (near-)equally good candidates take the one closest to the nominal f_1.
    near = np.flatnonzero(costs <= costs.min() * 1.02 + 1e-300)
    best = int(near[np.argmin(np.abs(np.log(grid_f[near] / f1_nom)))])
    theta = problem.zero_params()
    theta["log_kappa"] = np.asarray(log_kappa[best])
    theta["zeta_u"] = np.full(np.shape(theta["zeta_u"]), zeta_u[best])
    if problem.fit_ei:
        fit = np.asarray(problem.static_test.line_fit)
        x, l = float(problem.static_test.x_m), float(problem.length_m)
        ei = (x**2 * (3 * l - x) / 6) / fit[1] if fit[1] > 0 else float(nominal.EI)
        theta["log_EI"] = np.asarray(math.log(ei))
        theta["static_d0"] = np.asarray(float(fit[0]))
    designs = _profile_design(problem, theta)
    for r, rp, D in zip(problem.recordings, theta["recs"], designs, strict=True):
        coef = np.linalg.lstsq(np.asarray(D), np.asarray(r.y), rcond=None)[0]
        if r.forced == "known" and r.excitation == "sine":
            # Coefficients of the unit-RMS columns W(t), W(t − T/4): c1 W(t) + c2 W(t − T/4)
            # = R W(t − ψ/ω_b) with ψ = atan2(c2, c1).
            c1, c2 = coef[-2:]
            rp["tau"] = np.asarray(math.atan2(c2, c1) / (2 * np.pi * float(r.fb_hz)))
            coef = coef[:-2]
        elif r.forced == "known":  # base motion: its free column only served the start
            coef = coef[:-1]
        rp["c"] = np.asarray(coef)
    return jax.tree_util.tree_map(jnp.asarray, theta)


@eqx.filter_jit
def _profile_design(problem, theta):
    return [D for D, _ in problem.design(theta, profile=True)]


@eqx.filter_jit
def _profile_grid(problem, steps, log_kappa, zeta, log_ei):
    """Profile cost at each grid point, and the grid's ζ in the fitted (logistic) space."""
    zeta_u = _lsq.from_interval(zeta, 0.0, ZETA_MAX)
    costs = jax.lax.map(
        lambda xz: _profile_cost(problem, steps, xz[0], xz[1], log_ei), (log_kappa, zeta_u)
    )
    return costs, zeta_u


def _profile_cost(problem, steps, log_kappa, zeta_u, log_ei):
    theta = {"log_kappa": log_kappa, "zeta_u": zeta_u, "log_EI": log_ei}
    w = problem.whisker(theta)
    total = 0.0
    for r, step in zip(problem.recordings, steps, strict=True):
        if r.excitation != "base":  # base motion needs every step of its input
            r = eqx.tree_at(lambda q: (q.t, q.y), r, (r.t[::step], r.y[::step]))
        D, _ = recording_design(r, w, {"tau": 0.0}, profile=True)
        # Normal equations on unit-norm columns (a tiny ridge for a vanished column):
        # jnp.linalg.lstsq here (an SVD) made XLA re-evaluate the design several times.
        norm = jnp.sqrt(jnp.sum(D**2, axis=0)) + 1e-300
        Dn = D / norm
        gram = Dn.T @ Dn + 1e-12 * jnp.eye(D.shape[1])
        k = D.shape[1]
        L = _lsq.cholesky_small([[gram[i, j] for j in range(i + 1)] for i in range(k)])
        coef = jnp.stack(_lsq.cho_solve_small(L, list(Dn.T @ r.y)))
        res = Dn @ coef - r.y
        total = total + jnp.mean(res**2)
    return total
