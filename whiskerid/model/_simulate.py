"""Simulate what a whisker records: model × excitation × observable, sampled like a Pi.

This is the engine behind ``whiskerid simulate``. Models:

* ``paper``: Eq. 1 as printed (sine excitation only);
* ``steady``: the exact modal model's harmonic steady state (sine only);
* ``exact``: the exact modal model from rest: sine switched on at ``t = 0``, free decay
  after a pluck, or an arbitrary sampled base motion. A record calibrated with the
  nonlinear model (a ``[fit.nonlinear]`` table) plays its pluck back with mode 1's cubic
  stiffness and amplitude-dependent damping (:func:`whiskerid.model.nonlinear_pluck_state`).

Observables: ``deflection`` (relative to the base, at the sensor, m), ``acceleration``
(absolute, at the sensor, m/s²: an accelerometer on the beam), ``voltage`` (Hall sensor
output, V) and ``adc`` (ADS1115 codes: averaging over the conversion, oscillator error,
clipping and quantisation). Sample times follow the host's schedule (``rate_hz``) with the
record's timestamp jitter for ``voltage``/``adc``.
"""

from dataclasses import dataclass, replace
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np

from .._choices import EXCITATIONS, MODELS, OBSERVABLES, UNITS
from ..io import Recording
from ._nonlinear import nonlinear_coefficients, nonlinear_pluck_state
from ._paper import paper_eq1
from ._record import WhiskerRecord
from ._response import (
    base_motion_response,
    free_decay,
    harmonic_from_rest,
    harmonic_steady_state,
    observe,
    pluck,
)

Model = Literal["paper", "steady", "exact"]
Excitation = Literal["sine", "decay", "base"]
SimObservable = Literal["deflection", "acceleration", "voltage", "adc"]
SIM_OBSERVABLES = OBSERVABLES


@dataclass(frozen=True)
class BaseMotion:
    """A sampled base acceleration (m/s²) at increasing times (s)."""

    t: np.ndarray
    acc: np.ndarray


def _signal_function(
    record: WhiskerRecord,
    model: Model,
    excitation: Excitation,
    observable: Literal["deflection", "acceleration"],
    *,
    fb_hz: float,
    hb_m: float,
    tip_deflection_m: float,
    base: BaseMotion | None,
    oversample_hz: float,
    t_end: float = np.inf,
):
    """A vectorised JAX function ``t ↦ deflection or acceleration`` at the sensor."""
    whisker = record.whisker()
    if model in ("paper", "steady") and excitation != "sine":
        raise ValueError(
            f"model {model!r} is defined for --excitation sine only; "
            "use --model exact for decay or base"
        )
    if model == "paper":
        if observable != "deflection":
            raise ValueError(
                "model 'paper' gives a displacement only (Eq. 1); use --model "
                "steady or exact for accelerations"
            )
        return lambda t: paper_eq1(whisker, t, fb_hz=fb_hz, hb_m=hb_m)

    absolute = observable == "acceleration"
    if excitation == "sine":
        form = harmonic_steady_state if model == "steady" else harmonic_from_rest
        return lambda t: observe(
            whisker, form(whisker, t, fb_hz=fb_hz, hb_m=hb_m), observable, absolute=absolute
        )
    if excitation == "decay":
        q0 = pluck(whisker, tip_deflection_m)
        if nonlinear_coefficients(record) is not None:  # a nonlinear calibration: mode 1
            return _nonlinear_decay(record, whisker, q0, observable, oversample_hz, t_end)
        return lambda t: observe(
            whisker,
            free_decay(whisker, jnp.maximum(t, 0.0), q0=q0),
            observable,
            absolute=absolute,
        )
    if base is None:
        raise ValueError("--excitation base needs a base-motion file (--base FILE)")
    # Solve on a fine uniform grid (the input linearly interpolated), then interpolate.
    dt = min(float(np.median(np.diff(base.t))), 1.0 / oversample_hz)
    # The response is causal: input after the last sample time changes nothing.
    end = min(float(base.t[-1]), t_end + 2 * dt)
    if (end - base.t[0]) / dt > MAX_SAMPLES:
        raise ValueError(
            f"a base motion over {end - base.t[0]:.3g} s needs {(end - base.t[0]) / dt:.3g} "
            f"solver steps of {dt:.3g} s, more than the limit of {MAX_SAMPLES:.0e}; "
            "simulate a shorter --duration"
        )
    grid = np.arange(base.t[0], end + 0.5 * dt, dt)
    acc = np.interp(grid, base.t, base.acc)
    state = base_motion_response(whisker, jnp.asarray(grid), jnp.asarray(acc), uniform=True)
    values = observe(whisker, state, observable, absolute=absolute)
    return lambda t: jnp.interp(t, jnp.asarray(grid), values)


def _nonlinear_decay(record, whisker, q0, observable, oversample_hz, t_end):
    """A pluck with mode 1 nonlinear, solved on a fine grid and interpolated (the ADC's
    averaging asks for times between samples)."""
    dt = 1.0 / oversample_hz
    end = t_end + 2 * dt if np.isfinite(t_end) else 10.0
    grid = jnp.arange(0.0, end + 0.5 * dt, dt)
    state = nonlinear_pluck_state(whisker, grid, q0, nonlinear_coefficients(record))
    values = observe(whisker, state, observable, absolute=observable == "acceleration")
    return lambda t: jnp.interp(jnp.maximum(t, 0.0), grid, values)


def simulate(
    record: WhiskerRecord,
    *,
    model: Model = "exact",
    excitation: Excitation = "sine",
    observable: SimObservable = "deflection",
    fb_hz: float = 100.0,
    hb_m: float = 1e-4,
    tip_deflection_m: float = 1e-3,
    base: BaseMotion | None = None,
    rate_hz: float = 200.0,
    duration_s: float = 10.0,
    noise_db: float | None = None,
    jitter_s: float | None = None,
    seed: int = 0,
) -> Recording:
    """Simulate a recording of ``observable`` (see the module docstring for the choices).

    Args:
        record: The whisker (structure, damping, sensor, ADC).
        model: ``paper``, ``steady`` or ``exact``.
        excitation: ``sine`` (``fb_hz``, ``hb_m``), ``decay`` (``tip_deflection_m``) or
            ``base`` (``base``).
        observable: ``deflection``, ``acceleration``, ``voltage`` or ``adc``.
        fb_hz: Base excitation frequency (Hz).
        hb_m: Base excitation amplitude (m).
        tip_deflection_m: Initial tip deflection of a pluck (m).
        base: Sampled base acceleration for ``excitation="base"``.
        rate_hz: Host sampling rate (Hz); the Pi samples at 200 Hz.
        duration_s: Length of the recording (s).
        noise_db: Signal-to-noise ratio (dB) of added white noise; none when None.
        jitter_s: Timestamp jitter (s); the record's ADC value for voltage/adc, 0 otherwise.
        seed: Seed for jitter and noise.

    Returns:
        A :class:`Recording` with columns ``t`` and ``observable``, and metadata.
    """
    _check_inputs(model, excitation, observable, fb_hz, hb_m, rate_hz, duration_s)
    _check_optional(tip_deflection_m, noise_db, jitter_s)
    if excitation == "base":
        _check_base(base, rate_hz, duration_s)
    rng = np.random.default_rng(seed)
    physical = "acceleration" if observable == "acceleration" else "deflection"
    adc = record.adc
    if jitter_s is None:
        jitter_s = adc.jitter_s if observable in ("voltage", "adc") else 0.0
    adc = replace(adc, jitter_s=jitter_s)
    if observable in ("voltage", "adc"):
        t = adc.sample_times(rate_hz, duration_s, rng=rng)
    else:
        t = np.arange(round(duration_s * rate_hz)) / rate_hz
        if jitter_s > 0:
            t = t + np.clip(rng.standard_normal(t.size) * jitter_s, -0.45 / rate_hz, 0.45 / rate_hz)
            t = t - min(0.0, t[0])
    fn = _signal_function(
        record,
        model,
        excitation,
        physical,
        fb_hz=fb_hz,
        hb_m=hb_m,
        tip_deflection_m=tip_deflection_m,
        base=base,
        oversample_hz=max(20 * rate_hz, 20_000.0),
        t_end=float(t[-1]),
    )
    values = _observe(record, adc, fn, t, observable, noise_db, rng)
    meta = {
        "rate_hz": f"{rate_hz:g}",
        "units": UNITS[observable],
        "whisker": record.name,
        "model": model,
        "excitation": excitation,
    }
    if excitation == "sine":
        meta.update(fb_hz=f"{fb_hz:g}", hb_m=f"{hb_m:g}")
    if excitation == "decay":
        meta["tip_deflection_m"] = f"{tip_deflection_m:g}"
    if noise_db is not None:
        meta["noise_db"] = f"{noise_db:g}"
    meta["seed"] = str(seed)
    return Recording(t=t, columns={observable: values}, meta=meta)


def _observe(record, adc, fn, t, observable, noise_db, rng) -> np.ndarray:
    fn = jax.jit(fn)
    if observable in ("deflection", "acceleration"):
        clean = np.asarray(fn(jnp.asarray(t)))
        return clean + _noise(clean, noise_db, rng)
    hall = record.hall
    volts_fn = jax.jit(lambda tt: hall.voltage(fn(tt)))
    if observable == "voltage":
        clean = np.asarray(volts_fn(jnp.asarray(t)))
        return clean + _noise(clean, noise_db, rng)
    averaged = np.asarray(adc.average(volts_fn, jnp.asarray(t)))
    noisy = averaged + _noise(averaged, noise_db, rng)
    if adc.noise_v_rms > 0:
        noisy = noisy + adc.noise_v_rms * rng.standard_normal(noisy.shape)
    return np.asarray(adc.quantise(noisy)).astype(np.int64)


def _noise(clean: np.ndarray, noise_db: float | None, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise with power ``var(clean) / 10^(SNR/10)``."""
    if noise_db is None:
        return np.zeros_like(clean)
    sigma = np.std(clean) / 10 ** (noise_db / 20)
    return sigma * rng.standard_normal(clean.shape)


#: Longest simulation (samples); beyond it the arrays would not fit in memory.
MAX_SAMPLES = 100_000_000


def _check_inputs(model, excitation, observable, fb_hz, hb_m, rate_hz, duration_s) -> None:
    for name, value, allowed in (
        ("model", model, MODELS),
        ("excitation", excitation, EXCITATIONS),
        ("observable", observable, SIM_OBSERVABLES),
    ):
        if value not in allowed:
            raise ValueError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")
    for name, value in (("rate_hz", rate_hz), ("duration_s", duration_s), ("fb_hz", fb_hz)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name} = {value!r} must be a positive number")
    if not np.isfinite(hb_m) or hb_m < 0:
        raise ValueError(f"hb_m = {hb_m!r} must be zero or positive")
    if duration_s * rate_hz < 2:
        raise ValueError("duration_s * rate_hz must give at least 2 samples")
    if duration_s * rate_hz > MAX_SAMPLES:
        raise ValueError(
            f"duration_s * rate_hz = {duration_s * rate_hz:.3g} samples is more than the "
            f"limit of {MAX_SAMPLES:.0e}; simulate a shorter recording or a lower rate"
        )


def _check_optional(tip_deflection_m, noise_db, jitter_s) -> None:
    """Refuse NaN and infinities where a number is given (they would fill the output)."""
    if not np.isfinite(tip_deflection_m):
        raise ValueError(f"tip_deflection_m = {tip_deflection_m!r} must be a finite number")
    if noise_db is not None and not np.isfinite(noise_db):
        raise ValueError(
            f"noise_db = {noise_db!r} must be a finite SNR in dB (leave it out for no noise)"
        )
    if jitter_s is not None and (not np.isfinite(jitter_s) or jitter_s < 0):
        raise ValueError(f"jitter_s = {jitter_s!r} must be zero or positive")


#: Slowest base-motion sampling accepted (s): 20 Hz, below the paper whisker's first mode
#: (46 Hz) by half; a time column in ms read as seconds steps by whole seconds.
MAX_BASE_STEP_S = 0.05


def _check_base(base: BaseMotion | None, rate_hz: float, duration_s: float) -> None:
    """The base motion must cover the simulated span: outside it the input would be held."""
    if base is None:
        return
    t = np.asarray(base.t, dtype=float)
    if t.ndim != 1 or t.size < 2 or t.shape != np.shape(base.acc):
        raise ValueError("base motion: time and acceleration must be 1-D of equal length")
    step = float(np.median(np.diff(t)))
    if step > MAX_BASE_STEP_S:
        raise ValueError(
            f"the base motion is sampled every {step:.6g} s: a vibration record that slow "
            "says nothing about a whisker; is its time column in seconds (not ms)?"
        )
    # One sample of slack at either end (a first timestamp one step after 0 is common),
    # but never a sizeable part of the run.
    tol = max(1.0 / rate_hz, min(step, 0.05 * duration_s))
    if t[0] > tol:
        raise ValueError(
            f"the base motion starts at t = {t[0]:.6g} s but the simulation starts at 0: "
            "its time column must be in seconds from 0"
        )
    if t[-1] < duration_s - tol:
        raise ValueError(
            f"the base motion covers t = {t[0]:.6g} .. {t[-1]:.6g} s but the simulation "
            f"needs 0 .. {duration_s:g} s: give a --duration of at most {t[-1]:.6g} s, or a "
            "longer base recording"
        )
