"""Release detection on recordings as they come: one release is one decay, whatever rides on it.

Counted on an independent generator (``tests/generators/realistic_decays.py``: three modes,
pink and white noise, drift, mains hum, a hand's hold, taps at random phases, a 200 Hz
ADS1115 Hall sensor or a jittered 4 kHz accelerometer) and, where ``../shared/data`` is
present, on the real cantilever recordings (one pluck each).
"""

from pathlib import Path

import numpy as np
import pytest
from generators.realistic_decays import recording

from whiskerid.fit import find_decays

CANTILEVER = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cantilever"


@pytest.mark.parametrize(
    ("sensor", "seed", "n_taps"),
    [("hall", 0, 1), ("hall", 2, 3), ("hall", 4, None), ("hall", 6, 4),
     ("accelerometer", 1, 1), ("accelerometer", 3, 3), ("accelerometer", 5, None)],
)  # fmt: skip
def test_one_decay_per_release(sensor, seed, n_taps):
    t, y, truth = recording(np.random.default_rng(seed), sensor, n_taps=n_taps)
    decays = find_decays(t, y)
    assert len(decays) == truth.n_decays
    # each release found within a few periods of where it was
    starts = [d.start_s for d in decays[int(truth.from_start) :]]
    assert np.allclose(starts, truth.releases_s, atol=3.0 / truth.f1_hz)
    # at the first mode, not at the accelerometer's stronger-looking second
    assert all(abs(d.frequency_hz / truth.f1_hz - 1) < 0.05 for d in decays)


def test_a_rattle_every_period_is_not_a_release():
    """A clamp that knocks once a period rings a high resonance (here 390 Hz) a hundred
    times a decay: it was found as dozens of decays; the motion is one."""
    rng = np.random.default_rng(3)
    t = np.cumsum(np.full(40_000, 1 / 4000.0) * (1 + 0.05 * rng.standard_normal(40_000)))
    f1, tau = 4.3, 4.0
    y = np.exp(-t / tau) * np.cos(2 * np.pi * f1 * t)
    for k in np.flatnonzero(np.diff(np.sign(np.cos(2 * np.pi * f1 * t))) > 0):
        s = t - t[k]
        on = s >= 0
        y[on] += 0.3 * np.exp(-t[k] / tau) * np.exp(-s[on] / 0.01) * np.sin(2 * np.pi * 390 * s[on])
    y += 0.01 * rng.standard_normal(t.size)
    assert len(find_decays(t, y)) == 1


@pytest.mark.skipif(not CANTILEVER.is_dir(), reason="no ../shared/data/cantilever (real data)")
def test_real_cantilever_one_pluck_each():
    for path in sorted(CANTILEVER.glob("*/*.npy")):
        a = np.load(path)
        assert len(find_decays(a[0], a[1])) == 1, path.name
