"""Terrain simulator: determinism, compiled once, wheel filter, speed moves texture frequency."""

import logging
from dataclasses import replace

import jax
import numpy as np
import pytest

import whiskerid as wi
from whiskerid.terrain import RunSpec, base_acceleration, iso8608_roughness


def _compiles(caplog) -> int:
    return sum("Compiling" in r.getMessage() for r in caplog.records)


BRICK, SAND = RunSpec("brick", 0.2, 0), RunSpec("sand", 0.1, 1)


def test_synthesis_is_deterministic_by_seed_and_compiled_once(caplog):
    a = wi.synthesize_runs([BRICK, SAND], duration_s=2.0)
    # Another seed, terrains, speeds, whisker and amplifier in batches of the same shapes:
    # nothing is compiled again (the physical numbers are traced, not baked in).
    other = replace(wi.paper_record(), zeta=0.07, tip_mass_kg=1e-4, sensor_position_m=0.006)
    with caplog.at_level(logging.WARNING), jax.log_compiles():
        b = wi.synthesize_runs([SAND, RunSpec("flat", 0.15, 0)], duration_s=2.0)
        c = wi.synthesize_runs([SAND, BRICK], duration_s=2.0, seed=1)
        d = wi.synthesize_runs([RunSpec("soft-soil", 0.3, 2), RunSpec("carpet", 0.25, 0)],
                               duration_s=2.0, record=other, amplifier=13.0)  # fmt: skip
    assert _compiles(caplog) == 0
    assert d[0].signal().std() > 0
    # A run does not depend on the runs synthesised with it, nor on its place among them.
    np.testing.assert_array_equal(a[1].signal(), b[0].signal())
    np.testing.assert_array_equal(a[1].t, b[0].t)
    assert not np.array_equal(b[0].signal(), c[0].signal())
    rec = a[0]
    assert rec.t.size == 400 and rec.meta["terrain"] == "brick" and rec.meta["speed_mps"] == "0.2"
    assert np.all(np.diff(rec.t) > 0) and abs(np.median(np.diff(rec.t)) - 0.005) < 1e-4
    assert rec.signal().dtype.kind == "i" and rec.signal().std() > 3  # codes that vary


@pytest.mark.slow
def test_synthesis_does_not_depend_on_the_batch_size():
    whole = wi.synthesize_runs([BRICK, SAND], duration_s=2.0)
    single = wi.synthesize_runs([BRICK, SAND], duration_s=2.0, batch=1)
    for x, y in zip(whole, single, strict=True):
        np.testing.assert_array_equal(x.signal(), y.signal())


def test_wheel_filter_passes_long_waves_and_removes_short_ones():
    dx = 5e-4
    x = np.arange(8000) * dx
    for wavelength, lo, hi in ((1.0, 0.97, 1.01), (0.004, 0.0, 0.1)):
        z = 1e-3 * np.sin(2 * np.pi * x / wavelength)
        zw = wi.wheel_filter(z, dx, patch_m=0.004)[500:-500]
        ratio = (zw.max() - zw.min()) / 2e-3
        assert lo <= ratio <= hi, (wavelength, ratio)


def test_rigid_wheel_bridges_a_narrow_joint():
    dx = 5e-4
    z = np.zeros(400)
    z[195:205] = -3e-3  # 5 mm wide, 3 mm deep joint
    zw = wi.wheel_filter(z, dx, patch_m=dx)
    drop = 0.035 - np.sqrt(0.035**2 - 0.0025**2)  # sagitta of the 70 mm wheel over 5 mm
    assert abs(zw.min() + drop) < 2e-5 and zw.min() > -1e-3


def test_roughness_variance_matches_the_psd():
    rng = np.random.default_rng(0)
    dx, g0, w = 5e-4, 1e-5, 2.0
    z = np.stack([iso8608_roughness(20000, dx, g0, w, rng) for _ in range(20)])
    n = np.fft.rfftfreq(20000, dx)
    keep = n >= 0.5
    expected = np.sum(g0 * (n[keep] / 0.1) ** -w) * n[1]  # Σ G_d(n_k) Δn
    assert abs(z.var() / expected - 1) < 0.1


def test_speed_moves_the_texture_frequency():
    """Sand ripples of ~80 mm: f = v/λ moves from 1.25 Hz to 3.75 Hz."""
    peaks = []
    for v in (0.1, 0.3):
        t, acc = base_acceleration("sand", v, 20.0, np.random.default_rng(3), vary_run=False)
        f = np.fft.rfftfreq(t.size, t[1] - t[0])
        disp = np.abs(np.fft.rfft(acc)) / np.maximum((2 * np.pi * f) ** 2, 1e-9)
        band = (f > 0.5) & (f < 8)
        peaks.append(f[band][np.argmax(disp[band])])
    assert 0.8 < peaks[0] < 1.8 and 2.6 < peaks[1] < 5.0, peaks


def _planes_record(**planes):
    rec = wi.paper_record()
    return rec.replace(extra={**rec.extra, "planes": planes})


def test_two_sensors_keep_the_vertical_run_and_add_the_lateral_plane():
    """Sensor A of a two-sensor run is the one-sensor run (no cross-talk by default); sensor
    B reads the lateral plane, which is partly coherent with the vertical one. Gain,
    offset and cross-talk of a record's [planes] table act on sensor B as stated."""
    spec = [RunSpec("soft-soil", 0.2, 0)]
    one = wi.synthesize_runs(spec, duration_s=2.0)[0]
    two = wi.synthesize_runs(spec, duration_s=2.0, channels=2)[0]
    assert list(two.columns) == ["hall_a", "hall_b"] and two.meta["planes"]
    np.testing.assert_array_equal(two.columns["hall_a"], one.columns["adc"])
    np.testing.assert_array_equal(two.t, one.t)
    a, b = (two.columns[c].astype(float) for c in ("hall_a", "hall_b"))
    assert b.std() > 3 and abs(np.corrcoef(a, b)[0, 1]) < 0.9
    rec = _planes_record(gain_ratio_b=2.0, offset_b_v=1.0, cross_talk=0.0)
    other = wi.synthesize_runs(spec, duration_s=2.0, channels=2, record=rec)[0]
    b2 = other.columns["hall_b"].astype(float)
    assert abs(b2.std() / b.std() - 2) < 0.1
    lsb = rec.adc.lsb_v
    assert abs((b2.mean() - b.mean()) * lsb - (1.0 - 1.65)) < 0.02
    talk = wi.synthesize_runs(spec, duration_s=2.0, channels=2,
                              record=_planes_record(cross_talk=0.3))[0]  # fmt: skip
    a3 = talk.columns["hall_a"].astype(float)
    assert np.corrcoef(a3, talk.columns["hall_b"])[0, 1] > np.corrcoef(a, b)[0, 1] + 0.2


@pytest.mark.parametrize(
    ("planes", "match"),
    [({"lateral_frequncy_ratio": 1.1}, "unknown key"), ({"cross_talk": 0.9}, "cross_talk"),
     ({"lateral_zeta": 1.5}, "lateral_zeta"), ({"gain_ratio_b": 0.0}, "gain_ratio_b")],
)  # fmt: skip
def test_planes_table_is_checked(planes, match):
    with pytest.raises(ValueError, match=match):
        wi.synthesize_runs([BRICK], duration_s=2.0, channels=2, record=_planes_record(**planes))


def test_lateral_plane_has_its_own_frequency():
    """A lateral frequency ratio moves the lateral whisker's modes by that ratio (κ by its
    square) and leaves the vertical whisker as the record's."""
    from whiskerid.terrain import SensorPlanes

    rec = _planes_record(lateral_frequency_ratio=1.2, lateral_zeta=0.07)
    vert, lat = SensorPlanes.from_record(rec).whiskers(rec)
    np.testing.assert_allclose(lat.natural_frequencies_hz, 1.2 * vert.natural_frequencies_hz)
    np.testing.assert_allclose(vert.natural_frequencies_hz,
                               rec.whisker().natural_frequencies_hz)  # fmt: skip
    assert float(lat.zeta[0]) == 0.07 and float(vert.zeta[0]) == 0.04


@pytest.mark.slow
def test_two_sensor_pluck_calibrates_each_plane(tmp_path):
    """simulate --channels 2 plucks both planes of an asymmetric whisker; calibrate with both
    columns recovers each plane's f1 and zeta, the vertical at the top level and the lateral
    in [planes], without being given either."""
    from whiskerid.cli import main
    from whiskerid.terrain import SensorPlanes

    true = _planes_record(lateral_frequency_ratio=1.08, lateral_zeta=0.05).replace(zeta=0.03)
    whisker, pluck, out = (true.save(tmp_path / "w.toml"), tmp_path / "p.csv",
                           tmp_path / "cal.toml")  # fmt: skip
    assert main(["simulate", "--whisker", str(whisker), "--channels", "2", "--excitation",
                 "decay", "--observable", "adc", "--duration", "2", "--noise-db", "30",
                 "--out", str(pluck)]) == 0  # fmt: skip
    rec = wi.read_recording(pluck)
    assert list(rec.columns) == ["hall_a", "hall_b"]
    nominal = wi.paper_record().save(tmp_path / "nominal.toml")
    assert main(["calibrate", str(pluck), "--whisker", str(nominal), "--signal-col",
                 "hall_a,hall_b", "--out", str(out)]) == 0  # fmt: skip
    cal = wi.load_record(out)
    planes = SensorPlanes.from_record(cal)
    f1 = float(cal.whisker().natural_frequencies_hz[0])
    assert abs(f1 / float(true.whisker().natural_frequencies_hz[0]) - 1) < 0.005
    assert abs(float(np.ravel(cal.zeta)[0]) - 0.03) < 0.002
    assert abs(planes.lateral_frequency_ratio - 1.08) < 0.005
    assert abs(float(planes.lateral_zeta) - 0.05) < 0.003
    assert cal.extra["fit"]["options"]["signal_col"] == "hall_a"


def test_two_sensor_simulation_refuses_what_it_cannot_record(tmp_path):
    from whiskerid.cli import main

    out = str(tmp_path / "x.csv")
    assert main(["simulate", "--channels", "2", "--observable", "deflection", "--out", out]) == 2
    assert main(["simulate", "--channels", "2", "--model", "paper", "--out", out,
                 "--observable", "adc"]) == 2  # fmt: skip
