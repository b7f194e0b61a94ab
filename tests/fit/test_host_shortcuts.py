"""A warm calibration's host-side shortcuts give what they replace, to the last bit.

The median by partition against ``np.median``; the envelope's first run of windows found by
slices against the index arrays it replaced; a recording's moments computed while the
compiled program runs against those computed after it.
"""

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.fit._checks._checks import moments
from whiskerid.fit._data._signal import line_fit, median
from whiskerid.fit._linear._problem import FitProblem
from whiskerid.fit._linear._start import _Envelope
from whiskerid.fit._result import recording_diagnostics


def test_the_median_is_numpys_to_the_last_bit():
    """Odd and even lengths (1 to 41 and a few thousand), ties, rounded data, a list; a
    NaN, an integer array and a 2-D array take NumPy's own path and answer."""
    rng = np.random.default_rng(0)
    for n in [*range(1, 42), 1000, 2001, 4000]:
        for k in range(6):
            x = rng.normal(size=n) * 10.0 ** rng.uniform(-6, 6)
            if k % 2:
                x = np.round(x, 1)  # ties in the middle
            got, want = median(x), np.median(x)
            assert got == want and type(got) is type(want)
    assert median([3.0, 1.0, 2.0, 10.0]) == np.median([3.0, 1.0, 2.0, 10.0]) == 2.5
    assert np.isnan(median(np.array([1.0, np.nan, 2.0])))
    assert median(np.array([4, 1, 3, 2])) == np.median(np.array([4, 1, 3, 2])) == 2.5
    m2 = np.arange(12.0).reshape(3, 4)
    assert median(m2) == np.median(m2) == 5.5


def _zeta_as_indices(env: _Envelope, f_obs_hz: float, f_true_hz: float):
    """:meth:`_Envelope.zeta` as written before (every window's mean square by a masked
    divide, the first run of kept windows by index arrays): the plain definition."""
    t, span = env.t, env.span
    win = max(4.0 / max(f_obs_hz, 1e-9), 12 * env.dt)
    n_win = int(span // win)
    if n_win < 3:
        return None
    edges = t[0] + win * np.arange(n_win + 1)
    idx = np.searchsorted(t, edges)
    count = np.diff(idx)
    rms = np.full(count.size, np.nan)
    np.divide(np.maximum(np.diff(env.sums[idx]), 0.0), count, out=rms, where=count > 0)
    rms = np.sqrt(rms)
    mid = 0.5 * (edges[:-1] + edges[1:])
    keep = np.isfinite(rms) & (rms > 4 * np.fmin.reduce(rms))
    if np.count_nonzero(keep) < 2:
        return None
    first = np.flatnonzero(keep)
    breaks = np.flatnonzero(np.diff(first) > 1)
    run = first[: breaks[0] + 1] if breaks.size else first
    if run.size < 2:
        return None
    zeta = -line_fit(mid[run], np.log(rms[run]))[0] / (2 * np.pi * f_true_hz)
    return float(min(max(zeta, 1e-4), 0.5)) if np.isfinite(zeta) else None


@pytest.mark.parametrize("seed", range(6))
def test_the_envelopes_first_run_by_slices_is_the_index_arrays(seed):
    """Decays with a noise bump after them (a second run), with a gap in the samples (empty
    windows), rung down to the end or not, at the line, an alias and a low line (windows
    of many periods): the same ζ, or None, to the last bit."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 6.0, 1500))
    if seed % 2:
        t = t[(t < 2.0) | (t > 2.6)]
    zeta = rng.uniform(0.002, 0.1)
    y = np.exp(-zeta * 2 * np.pi * 30.0 * t) * np.cos(2 * np.pi * 30.0 * t)
    y += rng.normal(0, 10.0 ** rng.uniform(-4, -1), t.size)
    if seed % 3 == 0:
        y += 0.05 * np.exp(-((t - 5.0) ** 2) / 0.01)
    env = _Envelope(t, y - np.median(y))
    answers = 0
    for f_obs, f_true in ((30.0, 30.0), (170.0, 30.0), (5.0, 5.0), (0.8, 0.8), (90.0, 90.0)):
        got, want = env.zeta(f_obs, f_true), _zeta_as_indices(env, f_obs, f_true)
        assert got == want
        answers += got is not None
    assert answers >= 2  # not only Nones compared
    # quiet first, then ringing to the end: the run of kept windows reaches the last one
    late = np.where(t > 2.0, np.sin(2 * np.pi * 30.0 * t) * np.exp(-0.1 * t), 0.0)
    late += rng.normal(0, 1e-4, t.size)
    env = _Envelope(t, late)
    got = env.zeta(30.0, 30.0)
    assert got is not None and got == _zeta_as_indices(env, 30.0, 30.0)
    flat = _Envelope(t, np.ones_like(t))  # no window above four times the quietest
    assert flat.zeta(30.0, 30.0) is None and _zeta_as_indices(flat, 30.0, 30.0) is None


def test_moments_passed_in_give_the_same_diagnostics():
    """``recording_diagnostics`` with the moments computed beside the program equals it computing
    them itself."""
    record = wi.paper_record()
    t = np.arange(600) / 200.0
    y = 3.0 + np.exp(-0.7 * t) * np.sin(2 * np.pi * 23.0 * t)
    obs = [wi.Observation(t, y, excitation="decay", observable="deflection", gain=1.0)]
    problem = FitProblem.from_observations(record, obs, n_modes=2)
    opt = problem.zero_params()
    opt["recs"][0]["c"] = np.linspace(-1.0, 1.0, opt["recs"][0]["c"].size)
    models = [(np.asarray(r.y) * 0.9, np.stack([np.asarray(r.y)] * 2, axis=1))
              for r in problem.recordings]  # fmt: skip
    resid = np.zeros(t.size)
    a, _, _ = recording_diagnostics(problem, opt, obs, models, resid)
    b, _, _ = recording_diagnostics(problem, opt, obs, models, resid, None, moments(obs))
    assert a == b and a[0]["rms_signal"] == float(np.std(y))
