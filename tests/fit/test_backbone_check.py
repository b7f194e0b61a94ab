"""The nonlinear fit's backbone against the decay's own short-window f and ζ
(``whiskerid.fit._nonlinear._backbone_check``)."""

import numpy as np
import pytest
from generators.nonlinear_plucks import pluck

from whiskerid.fit import Observation, calibrate, nominal_gain
from whiskerid.fit._nonlinear import tip_per_sensor
from whiskerid.fit._nonlinear._backbone_check import backbone_check, misfit_reason
from whiskerid.model import paper_record

F0, RATE = 46.0, 200.0


def _decay(zeta_of_t, t):
    """A decay whose envelope falls at the rate ``ζ(t)ω`` (integrated), at f0."""
    w = 2 * np.pi * F0
    rate = np.cumsum(zeta_of_t * w) * (t[1] - t[0])
    return np.exp(-rate) * np.cos(w * t)


def _check(y, model, t, noise):
    obs = Observation(t, y, observable="voltage", gain=1.0, x_m=0.01)
    per_rec = [{"noise_amplitude_m": noise * np.sqrt(2), "rms_residual": noise}]
    return backbone_check([obs], [(t, y, model)], per_rec, F0)


def test_a_correct_curve_passes_at_its_false_alarm_rate_and_a_wrong_law_does_not():
    """20 noise draws about the true curve: at most 2 alarms (α = 1 %, expected 0.2); a
    constant-ζ curve against data whose ζ halves along the decay: ``backbone-misfit``,
    naming the bands."""
    t = np.arange(0, 3.0, 1 / RATE)
    truth = _decay(np.full(t.size, 0.005), t)
    rng = np.random.default_rng(3)
    alarms = 0
    for _ in range(20):
        check = _check(truth + rng.normal(0, 0.003, t.size), truth, t, 0.003)
        assert len(check["bands"]) == 4 and check["level"] < 0.01 / 8 * 1.01
        alarms += bool(check["misfit"])
    assert alarms <= 2
    # ζ from 0.015 at the release to 0.0075 (amplitude-dependent damping), fitted as 0.005
    data = _decay(0.0075 + 0.0075 * np.exp(-t / 0.6), t) + rng.normal(0, 0.003, t.size)
    check = _check(data, truth, t, 0.003)
    assert check["misfit"]
    text = misfit_reason(check)
    assert text is not None and "a " in text and "dzeta" in text
    assert misfit_reason(_check(truth, truth, t, 0.003)) is None


def _fit(kind, seed, **kwargs):
    record = paper_record()
    w = record.whisker().with_modes(1)
    ratio = float(tip_per_sensor(w, record.sensor_position_m))
    gain = nominal_gain(record, "voltage")
    t, y, truth = pluck(kind, seed, f0_hz=float(w.natural_frequencies_hz[0]), rate_hz=RATE,
                        gain_v_per_m=gain, amplitude_m=(1e-3 / ratio, 3e-3 / ratio))  # fmt: skip
    obs = Observation(t, y, observable="voltage", gain=gain, x_m=record.sensor_position_m)
    return calibrate(record, obs, n_modes=1, model="nonlinear", **kwargs), truth


@pytest.mark.slow
def test_backbone_check_on_independent_plucks():
    """A pluck inside the family (cubic stiffness, velocity-squared damping) stays ``ok``
    with the check run; the same law fitted without its damping term is refused
    (``backbone-misfit``). Not asserted because it is not so: a cubic-damping pluck
    (``ζ ∝ a²``, outside the family) passes the check, its ζ₀ several σ low (the module's
    docstring says why; the strict xfail below)."""
    nl, _ = _fit("cubic+velocity-squared", 0)
    assert nl.status == "ok", nl.warnings
    assert nl.diagnostics["backbone_check"]["bands"]
    assert "backbone-misfit" not in nl.checks


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the backbone check does not see cubic damping (issue 46)")
def test_a_cubic_damping_pluck_is_not_ok():
    """Cubic damping ``u²u̇`` (ζ ×1.5 at the release, outside the family): the fit's ζ₀ is
    10 % low at a pull near −5, and ``ok``. Strict: when a wider damping family or model
    averaging makes it right or not ``ok``, this test says so."""
    nl, truth = _fit("softening+cubic-damping", 0)
    p = nl.params["zeta"]
    assert nl.status != "ok" or abs(p["value"] - truth["zeta0"]) < 3 * p["std"]
