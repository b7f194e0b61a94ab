"""Hall sensor and ADS1115 signal-level model."""

import jax.numpy as jnp
import numpy as np
import pytest

import whiskerid as wi


def test_hall_sensor_polynomial():
    hall = wi.HallSensor(gain_v_per_m=1000.0, offset_v=1.5, quadratic_v_per_m2=2e6)
    w = jnp.array([-1e-3, 0.0, 2e-3])
    np.testing.assert_allclose(hall.voltage(w), 1.5 + 1000 * w + 2e6 * w**2, rtol=1e-14)


@pytest.mark.parametrize(("rate", "f"), [(860, 100.0), (475, 150.0), (250, 100.0), (128, 40.0)])
def test_conversion_averaging_is_a_sinc(rate, f):
    adc = wi.ADS1115Model(data_rate_sps=rate, averaging_points=64)
    t = jnp.linspace(0.1, 0.1 + 20 / f, 4001)
    y = adc.average(lambda s: jnp.sin(2 * jnp.pi * f * s), t)
    assert float(jnp.max(jnp.abs(y))) == pytest.approx(abs(np.sinc(f / rate)), rel=2e-3)


def test_codes_clip_and_scale_exactly():
    adc = wi.ADS1115Model(fsr_v=2.048)
    volts = jnp.array([-3.0, -2.048, -1e-4, 0.0, 0.0625e-3, 1.0, 2.048, 5.0])
    codes = np.asarray(adc.quantise(volts))
    assert codes.tolist() == [-32768, -32768, -2, 0, 1, 16000, 32767, 32767]
    assert float(adc.codes_to_volts(16000)) == 16000 * 2.048 / 32768


def test_oscillator_error_changes_the_conversion_time():
    assert wi.ADS1115Model(data_rate_sps=475, clock_error=0.1).conversion_time_s == (
        pytest.approx(1 / (475 * 1.1))
    )


def test_sample_times_jitter_and_order():
    adc = wi.ADS1115Model(jitter_s=2e-4)
    t = adc.sample_times(200.0, 5.0, rng=np.random.default_rng(0))
    steps = np.diff(t)
    assert np.all(steps > 0)
    assert np.std(steps - 0.005) == pytest.approx(2e-4 * np.sqrt(2), rel=0.15)
    assert t[0] >= adc.conversion_time_s - 0.45 / 200


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"data_rate_sps": 200}, "no 200 SPS"),
        ({"fsr_v": 3.3}, "full-scale"),
        ({"clock_error": 0.5}, "clock_error"),
        ({"noise_v_rms": -1.0}, "noise"),
    ],
)
def test_impossible_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        wi.ADS1115Model(**kwargs)


def test_simulated_adc_recording_sees_f1_and_the_alias_of_f2():
    """At 200 Hz, f_1 = 46 Hz is seen directly and f_2 = 288 Hz folds to 88 Hz."""
    rec = wi.paper_record()
    sim = wi.simulate(
        rec,
        excitation="decay",
        observable="adc",
        tip_deflection_m=3e-3,
        rate_hz=200.0,
        duration_s=4.0,
        seed=2,
    )
    codes = sim.signal()
    assert codes.dtype.kind == "i"
    freqs, amps = wi.amplitude_spectrum(codes[:200].astype(float), 200.0)
    f1_bin = np.argmin(np.abs(freqs - 46.0))
    assert amps[f1_bin - 2 : f1_bin + 3].max() == amps[5:].max()
    # Driven at f_2 and sampled at 200 Hz, the record shows f_2 - 200 = 88 Hz (aliasing
    # follows from evaluating the model at the real sample times).
    f2 = float(rec.whisker().natural_frequencies_hz[1])
    steady = wi.simulate(rec, model="steady", fb_hz=f2, hb_m=1e-5, rate_hz=200.0, duration_s=4.0)
    peak = wi.dominant_peaks(steady.t, steady.signal(), n=1)[0]
    assert peak.frequency_hz == pytest.approx(f2 - 200.0, abs=0.05)
