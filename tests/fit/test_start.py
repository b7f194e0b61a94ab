"""The calibration's start from the spectrum: candidates near the truth, a small grid for free
decays, and a chosen start near the truth at every sampling rate.

The plucks are written here in NumPy (two damped modes, f_2/f_1 the cantilever's 6.267,
white noise), not by the package's simulator; the record the start is centred on is 30 %
high in f_1, as a user's nominal record may well be.
"""

import itertools
from dataclasses import replace

import numpy as np
import pytest

from whiskerid.fit import FitProblem, Observation
from whiskerid.fit._data._signal import line_fit
from whiskerid.fit._linear._problem import recording_design
from whiskerid.fit._linear._start import (
    F_DECAY,
    F_FORCED,
    F_POINTS,
    Z_FORCED,
    Z_POINTS,
    _start_jit,
    envelope_zeta,
    profile_rows,
    start_grid,
    start_values,
)
from whiskerid.model import paper_record

RATIO = 6.267  # f_2/f_1 of a cantilever without tip mass (4.6941²/1.8751²)

# (sampling rate Hz, f_1 Hz, ζ): slow, fast and strongly damped; mode 2 aliased at 200 Hz
PLUCKS = [
    (200.0, 46.0, 0.04),
    (200.0, 71.0, 0.01),
    (475.0, 92.0, 0.12),
    (860.0, 30.0, 0.005),
    (860.0, 110.0, 0.03),
]


def _record(f1_hz):
    """The paper whisker's record with its f_1 moved to ``f1_hz`` (through its modulus)."""
    rec = paper_record()
    f0 = float(rec.whisker().natural_frequencies_hz[0])
    s = rec.structure
    return rec.replace(
        structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * (f1_hz / f0) ** 2)
    )


def _pluck(rate_hz, f1_hz, zeta, seed=0):
    """A two-mode free decay sampled at ``rate_hz`` until it is ~1 % of its start, 30 dB SNR."""
    rng = np.random.default_rng(seed)
    duration = float(np.clip(4.6 / (2 * np.pi * f1_hz * zeta), 1.0, 6.0))
    t = np.arange(int(duration * rate_hz)) / rate_hz
    y = np.zeros_like(t)
    for f, a in ((f1_hz, 1.0), (RATIO * f1_hz, 0.15)):
        w = 2 * np.pi * f
        wd = w * np.sqrt(1 - zeta**2)
        y += a * np.exp(-zeta * w * t) * np.cos(wd * t + rng.uniform(0, 2 * np.pi))
    y = 1000.0 * y + 200.0
    y += rng.normal(0.0, np.std(y) / 10 ** (30 / 20), t.size)
    return Observation(t, y, excitation="decay", observable="deflection")


def _problem(obs, nominal):
    problem = FitProblem.from_observations(nominal, [obs], n_modes=2, pin="geometry")
    return problem, nominal.whisker().with_modes(2)


@pytest.mark.parametrize(("rate", "f1", "zeta"), PLUCKS)
def test_the_spectrum_puts_a_candidate_on_f1_with_its_own_zeta(rate, f1, zeta):
    obs = _pluck(rate, f1, zeta)
    nominal = _record(1.3 * f1)
    problem, whisker = _problem(obs, nominal)
    grid = start_grid(problem, [obs], whisker)
    # a free decay's grid is the small one: the spectrum's candidates, 16 profiles
    assert grid["f_hz"].shape == (F_DECAY,) and grid["zeta1"].shape == (F_DECAY, 1)
    err = np.abs(grid["f_hz"] / f1 - 1)
    best = int(np.argmin(np.where(grid["f_valid"] > 0, err, np.inf)))
    # within a few tenths of a bin (1/duration: 1 % at 92 Hz over 1.1 s) or a tenth of the
    # resonance's half-power width (2ζ f_1: a strongly damped peak is broad and skewed)
    bin_rel = 1.0 / (obs.t[-1] * f1)
    assert err[best] < max(0.3 * bin_rel, 0.1 * zeta, 2e-3), (grid["f_hz"], f1)
    # its first ζ from the envelope's decay rate, within 35 % of the truth
    assert abs(grid["zeta1"][best, 0] / zeta - 1) < 0.35, (grid["zeta1"][best], zeta)


def test_an_alias_in_the_grid_comes_with_its_line_below_the_nyquist_frequency():
    """Strongly damped plucks near the Nyquist frequency, the record 30 % high (nearer the
    alias than the line): a broad, noisy peak gives several spectral peaks, each entered as
    the line and as its alias nearest the record, more than the grid's slots. Wherever an
    alias is in the grid, so is its mirror below the Nyquist frequency (when within the
    search range), which the search prefers among equal costs; before, the last slot could
    take an alias alone (15 of these 60 grids), and a 10 s pluck of a coil whisker at
    87 Hz was fitted on its alias at 113 Hz."""
    lone = []
    for (f1, zeta), seed in itertools.product(
        ((87.2, 0.04), (80.0, 0.04), (86.0, 0.06), (90.0, 0.03), (75.0, 0.05)), range(12)
    ):
        obs = _pluck(200.0, f1, zeta, seed=seed)
        problem, whisker = _problem(obs, _record(1.3 * f1))
        grid = start_grid(problem, [obs], whisker)
        f = grid["f_hz"][grid["f_valid"] > 0]
        nyquist, ref = float(grid["nyquist_hz"]), float(grid["f_ref_hz"])
        assert abs(nyquist - 100.0) < 1e-9 and f.size == F_DECAY  # every slot taken
        for alias in f[f > nyquist]:
            mirror = 2 * nyquist - alias
            if ref / 2.5 <= mirror <= ref * 2.5 and not np.any(np.abs(f - mirror) <= 5e-3 * mirror):
                lone.append((f1, zeta, seed, float(alias)))
    assert not lone, lone


def test_a_sine_keeps_the_geometric_grid():
    """Without a free decay the spectrum does not say where f_1 is: the 17 geometric steps,
    with the record's five ζ in the second stage, in a grid of its own size."""
    t = np.arange(600) / 200.0
    y = 100 * np.sin(2 * np.pi * 40.0 * t) + np.random.default_rng(1).normal(0, 1, t.size)
    obs = Observation(t, y, excitation="sine", fb_hz=40.0, observable="deflection")
    nominal = paper_record()
    problem, whisker = _problem(obs, nominal)
    grid = start_grid(problem, [obs], whisker)
    assert grid["f_hz"].shape == (F_FORCED,) and int(grid["f_valid"].sum()) == 17
    assert grid["zeta"].shape == (Z_FORCED,) and int(grid["z_valid"].sum()) == 5
    steps = grid["f_hz"][1:17] / grid["f_hz"][:16]
    assert np.allclose(steps, 2.5 ** (2 / 16)) and np.isclose(np.prod(steps), 6.25)


def _envelope_zeta_by_definition(t, y, f_obs_hz, f_true_hz):
    """The envelope's ζ as first written: each window's RMS (NaN where it holds no sample),
    windows above four times the quietest, their first run, ``ζ = −slope/(2π f)``."""
    y = y - np.median(y)
    dt = float(np.median(np.diff(t)))
    win = max(4.0 / max(f_obs_hz, 1e-9), 12 * dt)
    n_win = int((t[-1] - t[0]) // win)
    if n_win < 3:
        return None
    edges = t[0] + win * np.arange(n_win + 1)
    rms = []
    for lo, hi in itertools.pairwise(edges):
        inside = y[(t >= lo) & (t < hi)]
        rms.append(np.sqrt(np.mean(inside**2)) if inside.size else np.nan)
    rms, mid = np.array(rms), 0.5 * (edges[:-1] + edges[1:])
    keep = np.isfinite(rms) & (rms > 4 * np.nanmin(rms))
    run = []
    for i in np.flatnonzero(keep):
        if run and i != run[-1] + 1:
            break
        run.append(i)
    if len(run) < 2:
        return None
    zeta = -line_fit(mid[run], np.log(rms[run]))[0] / (2 * np.pi * f_true_hz)
    return float(np.clip(zeta, 1e-4, 0.5)) if np.isfinite(zeta) else None


@pytest.mark.parametrize("seed", range(4))
def test_the_envelope_zeta_is_its_definition(seed):
    """The envelope's decay rate from cumulative sums equals the window-by-window
    definition (to the sums' rounding), on decays with noise bumps after them and with a
    gap in the samples (empty windows), at the line and at an alias."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 6.0, 1500))
    if seed % 2:
        t = t[(t < 2.0) | (t > 2.6)]  # windows with no sample in them
    zeta = rng.uniform(0.005, 0.1)
    y = np.exp(-zeta * 2 * np.pi * 30.0 * t) * np.cos(2 * np.pi * 30.0 * t) + 5.0
    y += rng.normal(0, 1e-3, t.size) + 0.05 * np.exp(-((t - 5.0) ** 2) / 0.01)
    found = 0
    for f_obs, f_true in ((30.0, 30.0), (170.0, 30.0), (5.0, 5.0)):
        got = envelope_zeta(t, y, f_obs, f_true)
        want = _envelope_zeta_by_definition(t, y, f_obs, f_true)
        assert (got is None and want is None) or got == pytest.approx(want, rel=1e-9, abs=0)
        found += got is not None
    assert found >= 2  # the line and its alias are measurable


def _kinds():
    """A pluck read by the ADC (its conversion averaged), a deflection pluck, a sine with a
    free and a known amplitude, and base motion: every kind of design column."""
    t = np.arange(300) / 200.0
    rng = np.random.default_rng(2)
    y = 100 * np.exp(-t) * np.sin(2 * np.pi * 40.0 * t) + rng.normal(0, 1, t.size)
    kinds = [
        Observation(t, y + 10000.0, excitation="decay", observable="adc", gain=None),
        Observation(t, y, excitation="decay", observable="deflection"),
        Observation(t, y, excitation="sine", fb_hz=30.0, observable="deflection"),
        Observation(
            t, y, excitation="sine", fb_hz=30.0, hb_m=1e-3, observable="deflection", gain=1.0
        ),
        Observation(
            t,
            y,
            excitation="base",
            observable="deflection",
            gain=1.0,
            base_acc=np.sin(2 * np.pi * 21.0 * t),
        ),
    ]
    return kinds


@pytest.mark.parametrize("kind", range(5))
def test_the_profiles_rows_are_the_design_transposed(kind):
    """The start search's design, laid out as rows (samples along the minor axis), holds the
    numbers of the calibration's own design with its forced response free: same columns,
    same order, for every excitation and observable."""
    obs = _kinds()[kind]
    problem = FitProblem.from_observations(paper_record(), [obs], n_modes=2, pin="geometry")
    params = problem.zero_params()
    params["log_kappa"] = params["log_kappa"] + 0.3
    params["zeta_u"] = params["zeta_u"] - 1.0
    w = problem.whisker(params)
    rec = problem.recordings[0]
    D, _ = recording_design(rec, w, params["recs"][0], profile=True)
    rows = np.asarray(profile_rows(rec, w))
    # offset, drift, two modes' cos and sin; a sine's two phases, base motion's response
    assert rows.shape == (D.shape[1], D.shape[0]) == ((6, 6, 8, 8, 7)[kind], 300)
    np.testing.assert_allclose(rows, np.asarray(D).T, rtol=1e-13, atol=1e-13)


@pytest.mark.slow
@pytest.mark.parametrize(("rate", "f1", "zeta"), PLUCKS)
def test_the_chosen_start_is_near_the_truth(rate, f1, zeta):
    """The compiled search picks the line, not the record's f_1 nor an alias of mode 2."""
    obs = _pluck(rate, f1, zeta, seed=1)
    nominal = _record(1.3 * f1)
    problem, whisker = _problem(obs, nominal)
    theta = start_values(problem, [obs], whisker)
    w = problem.whisker(theta)
    assert abs(float(w.natural_frequencies_hz[0]) / f1 - 1) < 5e-3
    assert 0.5 < float(np.asarray(w.zeta)[0]) / zeta < 2.0


def _sine_from_rest(rate_hz, f1_hz, zeta, fb_hz, duration_s, seed=0):
    """Two modes driven by a sine from rest: each mode's steady state at ``fb_hz`` (its
    complex amplitude ``1/(ω² − ω_b² + 2iζωω_b)``) plus the free decay that starts it from
    zero deflection and velocity, 40 dB SNR; written in NumPy, not with the package's model."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    wb = 2 * np.pi * fb_hz
    y = np.zeros_like(t)
    for f, a in ((f1_hz, 1.0), (RATIO * f1_hz, -0.3)):
        w = 2 * np.pi * f
        sigma, wd = zeta * w, w * np.sqrt(1 - zeta**2)
        h = a * w**2 / (w**2 - wb**2 + 2j * zeta * w * wb)  # steady state of e^{iω_b t}
        steady = np.imag(h * np.exp(1j * wb * t))
        # homogeneous part e^{-σt}(c1 cos ω_d t + c2 sin ω_d t) cancelling x(0) and x'(0)
        c1 = -np.imag(h)
        c2 = -(np.real(h) * wb + sigma * c1) / wd
        y += steady + np.exp(-sigma * t) * (c1 * np.cos(wd * t) + c2 * np.sin(wd * t))
    y = 500.0 * y + 100.0
    y += rng.normal(0.0, np.std(y) / 10 ** (40 / 20), t.size)
    return Observation(t, y, excitation="sine", fb_hz=fb_hz, observable="deflection")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rate", "f1", "zeta", "fb", "duration"),
    # 1500 samples each: the second case runs the programs the first compiled
    [(1000.0, 46.0, 0.04, 30.0, 1.5), (200.0, 71.0, 0.02, 40.0, 7.5)],
)
def test_a_sine_grid_sized_to_its_points_chooses_what_the_full_grid_chose(
    rate, f1, zeta, fb, duration
):
    """No free decay: 17 f_1 steps × 2 ζ, then 4 × 5 ζ, in a grid of 24 × 2 and 4 × 8 (80
    profiles), not the full one (48 × 2, then 4 × 12: the same points, more padding). Both
    choose the same start, on a sine from rest written in NumPy, and it is the grid's best:
    the step (12 % apart) nearest the truth's f_1, or its neighbour."""
    obs = _sine_from_rest(rate, f1, zeta, fb, duration_s=duration)
    nominal = _record(1.3 * f1)
    problem, whisker = _problem(obs, nominal)
    grid = start_grid(problem, [obs], whisker)
    assert grid["f_hz"].shape == (F_FORCED,) and grid["zeta"].shape == (Z_FORCED,)
    full = dict(grid)  # the grid as it was: the same points, padded further
    for key, n in (("f_hz", F_POINTS), ("log_kappa", F_POINTS), ("zeta", Z_POINTS)):
        full[key] = np.pad(grid[key], (0, n - grid[key].size), mode="edge")
    full["zeta1"] = np.pad(grid["zeta1"], ((0, F_POINTS - F_FORCED), (0, 0)), mode="edge")
    full["f_valid"] = np.pad(grid["f_valid"], (0, F_POINTS - F_FORCED))
    full["z_valid"] = np.pad(grid["z_valid"], (0, Z_POINTS - Z_FORCED))
    new, old = (_start_jit(problem, {k: np.asarray(v) for k, v in g.items()}) for g in (grid, full))
    for key in ("log_kappa", "zeta_u"):
        assert np.allclose(np.asarray(new[key]), np.asarray(old[key]), rtol=0, atol=1e-12)
    f_start = float(problem.whisker(new).natural_frequencies_hz[0])
    # At 200 Hz mode 1's transient at 71 Hz and at its alias 129 Hz give the same samples
    # (only the weak mode 2 differs), and a sine has no Nyquist preference: either may win.
    lines = [f1] if rate / 2 > 2.5 * 1.3 * f1 else [f1, rate - f1]
    assert min(abs(np.log(f_start / f)) for f in lines) < 1.5 * np.log(2.5) / 16, (f_start, f1)
