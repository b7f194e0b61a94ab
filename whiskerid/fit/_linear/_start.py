"""Start values from the data: spectral peaks, aliases unfolded, envelope decay, release time,
and the grid over ``(κ, ζ)`` with the linear coefficients solved exactly (variable projection).

The grid is built from the data in NumPy (:func:`start_grid`: a fixed number of points, so
that one compiled program serves every recording) and searched inside the calibration's
compiled program (:func:`start_from_grid`, traceable); :func:`start_values` runs both.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...model import Whisker
from .._data import Observation, amplitude_spectrum, find_peaks, line_fit, median, resample_uniform
from .._numerics import lsq, sincos
from ._decay import decay_rates, free_decay_columns
from ._problem import ZETA_MAX, FitProblem, forced_columns


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
    return spectral_peaks_uniform(yu, rate, window, n), rate


def spectral_peaks_uniform(y: np.ndarray, rate_hz: float, window: str = "hann", n: int = 3):
    """:func:`spectral_peaks` of uniformly sampled ``y`` (frequencies only)."""
    freqs, amps = amplitude_spectrum(y, rate_hz, window=window)
    df = freqs[1] - freqs[0] if freqs.size > 1 else 1.0
    peaks = find_peaks(freqs, amps, n=n, min_separation_hz=3 * df)
    return [p.frequency_hz for p in peaks if p.frequency_hz > 0]


def envelope_zeta(t: np.ndarray, y: np.ndarray, f_obs_hz: float, f_true_hz: float) -> float | None:
    """ζ from the logarithmic decay of the signal's RMS envelope (None if not measurable).

    RMS over consecutive windows of about four periods of the observed (possibly aliased)
    frequency; windows near the noise floor are dropped; ``ζ = −slope/(2π f)``.
    """
    return _Envelope(t, y - median(y)).zeta(f_obs_hz, f_true_hz)


class _Envelope:
    """:func:`envelope_zeta` of one recording ``(t, y)`` (``y`` less its median), with what
    does not depend on the frequency (the cumulative squares, the median step) computed
    once for all of its spectral peaks."""

    def __init__(self, t: np.ndarray, y: np.ndarray, dt: float | None = None):
        self.t = t
        self.span = t[-1] - t[0]
        self.dt = float(median(np.diff(t))) if dt is None else dt  # the median step
        self.sums = np.concatenate([[0.0], np.cumsum(y**2)])

    def zeta(self, f_obs_hz: float, f_true_hz: float) -> float | None:
        t, span = self.t, self.span
        win = max(4.0 / max(f_obs_hz, 1e-9), 12 * self.dt)
        n_win = int(span // win)
        if n_win < 3:
            return None
        edges = t[0] + win * np.arange(n_win + 1)
        idx = np.searchsorted(t, edges)
        # each window's mean square from cumulative sums (a loop over windows took ms;
        # empty windows NaN; a start search asks this of every spectral peak, so no
        # np.errstate, np.nanmin or np.clip of a scalar: each cost more than the sums)
        count = np.diff(idx)
        ms = np.maximum(np.diff(self.sums[idx]), 0.0)
        if count.all():  # the usual case (windows of 12 samples or more): no empty window
            rms = ms / count
        else:
            rms = np.full(count.size, np.nan)
            np.divide(ms, count, out=rms, where=count > 0)
        rms = np.sqrt(rms)
        mid = 0.5 * (edges[:-1] + edges[1:])
        floor = np.fmin.reduce(rms)  # the least of the windows that hold samples
        keep = np.isfinite(rms) & (rms > 4 * floor)
        # Use only the first run of windows above the floor (the decay, not later noise
        # bumps): from the first kept window to the first one left out after it (argmin of
        # the booleans; 0 where all are kept), as slices.
        start = int(keep.argmax())
        length = int(keep[start:].argmin()) or keep.size - start
        if not keep[start] or length < 2:
            return None
        run = slice(start, start + length)
        slope = line_fit(mid[run], np.log(rms[run]))[0]
        zeta = -slope / (2 * np.pi * f_true_hz)
        return float(min(max(zeta, 1e-4), 0.5)) if math.isfinite(zeta) else None


# --------------------------------------------------------------------------- start grid
_MAX_PROFILE_SAMPLES = 6000
#: Candidate f_1 of the start search (beyond are dropped, padding is never chosen): 17
#: geometric steps plus each decay recording's spectral peaks and their aliases.
F_POINTS = 48
#: Candidate ζ in the second stage of the search: the record's ×¼…×4 and the envelopes'.
Z_POINTS = 12
#: The same when every recording is a free decay (the spectrum's candidates only).
F_DECAY = 8
#: Second-stage ζ of a free-decay grid: the record's, and the envelopes' ×½, ×1, ×2.
Z_DECAY = 4
#: f_1 candidates of a free-decay grid whose ζ is searched in the second stage.
REFINED_DECAY = 2
#: The same sizes when no recording is a free decay (a sine, base motion): no spectral
#: peak nor envelope adds a candidate, so the grid holds the 17 geometric steps and the
#: record's five ζ (sized :data:`F_POINTS` and :data:`Z_POINTS`, 62 of the first stage's 96
#: profiles and 28 of the second's 48 were padding, computed and never chosen). Both stages
#: stay whole batches of :data:`_GRID_BATCH` (2·24 and 4·8): a remainder, or a batch of
#: another size, is compiled as a program of its own, which cost more than it saved.
F_FORCED = 24
Z_FORCED = 8
#: f_1 candidates (the best of the first stage) whose ζ is searched in the second.
_REFINED = 4
#: Grid points profiled at once (vectorised) inside the sequential map over the grid.
_GRID_BATCH = 16
#: Relative cost within which grid points count as equally good (aliases of each other).
_NEAR = 1.02
#: Relative cost within which the mirror below the Nyquist frequency of a line above it is
#: preferred (see :func:`start_from_grid`).
_MIRROR = 1.5


def _kappa_from_f1(nominal: Whisker, f1_hz):
    beta1, length = float(np.asarray(nominal.beta)[0]), float(nominal.length_m)
    return (2 * np.pi * np.asarray(f1_hz) * length**2 / beta1**2) ** 2


def profile_steps(problem: FitProblem) -> tuple[int, ...]:
    """Every how many samples each recording is profiled on the grid (at most ~6000 samples
    a recording: the model is evaluated at the same instants, so decimation aliases model and
    data alike)."""
    return tuple(max(1, math.ceil(r.t.shape[0] / _MAX_PROFILE_SAMPLES)) for r in problem.recordings)


def start_grid(
    problem: FitProblem,
    observations: list[Observation],
    nominal: Whisker,
    *,
    f1_hz: float | None = None,
) -> dict[str, np.ndarray]:
    """The start grid over ``(κ, ζ)``, seeded by the data, as arrays of fixed sizes.

    f_1 is searched within a factor 2.5 of the nominal (``f1_hz``, else the record's) among
    the spectral peaks of every free decay, each as the line itself and with its aliases
    unfolded (:func:`unalias`), and, where no recording is a free decay (a sine, base
    motion), 17 geometric steps 12 % apart; ζ among the record's (×¼…×4) and the envelopes'
    decay rates (see :func:`start_from_grid` for the two stages). When every recording is a
    free decay the spectrum says where f_1 is, and the grid is small (:data:`F_DECAY`
    candidates, each with the ζ that the envelopes' decay rate σ = ζω gives at its
    frequency, then the best
    :data:`REFINED_DECAY` with :data:`Z_DECAY` ζ): 16 profiles instead of 144, which were
    most of a warm calibration's time. Its free slots (fewer peaks than slots) hold steps
    of 25 % about the nominal f_1. When no recording is a free decay, the grid is sized to
    the 17 steps and five ζ (:data:`F_FORCED`, :data:`Z_FORCED`): 80 profiles instead of
    144, the same points and the same choice (the rest is padding either way).

    Returns:
        ``f_hz`` and ``log_kappa`` of each f_1 candidate and ``f_valid`` (0 for padding);
        ``zeta1``, the first stage's ζ of each candidate (``(n_f, k)``);
        ``zeta`` and ``z_valid``, the second stage's;
        ``f_ref_hz`` (the centre of the search), ``nyquist_hz`` (of the fastest free-decay
        recording; infinite without one), ``prefer_baseband`` (1 unless ``f1_hz`` was given:
        see :func:`start_from_grid`), ``log_ei`` and ``static_d0`` (a static test's start).
    """
    # (NumPy from here: indexing a JAX array would compile a program in a fresh process)
    f1_nom = f1_hz or float(np.asarray(nominal.natural_frequencies_hz)[0])
    zeta_nom = float(np.mean(np.asarray(nominal.zeta)))
    # At low sample rates a higher mode can alias onto the first (e.g. f_2 = 645 Hz folds to
    # 45 Hz at 200 Hz): each candidate is judged by the cost of the whole multi-mode model.
    lo, hi = f1_nom / 2.5, f1_nom * 2.5
    spectral, rates, nyquist = _spectral_candidates(observations, f1_nom, lo, hi)
    envelopes = [r / (2 * np.pi * f) for f, r, true in spectral if true and r is not None]
    zeta_env = float(median(envelopes)) if envelopes else 2 * zeta_nom
    if all(r.excitation == "decay" for r in problem.recordings):
        f_cands = _unique([f for f, _, _ in spectral])[:F_DECAY]
        steps = [f1_nom * 1.25**k for k in (0, -1, 1, -2, 2, -3, 3, -4)]
        f_cands += steps[: F_DECAY - len(f_cands)]
        # each candidate's own ζ: the envelope's decay rate σ = ζ ω at that frequency
        rate = float(median(rates)) if rates else None
        zeta1 = [[rate / (2 * np.pi * f) if rate else zeta_nom] for f in f_cands]
        z_cands = [zeta_nom, zeta_env, zeta_env / 2, zeta_env * 2]
        nf, nz = F_DECAY, Z_DECAY
    else:
        f_cands = list(f1_nom * np.geomspace(1 / 2.5, 2.5, 17))
        f_cands += [f for f, _, _ in spectral]
        zeta1 = [[zeta_nom, zeta_env]] * min(len(f_cands), F_POINTS)
        # The record's five ζ, then the envelopes' in order.
        z_cands = [zeta_nom * k for k in (0.25, 0.5, 1.0, 2.0, 4.0)] + envelopes
        nf, nz = (F_POINTS, Z_POINTS) if spectral or envelopes else (F_FORCED, Z_FORCED)
    z_cands = np.clip(np.unique(np.round(z_cands[:nz], 6)), 1e-4, 0.5)
    f_cands = np.asarray(f_cands)[:nf]
    pad_f, pad_z = nf - f_cands.size, nz - z_cands.size
    log_ei, d0 = math.log(float(nominal.EI)), 0.0
    if problem.fit_ei:
        fit = np.asarray(problem.static_test.line_fit)
        x, l = float(problem.static_test.x_m), float(problem.length_m)
        ei = (x**2 * (3 * l - x) / 6) / fit[1] if fit[1] > 0 else float(nominal.EI)
        log_ei, d0 = math.log(ei), float(fit[0])
    return {
        "log_kappa": _pad_edge(np.log(_kappa_from_f1(nominal, f_cands)), pad_f),
        "f_hz": _pad_edge(f_cands, pad_f),
        "f_valid": _valid(f_cands.size, pad_f),
        "zeta1": _pad_edge(np.clip(np.asarray(zeta1), 1e-4, 0.5), pad_f),
        "zeta": _pad_edge(z_cands, pad_z),
        "z_valid": _valid(z_cands.size, pad_z),
        "f_ref_hz": np.asarray(f1_nom),
        "nyquist_hz": np.asarray(nyquist),
        "prefer_baseband": np.asarray(0.0 if f1_hz else 1.0),
        "log_ei": np.asarray(log_ei),
        "static_d0": np.asarray(d0),
    }


def _pad_edge(x: np.ndarray, pad: int) -> np.ndarray:
    """``x`` with its last row repeated ``pad`` times (``np.pad``'s edge mode along the first
    axis, without its tenths of a millisecond of set-up per call)."""
    return np.concatenate([x, np.repeat(x[-1:], pad, axis=0)]) if pad else x


def _valid(n: int, pad: int) -> np.ndarray:
    """``n`` ones then ``pad`` zeros."""
    return np.concatenate([np.ones(n), np.zeros(pad)])


def _spectral_candidates(observations, f1_nom, lo, hi):
    """f_1 candidates from the free decays' spectral peaks, within ``[lo, hi]``.

    Returns:
        ``(f_hz, decay rate σ (1/s) or None, whether f is the unfolded alias)`` of each
        candidate, in the order found (the largest peaks first); each recording's decay rate;
        and the Nyquist frequency of the fastest free decay (infinite without one).
    """
    out, rates, nyquist = [], [], np.inf
    for o in observations:
        if o.excitation != "decay":
            continue
        # Both windows: a pluck that dies out within the first few percent of the record is
        # below the noise in the Hann-windowed spectrum (the start then rested on the grid
        # alone and picked an aliased higher mode in 5 of 200 seeded trials).
        yc = o.y - median(o.y)
        dt = float(median(np.diff(o.t)))  # once for the grid and the envelope
        _, yu, rate = resample_uniform(o.t, yc, 1.0 / dt)
        peaks = spectral_peaks_uniform(yu, rate) + spectral_peaks_uniform(yu, rate, "none")
        nyquist = rate / 2 if not np.isfinite(nyquist) else max(nyquist, rate / 2)
        first = True  # the recording's decay rate: its largest peak's (the envelope is the
        # whole signal's RMS, over windows of four periods: a weak low line's are too long)
        envelope = _Envelope(o.t, yc, dt)
        for fp in _unique(peaks):
            # the alias nearest the nominal, and the line itself (below the Nyquist frequency)
            f_true = unalias(fp, rate, f1_nom)
            sigma = None
            if lo <= f_true <= hi:
                z = envelope.zeta(fp, f_true)
                sigma = None if z is None else z * 2 * np.pi * f_true
                if sigma is not None and first:
                    rates.append(sigma)
                    first = False
            # The line first, then its alias: where the grid has no slot left for both
            # (F_DECAY), the line below the Nyquist frequency stays, so that an alias in the
            # grid always has its mirror there (start_from_grid prefers the mirror).
            out.extend(
                (f, sigma, f == f_true) for f in dict.fromkeys((fp, f_true)) if lo <= f <= hi
            )
    return out, rates, nyquist


def _unique(freqs, rel: float = 1e-3) -> list[float]:
    """``freqs`` in order, without those within ``rel`` of an earlier one."""
    out: list[float] = []
    for f in freqs:
        if all(abs(f - g) > rel * g for g in out):
            out.append(float(f))
    return out


def start_from_grid(
    problem: FitProblem, grid: dict, masks=None, *, coefficients: bool = True
) -> dict:
    """The start parameters from :func:`start_grid` (traceable): the grid point of least
    profile cost, with the linear coefficients solved exactly there.

    Two stages: every f_1 candidate with its first-stage ζ (the record's and the envelopes';
    a free-decay grid's own envelope ζ), then the best f_1 (four; a free-decay grid's two)
    with every ζ candidate (the profile cost of a decay depends on ζ far less than on f_1,
    so the full product is not needed). Among points within 2 % of the least cost (a line
    and its alias fit alike), the one nearest the centre of the search, preferring those
    below the Nyquist frequency of the free decays unless f_1 was given
    (``prefer_baseband``): a sampling rate is chosen to resolve f_1, and a record's f_1 may
    well be 30 % off, which puts a line near the Nyquist frequency closer to its alias. For
    the same reason a line above the Nyquist frequency gives way to its mirror below it
    when the mirror's profile cost is within 50 % (the grid's f_1 are a few tenths of a hertz
    off the line, which moves the two costs apart by up to about 25 %).

    Args:
        problem: The fit problem.
        grid: From :func:`start_grid`.
        masks: Per recording, 1 for a sample and 0 for padding (None: no padding).
        coefficients: Solve the linear coefficients at the point chosen (else they are left
            at zero, except where a known sine's start time τ is read from them): a solver
            by variable projection solves them at every point and does not read them.
    """
    steps = profile_steps(problem)
    if masks is None:
        masks = [jnp.ones(r.t.shape[0]) for r in problem.recordings]

    def costs(log_kappa, zeta, valid):
        zu = lsq.from_interval(zeta, 0.0, ZETA_MAX)
        c = jax.lax.map(
            lambda p: _profile_cost(problem, steps, masks, p[0], p[1], grid["log_ei"]),
            (log_kappa, zu),
            batch_size=_GRID_BATCH,
        )
        return jnp.where((valid > 0) & jnp.isfinite(c), c, jnp.inf), zu

    nf, nz = grid["f_hz"].shape[0], grid["zeta"].shape[0]
    k1 = grid["zeta1"].shape[1]
    refined = REFINED_DECAY if nf <= F_DECAY else _REFINED
    # stage 1: every f_1 with its first ζ
    lk1 = jnp.repeat(grid["log_kappa"], k1)
    f1 = jnp.repeat(grid["f_hz"], k1)
    c1, zu1 = costs(lk1, grid["zeta1"].reshape(-1), jnp.repeat(grid["f_valid"], k1))
    # stage 2: the best f_1 with every ζ
    top = jnp.argsort(jnp.min(c1.reshape(nf, k1), axis=1))[:refined]
    lk2 = jnp.repeat(grid["log_kappa"][top], nz)
    f2 = jnp.repeat(grid["f_hz"][top], nz)
    valid2 = jnp.repeat(grid["f_valid"][top], nz) * jnp.tile(grid["z_valid"], refined)
    c2, zu2 = costs(lk2, jnp.tile(grid["zeta"], refined), valid2)
    cost, f_hz = jnp.concatenate([c1, c2]), jnp.concatenate([f1, f2])
    log_kappa, zeta_u = jnp.concatenate([lk1, lk2]), jnp.concatenate([zu1, zu2])
    near = cost <= jnp.min(cost) * _NEAR + 1e-300
    below = f_hz <= grid["nyquist_hz"]
    shun = (grid["prefer_baseband"] > 0) & jnp.any(near & below) & ~below
    score = jnp.abs(jnp.log(f_hz / grid["f_ref_hz"])) + jnp.where(shun, 1e3, 0.0)
    best = jnp.argmin(jnp.where(near, score, jnp.inf))
    # A line above the Nyquist frequency and its mirror below it differ in the samples only
    # through the weaker higher modes, which on a grid (f_1 a few tenths of a hertz off) can
    # favour either by tens of percent: the mirror is taken if it is within _MIRROR.
    mirror = 2 * grid["nyquist_hz"] - f_hz[best]
    is_mirror = (jnp.abs(f_hz - mirror) <= 5e-3 * mirror) & (f_hz <= grid["nyquist_hz"])
    is_mirror = is_mirror & (cost <= cost[best] * _MIRROR)
    use = (grid["prefer_baseband"] > 0) & (f_hz[best] > grid["nyquist_hz"]) & jnp.any(is_mirror)
    best = jnp.where(use, jnp.argmin(jnp.where(is_mirror, cost, jnp.inf)), best)
    theta = jax.tree_util.tree_map(jnp.asarray, problem.zero_params())
    theta["log_kappa"] = log_kappa[best]
    theta["zeta_u"] = jnp.full(jnp.shape(theta["zeta_u"]), zeta_u[best])
    if problem.fit_ei:
        theta["log_EI"] = grid["log_ei"]
        theta["static_d0"] = grid["static_d0"]
    need = [coefficients or (r.forced == "known" and r.excitation == "sine")
            for r in problem.recordings]  # fmt: skip
    if not any(need):
        return theta
    designs = [D for D, _ in problem.design(theta, profile=True)]
    for r, rp, D, m, solve in zip(problem.recordings, theta["recs"], designs, masks, need,
                                  strict=True):  # fmt: skip
        if not solve:
            continue
        coef = jnp.linalg.lstsq(D * m[:, None], r.y * m)[0]
        if r.forced == "known" and r.excitation == "sine":
            # Coefficients of the unit-RMS columns W(t), W(t − T/4): c1 W(t) + c2 W(t − T/4)
            # = R W(t − ψ/ω_b) with ψ = atan2(c2, c1).
            rp["tau"] = jnp.arctan2(coef[-1], coef[-2]) / (2 * jnp.pi * r.fb_hz)
            coef = coef[:-2]
        elif r.forced == "known":  # base motion: its free column only served the start
            coef = coef[:-1]
        rp["c"] = coef
    return theta


def start_values(
    problem: FitProblem,
    observations: list[Observation],
    nominal: Whisker,
    *,
    f1_hz: float | None = None,
) -> dict:
    """Start parameters: the best ``(κ, ζ)`` on a grid seeded by the data, with the linear
    coefficients solved exactly there (:func:`start_grid`, then :func:`start_from_grid`).

    Args:
        problem: The fit problem.
        observations: Its recordings (for their spectra and envelopes).
        nominal: The record's whisker with the problem's number of modes.
        f1_hz: Centre of the search (the nominal f_1 by default).
    """
    grid = start_grid(problem, observations, nominal, f1_hz=f1_hz)
    return _start_jit(problem, jax.tree_util.tree_map(jnp.asarray, grid))


@eqx.filter_jit
def _start_jit(problem, grid):
    return start_from_grid(problem, grid)


def _profile_cost(problem, steps, masks, log_kappa, zeta_u, log_ei):
    theta = {"log_kappa": log_kappa, "zeta_u": zeta_u, "log_EI": log_ei}
    w = problem.whisker(theta)
    total = 0.0
    for r, step, m in zip(problem.recordings, steps, masks, strict=True):
        if r.excitation != "base":  # base motion needs every step of its input
            r = eqx.tree_at(lambda q: (q.t, q.y), r, (r.t[::step], r.y[::step]))
            m = m[::step]
        D = profile_rows(r, w) * m  # padding (zero weight) out of the normal equations
        # Normal equations on unit-norm columns (a tiny ridge for a vanished column):
        # jnp.linalg.lstsq here (an SVD) made XLA re-evaluate the design several times.
        norm = jnp.sqrt(jnp.sum(D**2, axis=1)) + 1e-300
        Dn = D / norm[:, None]
        gram = Dn @ Dn.T + 1e-12 * jnp.eye(D.shape[0])
        k = D.shape[0]
        L = lsq.cholesky_small([[gram[i, j] for j in range(i + 1)] for i in range(k)])
        coef = jnp.stack(lsq.cho_solve_small(L, list(Dn @ (r.y * m))))
        res = (coef @ Dn - r.y) * m
        total = total + jnp.sum(res**2) / jnp.sum(m)
    return total


def profile_rows(rec, w: Whisker):
    """The design of :func:`whiskerid.fit._linear._problem.recording_design` with ``profile=True``
    (a known forced response as free columns too), transposed: ``(columns, samples)``.

    The same numbers, laid out so that the profile's sums over the samples (the columns'
    norms, the normal equations, the residual) run along contiguous memory. With the samples
    as the leading axis XLA's CPU code summed them with a stride: the start search's 16
    profiles of a 2048-sample pluck took 2.3 ms of a warm calibration's program, about
    half as long this way (the profile costs agree to rounding, and the point chosen is
    the same).
    """
    t = rec.t
    span = jnp.maximum(t[-1] - t[0], 1e-12)
    rows = [jnp.ones_like(t)[None, :], ((t - 0.5 * (t[0] + t[-1])) / span)[None, :]]
    sigma, wd = decay_rates(w.omega_rad_s, w.zeta)
    c, s = free_decay_columns(t[None, :], sigma[:, None], wd[:, None], rec.avg_offsets,
                              sincos=sincos)  # fmt: skip
    rows += [c, s, *(col[None, :] for col in forced_columns(rec, w, t))]
    return jnp.concatenate(rows, axis=0)
