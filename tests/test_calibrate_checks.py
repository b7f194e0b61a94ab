"""A calibration never calls a wrong answer ok, and its 1σ matches the spread of repeats."""

from dataclasses import replace

import numpy as np
import pytest

from whiskerid.fit import Observation, calibrate, observations_from_recording
from whiskerid.io import Recording
from whiskerid.model import paper_record, simulate, simulate_pluck


def _fast_record(**changes):
    rec = paper_record()
    return rec.replace(adc=replace(rec.adc, data_rate_sps=860), **changes)


def _pluck(record, seed=0, extra=None):
    r, _ = simulate_pluck(record, kind="held", rate_hz=860.0, duration_s=1.2, release_s=0.3,
                          hold_s=0.15, noise_db=35.0, seed=seed)  # fmt: skip
    y = r.signal().astype(float)
    if extra is not None:
        y = y + extra(r.t, y)
    return Recording(t=r.t, columns={"adc": y}, meta={"excitation": "decay"}, source="p.csv")


def _hum(t, y):
    """A steady 70 Hz line (a motor on the bench) at a tenth of the pluck's amplitude."""
    return 0.1 * np.std(y) * np.sin(2 * np.pi * 70.0 * t)


def _stiffer(record, factor):
    s = record.structure
    return record.replace(structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * factor))


# (what goes wrong, the record the user gives, a change to the recording, checks one of which
# must fail)
CASES = [
    pytest.param("wrong record: f1 three times the whisker's", lambda r: _stiffer(r, 9.0), None,
                 {"far-from-nominal", "mode-1-weak", "residual-peak", "correlated-residuals",
                  "zeta-large", "at-bound"}, marks=pytest.mark.slow),
    pytest.param("a steady line the model does not have", lambda r: r, _hum,
                 {"residual-peak", "correlated-residuals"}, marks=pytest.mark.slow),
    pytest.param("f1 87 Hz sampled at 200 Hz from a record 30 % high: its alias at 113 Hz "
                 "fits as well", lambda r: _stiffer(r, 1.3**2), None, {"aliased"},
                 marks=pytest.mark.slow),
]  # fmt: skip


@pytest.mark.parametrize(("what", "given", "extra", "expected"), CASES)
def test_a_wrong_or_doubtful_fit_is_not_ok(what, given, extra, expected):
    truth = _fast_record()
    rec = _pluck(truth, extra=extra)
    if "aliased" in expected:  # a stiffer whisker, read at 200 Hz
        truth = _stiffer(paper_record(), (87.0 / 46.0) ** 2)
        r, _ = simulate_pluck(truth, kind="held", rate_hz=200.0, duration_s=3.0, release_s=0.5,
                              noise_db=35.0, seed=0)  # fmt: skip
        rec = Recording(t=r.t, columns={"adc": r.signal().astype(float)},
                        meta={"excitation": "decay"}, source="p.csv")  # fmt: skip
    nominal = given(truth)
    cal = calibrate(nominal, observations_from_recording(rec, nominal, observable="adc"))
    assert cal.status != "ok", what
    if cal.status == "check":
        assert set(cal.checks) & expected, cal.checks
        assert all(name in " ".join(cal.warnings) for name in cal.checks)
    if "correlated-residuals" in cal.checks:  # the 1σ then allows for the correlation
        p = cal.params["f1_hz"]
        assert p["std"] >= p["std_white"]
        assert cal.diagnostics["uncertainty"].startswith("HAC")


def test_a_clean_pluck_is_ok_and_reported():
    truth = _fast_record(zeta=0.05)
    obs = observations_from_recording(_pluck(truth, seed=3), truth, observable="adc")
    cal = calibrate(truth, obs)
    f1 = float(truth.whisker().natural_frequencies_hz[0])
    assert cal.status == "ok" and not cal.checks
    assert abs(cal.params["f1_hz"]["value"] / f1 - 1) < 0.005
    assert abs(cal.params["zeta"]["value"] / 0.05 - 1) < 0.1
    text = cal.report()
    for part in ("status ok", "f1_hz", "±", "release detected", "lag-1", "[[Checks]] all passed"):
        assert part in text


def _sine(seed):
    rec = paper_record()
    r = simulate(rec, excitation="sine", fb_hz=40.0, hb_m=1e-4, observable="adc", rate_hz=200.0,
                 duration_s=3.0, noise_db=30.0, seed=seed)  # fmt: skip
    return Observation(r.t, r.signal(), excitation="sine", fb_hz=40.0, observable="adc", gain=None)


def _decay(seed):
    truth = _fast_record(zeta=0.03)
    r, where = simulate_pluck(
        truth, kind="held", rate_hz=860.0, duration_s=1.2, release_s=0.3, hold_s=0.15,
        noise_db=30.0, seed=seed, drift=0.0, tremor=0.0,
    )  # fmt: skip
    keep = r.t >= where.releases_s[0]
    return Observation(r.t[keep], r.signal()[keep], observable="adc", gain=None)


@pytest.mark.slow
@pytest.mark.parametrize("make", [_sine, _decay], ids=["sine", "decay"])
def test_reported_sigma_matches_the_spread_of_seeded_repeats(make):
    """20 repeats with new noise: the median reported 1σ of f1 and ζ within a factor 1.6 of
    the spread (the spread of 20 values is itself uncertain by about 16 %)."""
    record = paper_record() if make is _sine else _fast_record(zeta=0.03)
    fits = [calibrate(record, make(seed)) for seed in range(20)]
    for name in ("f1_hz", "zeta"):
        values = np.array([c.params[name]["value"] for c in fits])
        sigma = np.median([c.params[name]["std"] for c in fits])
        ratio = sigma / np.std(values, ddof=1)
        assert 1 / 1.6 < ratio < 1.6, (name, ratio)


# (fitted f1, the f1 expected, rates of the decay recordings, the alias reported or None)
ALIASES = [
    (46.0, 59.8, [200.0], None),  # the paper whisker at 200 Hz from a record 30 % high
    (112.9, 113.4, [200.0], 87.1),  # above the Nyquist frequency: the start decided
    (87.1, 113.4, [200.0], 112.9),  # below it, but the alias is nearer the record's
    (87.1, 87.0, [200.0], None),  # below it and nearer the record's
    (87.1, 113.4, [200.0, 860.0], None),  # a recording at 860 Hz tells them apart
    (87.1, 113.4, [], None),  # no free decay (sine or base excitation)
]


@pytest.mark.parametrize(("f1", "expected", "rates", "alias"), ALIASES)
def test_an_f1_is_aliased_when_the_data_cannot_choose_it(f1, expected, rates, alias):
    from whiskerid.fit._checks import aliased

    got = aliased(f1, expected, rates)
    assert (got is None) if alias is None else got == pytest.approx(alias)
