"""The noise-floor check: the floor from a quiet stretch (second differences, trimmed), its
degrees of freedom, ADC steps, the F test's false-alarm rate, and a held pluck end to end."""

from types import SimpleNamespace

import numpy as np
import pytest

from whiskerid.fit._data import _noise_floor as NF
from whiskerid.fit._data._release import Decay


def test_floor_ignores_offset_drift_and_tremor():
    rng = np.random.default_rng(0)
    fs, m, sigma = 200.0, 400, 3.0
    t = np.arange(m) / fs
    held = 1000 + 40 * t + 20 * np.sin(2 * np.pi * 10 * t)  # drift and a 10 Hz tremor
    floor = NF.noise_floor(held + rng.normal(0, sigma, m))
    # the tremor's share: (2 - 2cos 2πf/fs)² A²/2 / 6 ≈ 0.32 of σ² = 9 here: at most 2 %
    assert floor["sigma"] == pytest.approx(sigma, rel=0.12)
    assert floor["nu"] == pytest.approx(36 * (m - 2) / 70, rel=0.01)


def test_degrees_of_freedom_match_the_estimates_scatter():
    """Var σ̂² = 2σ⁴/ν over repeats (Gaussian noise): the ν the F test uses is right."""
    rng = np.random.default_rng(1)
    m, reps = 120, 3000
    est = np.array([NF.noise_floor(rng.normal(0, 1, m))["sigma"] ** 2 for _ in range(reps)])
    nu = NF.noise_floor(np.zeros(m) + rng.normal(0, 1, m))["nu"]
    assert np.mean(est) == pytest.approx(1.0, abs=0.02)
    assert np.var(est) == pytest.approx(2 / nu, rel=0.15)


def test_quantum_and_rounding_floor():
    codes = np.round(np.random.default_rng(2).normal(5000, 4, 300))
    assert NF.lattice_step(codes) == 1.0
    lsb = 4.096 / 32768
    assert NF.lattice_step(codes * lsb) == pytest.approx(lsb, rel=1e-9)
    assert NF.lattice_step(np.random.default_rng(3).normal(0, 1, 300)) == 0.0
    # a stretch that sits on one code: the floor is the rounding of a moving signal, q/√12
    floor = NF.noise_floor(np.full(100, 7.0), q=1.0)
    assert floor["sigma"] == pytest.approx(1 / np.sqrt(12))


def test_trimming_drops_a_ramp_and_an_impact():
    rng = np.random.default_rng(4)
    x = rng.normal(0, 1.0, 300)
    x[100:120] += np.linspace(0, 400, 20)  # the hand bends the whisker
    x[120:] += 400
    x[250] += 300  # a knock
    floor = NF.noise_floor(x)
    assert floor["sigma"] == pytest.approx(1.0, rel=0.12)
    assert floor["trimmed"] >= 3


def _fake(sigma_resid, sigma_floor, n, m, rng, name="r"):
    resid = rng.normal(0, sigma_resid, n)
    obs = SimpleNamespace(t=np.arange(n) / 200.0, y=rng.normal(0, 50, n), name=name,
                          quiet=rng.normal(0, sigma_floor, m))  # fmt: skip
    per = {"rms_residual": float(np.sqrt(np.mean(resid**2)))}
    return per, obs


def test_f_test_false_alarm_rate_and_power():
    """Residuals at the floor: p-values uniform (5 % below 0.05, within binomial scatter),
    never a rejection; residuals three times the floor: rejected, with a message."""
    rng = np.random.default_rng(5)
    p = []
    for _ in range(800):
        per, obs = _fake(1.0, 1.0, 600, 80, rng)
        res = NF.floor_test([per], [obs], n_params=0)
        assert not res["rejects"]
        p.append(res["recordings"][0]["p_value"])
    assert 0.025 < np.mean(np.array(p) < 0.05) < 0.075
    per, obs = _fake(3.0, 1.0, 600, 80, rng, name="pluck")
    res = NF.floor_test([per], [obs], n_params=6)
    assert res["rejects"] == ["pluck"]
    assert "times the noise measured on its quiet stretch" in res["message"]
    # no quiet stretch: not tested
    obs.quiet = None
    assert not NF.floor_test([per], [obs], n_params=6)["recordings"][0]["tested"]


def test_a_residual_far_above_a_tiny_floor_is_rejected_not_an_overflow():
    """A fit to noise beside a near-silent hold: the variance ratio is beyond a float (it
    raised OverflowError); an exactly constant hold is not tested."""
    rng = np.random.default_rng(6)
    per, obs = _fake(1e150, 1e-160, 600, 80, rng, name="noise")
    res = NF.floor_test([per], [obs], n_params=6)
    assert res["rejects"] == ["noise"] and res["recordings"][0]["p_value"] == 0.0
    obs.quiet = np.zeros(80)
    obs.y = rng.normal(0, 50, 600)  # not on a converter's codes: no rounding floor either
    assert not NF.floor_test([per], [obs], n_params=6)["recordings"][0]["tested"]


def test_quiet_stretch_stops_before_a_tap_and_skips_unseen_releases():
    fs, f = 860.0, 80.0
    t = np.arange(2000) / fs
    y = np.zeros(t.size)
    d = Decay(start_s=t[1000], end_s=t[1800], frequency_hz=f)
    q = NF.quiet_stretch(t, y, [d], 0)
    period = int(np.ceil(fs / f))
    assert q.size == 1000 - NF.MARGIN - period
    # the recording starts in the decay: only the rest after it
    d2 = Decay(start_s=t[0], end_s=t[1800], frequency_hz=f, from_start=True)
    assert NF.quiet_stretch(t, y, [d2], 0).size == 2000 - 1801 - NF.MARGIN
    d3 = Decay(start_s=t[0], end_s=t[1990], frequency_hz=f, from_start=True)
    assert NF.quiet_stretch(t, y, [d3], 0) is None


def test_recording_decays_carry_their_quiet_stretch():
    """A held pluck read as the command line reads it: the decay's observation carries the
    hold (not the decay), whose floor is the noise put in."""
    from whiskerid.fit import observations_from_recording
    from whiskerid.io import Recording
    from whiskerid.model import paper_record

    rng = np.random.default_rng(6)
    fs, f, zeta, sigma = 200.0, 46.0, 0.03, 0.002
    t = np.arange(int(3.0 * fs)) / fs
    tau = t - 0.8
    y = np.where(tau < 0, 1.0, np.exp(-zeta * 2 * np.pi * f * tau) * np.cos(2 * np.pi * f * tau))
    y = 1.65 + 0.3 * y + rng.normal(0, sigma, t.size)
    rec = Recording(t=t, columns={"voltage": y}, meta={"units": "V", "excitation": "decay"})
    (obs,) = observations_from_recording(rec, paper_record(), observable="voltage")
    assert obs.quiet is not None and obs.quiet.size >= 0.8 * fs - 12
    assert np.all(np.abs(obs.quiet - (1.65 + 0.3)) < 6 * sigma)  # the hold only
    assert NF.noise_floor(obs.quiet)["sigma"] == pytest.approx(sigma, rel=0.2)
