"""A dead or absurd input is never a terrain: :func:`whiskerid.classify.window_health`, used
by offline ``classify`` and by the online stream alike."""

import numpy as np
import pytest
from scipy.signal import lfilter
from whiskerid.hw import OnlineClassifier

import whiskerid as wi
from whiskerid.classify import HealthReference, TrainConfig, load_dataset, window_health
from whiskerid.io._health import descriptors, sensor_fault, white_flatness
from whiskerid.io._health_modes import mode_prominence

RATE = 200.0
LEVEL = 13200  # ADC codes of 1.65 V at ±4.096 V full scale: a Hall sensor at rest
FAST = TrainConfig(hidden=(16,), max_epochs=40, patience=20, batch_size=64)


def _whisker(rng, n: int, f0: float, drive: float) -> np.ndarray:
    """A resonator at ``f0`` (ζ ≈ 0.05) driven by white noise, in ADC codes: the shape of
    a whisker's signal (its first mode standing out of the spectrum), plus 2 codes of
    electronics noise."""
    r, th = np.exp(-2 * np.pi * f0 * 0.05 / RATE), 2 * np.pi * f0 / RATE
    y = lfilter([1.0], [1.0, -2 * r * np.cos(th), r * r], drive * rng.standard_normal(n))
    return np.round(LEVEL + y + 2 * rng.standard_normal(n))


def _recording(x, **meta) -> wi.Recording:
    return wi.Recording(t=np.arange(x.size) / RATE, columns={"adc": x},
                        meta={"rate_hz": RATE, **meta})  # fmt: skip


@pytest.fixture(scope="module")
def train_set(tmp_path_factory):
    """Two 'terrains' (the resonance driven softly or hard, with a second mode), 5
    recordings each of 10 s."""
    root = tmp_path_factory.mktemp("health")
    rng = np.random.default_rng(0)
    for label, drive in (("soft", 4.0), ("hard", 20.0)):
        for r in range(5):
            x = _whisker(rng, 2000, 35.0 + 3 * r, drive)
            if label == "hard":
                x += np.round(_whisker(rng, 2000, 70.0, drive / 2) - LEVEL)
            wi.write_csv(root / label / f"{label}{r}.csv", _recording(x))
    return load_dataset(root)


@pytest.fixture(scope="module")
def model(train_set):
    return wi.train_classifier(train_set, config=FAST)


@pytest.mark.parametrize(
    ("name", "make", "label", "why"),
    [
        # The probe's cases: a flat 1.65 V plus 1-3 mV of noise (8-24 codes RMS), white
        # noise alone, a chip toggling between two codes.
        ("dead 8", lambda rng, n: LEVEL + 8 * rng.standard_normal(n), "unknown", "noise-like"),
        ("dead 24", lambda rng, n: LEVEL + 24 * rng.standard_normal(n), "unknown", "noise-like"),
        ("white noise", lambda rng, n: 300 * rng.standard_normal(n), "unknown", ""),
        ("two codes", lambda rng, n: LEVEL + rng.integers(0, 2, n), "sensor-fault", "toggling"),
        ("absurd gain", lambda rng, n: 1e6 * (_whisker(rng, n, 40, 4) - LEVEL), "unknown", ""),
    ],
)  # fmt: skip
def test_a_dead_or_absurd_input_is_never_a_terrain(model, name, make, label, why):
    """Every window, offline and online: the fault label and its reason, no terrain."""
    x = np.round(make(np.random.default_rng(3), 1600))
    res = model.classify_recording(_recording(x))
    assert {w["label"] for w in res["windows"]} == {label}, name
    assert res["label"] == label and res["confidence"] == 0.0 and why in res["reason"]
    assert res["fault_windows"] == len(res["windows"])
    online = OnlineClassifier(model, hop_s=1.0, limits=(-1e12, 1e12))
    labels = [lab for i, v in enumerate(x) if (lab := online.push(i / RATE, v)) is not None]
    assert len(labels) >= 6 and {lab.label for lab in labels} == {label}
    assert all(lab.fault and lab.reason for lab in labels)


def test_a_recording_that_sticks_or_pins_loses_only_its_dead_windows(model):
    """Stuck after 2 s, or pinned at 32767 for its second half: the windows over the dead
    part (and those it covers by a quarter or more) are sensor faults, the rest terrains."""
    rng = np.random.default_rng(4)
    x = _whisker(rng, 2000, 40.0, 20.0)
    stuck, pinned = x.copy(), x.copy()
    stuck[400:] = stuck[400]
    pinned[1000:] = 32767
    for y, dead_from in ((stuck, 2.0), (pinned, 5.0)):
        res = model.classify_recording(_recording(y))
        for w in res["windows"]:
            dead = w["start_s"] + 1.0 > dead_from + 0.25
            assert (w["label"] == "sensor-fault") == dead, w
            assert (w["label"] in model.labels) == (not dead)
        assert res["label"] in model.labels  # the whole: from the live windows only


def test_clean_held_out_recordings_are_rarely_rejected(model):
    """The false-rejection rate on clean recordings the model never saw (the training
    windows' own rate is kept in the model file)."""
    rng = np.random.default_rng(11)
    n = rejected = 0
    for r in range(6):
        res = model.classify_recording(_recording(_whisker(rng, 2000, 36.0 + 2 * r, 4.0)))
        n += len(res["windows"])
        rejected += res["fault_windows"]
    assert n == 60 and rejected <= 1  # measured 0
    assert model.health.train_rejection <= 0.01 and model.health.noise_flatness is not None


def test_the_reference_round_trips_through_the_model_file(model, tmp_path):
    """Saved and loaded with the model; an older model (no reference) still catches sensor
    faults; a corrupt reference is refused by name."""
    back = wi.ClassifierModel.load(model.save(tmp_path / "m"))
    assert back.health.to_dict() == model.health.to_dict()
    x = np.round(LEVEL + 8 * np.random.default_rng(0).standard_normal(200))
    assert back.window_health(x)[0] == "unknown"
    back.health = None
    assert back.window_health(x) is None
    assert back.window_health(np.full(200, 32767.0))[0] == "sensor-fault"
    head = (tmp_path / "m" / "model.json").read_text()
    (tmp_path / "m" / "model.json").write_text(head.replace('"log_rms"', '"log_rm"'))
    with pytest.raises(wi.ModelError, match="corrupt health reference"):
        wi.ClassifierModel.load(tmp_path / "m")


def test_sensor_faults_need_no_training_data():
    rng = np.random.default_rng(1)
    live = _whisker(rng, 200, 40.0, 4.0)
    assert sensor_fault(live) is None and window_health(live) is None
    assert "not-finite" in sensor_fault(np.where(np.arange(200) == 7, np.nan, live))
    assert "flat" in sensor_fault(np.full(200, 5.0))
    assert "toggling" in sensor_fault(np.tile([3.0, 4.0], 100))
    held = live.copy()
    held[150:] = held[150]  # the last quarter frozen
    assert "stuck: 50 of 200" in sensor_fault(held)
    assert "channel 1" in sensor_fault(np.stack([live, np.full(200, 1.0)]))


def test_white_noise_flatness_threshold_matches_theory():
    """One periodogram of white noise has expected log flatness log10 e^-γ ≈ -0.251 (the
    mean of log χ²₂/2 is -γ); the 0.1 % quantile lies below it, and approaches it as the
    window lengthens (fewer bins, more spread)."""
    rng = np.random.default_rng(2)
    mean = descriptors(rng.standard_normal((4000, 400)))[:, 1].mean()
    assert mean == pytest.approx(np.log10(np.exp(-np.euler_gamma)), abs=0.01)
    assert white_flatness(100) < white_flatness(400) < mean


def test_training_on_noise_like_windows_turns_the_noise_check_off():
    """A model whose own classes look like white noise cannot call noise unknown."""
    rng = np.random.default_rng(5)
    w = rng.standard_normal((200, 200)) * np.repeat([1.0, 3.0], 100)[:, None]
    ref = HealthReference.fit(w, np.repeat([0, 1], 100))
    assert ref.noise_flatness is None and ref.out_of_range(rng.standard_normal(200)) is None
    assert "amplitude" in ref.out_of_range(1e4 * rng.standard_normal(200))


def _coloured(rng, n: int, corner_hz: float, rms: float) -> np.ndarray:
    """Electrical noise through a first-order low-pass: not flat in spectrum, yet with
    nothing standing out anywhere (what a dead input behind a filter gives)."""
    a = np.exp(-2 * np.pi * corner_hz / RATE)
    y = lfilter([1 - a], [1.0, -a], rng.standard_normal(n + 200))[200:]
    return np.round(LEVEL + rms * y / y.std())


def test_the_mode_check_finds_the_training_resonance_and_rejects_what_lacks_it(model, train_set):
    """The reference's modes are the training windows' resonances (five whiskers of 35 to
    47 Hz here: one or two modes in that span); white noise reaches the threshold in about
    0.1 % of windows."""
    ref = model.health
    assert ref.rate_hz == RATE and 1 <= len(ref.modes_hz) <= 2
    assert all(33 <= f <= 49 for f in ref.modes_hz) and ref.mode_floor is not None
    rng = np.random.default_rng(21)
    noise = rng.standard_normal((4000, 200))
    caught = mode_prominence(noise, RATE, ref.modes_hz).max(axis=1) < ref.mode_floor
    # At most one in a thousand passes (the threshold is lowered only as far as the
    # training windows' weakest need, while it still catches 90 %)
    assert ref.mode_noise_caught >= 0.9 and caught.mean() == pytest.approx(
        ref.mode_noise_caught, abs=0.01
    )
    assert (
        np.mean(mode_prominence(train_set.windows, RATE, ref.modes_hz).max(axis=1) < ref.mode_floor)
        <= 0.005
    )
    # Coloured noise at the level and amplitude of the training windows: not flat (the
    # noise check passes much of it), and no whisker near the mode (measured: 97 % and
    # 98 % of windows refused, 97 % and 52 % by the mode check).
    for corner in (5.0, 20.0):
        why = [model.window_health(_coloured(rng, 200, corner, 10.0)) for _ in range(300)]
        assert np.mean([w is not None and w[0] == "unknown" for w in why]) >= 0.93, corner
        assert any(w is not None and "no whisker response" in w[1] for w in why)
    # One recording of it: its windows get no terrain but for a few at most.
    res = model.classify_recording(_recording(_coloured(rng, 2000, 5.0, 10.0)))
    assert res["fault_windows"] >= 8 and "no whisker response" in " ".join(
        w.get("reason", "") for w in res["windows"]
    )


def test_a_mode_threshold_is_kept_and_checked_in_the_model_file(model, tmp_path):
    back = wi.ClassifierModel.load(model.save(tmp_path / "m"))
    assert back.health.modes_hz == model.health.modes_hz
    assert back.health.mode_floor == model.health.mode_floor
    head = (tmp_path / "m" / "model.json").read_text()
    (tmp_path / "m" / "model.json").write_text(head.replace('"modes_hz": [', '"modes_hz": [150, '))
    with pytest.raises(wi.ModelError, match="corrupt health reference"):
        wi.ClassifierModel.load(tmp_path / "m")


def test_on_another_whisker_only_the_noise_check_applies():
    """Another whisker has its own offset, gain and mode: a louder, shifted resonance is not
    refused, electrical noise still is, and an amplitude far beyond that whisker's gain."""
    rng = np.random.default_rng(8)
    train = np.stack([_whisker(rng, 200, 40.0, 4.0) for _ in range(300)])
    ref = HealthReference.fit(train, rate_hz=RATE, modes_hz=(40.0,))
    assert ref.mode_floor is not None and ref.train_rejection <= 0.01
    other = ref.for_whisker()
    louder = 5 * (_whisker(rng, 200, 25.0, 4.0) - LEVEL) + 3 * LEVEL  # another gain, offset
    assert ref.out_of_range(louder) is not None and other.out_of_range(louder) is None
    assert "noise-like" in other.out_of_range(LEVEL + 8 * rng.standard_normal(200))
    # With that whisker's gain (5 here), its amplitude range: the louder whisker passes,
    # a thousand times more is refused.
    scaled = ref.for_whisker(5.0)
    assert scaled.out_of_range(louder) is None
    assert "amplitude" in scaled.out_of_range(1000 * (louder - 3 * LEVEL))
