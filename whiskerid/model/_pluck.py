"""Simulate the plucks and taps people make when they calibrate a whisker.

A pluck in a textbook starts at rest in a bent shape at ``t = 0``. A pluck made by hand does
not: the whisker is held bent for a while (and the hand drifts and trembles), or it is
flicked while moving, or tapped, and the recording starts before the release, or after it,
or holds several plucks. Large plucks clip at the ADC's rails for their first cycles. These
recordings are what release detection and calibration must handle, so they are simulated
here with the exact modal model (every mode of the record), the Hall sensor and the
ADS1115's conversion averaging, clipping and quantisation.

Kinds (``kind``):

* ``held``: at rest, then bent over ``ramp_s`` to the pluck's shape, held for ``hold_s``
  (with a slow drift and a hand tremor at 8–12 Hz), then released at rest;
* ``flick``: bent continuously and released while still moving (released with the shape's
  velocity, no hold);
* ``tap``: at rest, then an impulse at the tip (released with velocity only);
* ``late``: the recording starts ``late_s`` after the release;
* several plucks: ``n_plucks`` of the kind above, ``gap_s`` apart.
"""

from dataclasses import dataclass, replace

import jax.numpy as jnp
import numpy as np

from .._choices import UNITS
from ..io import Recording
from ._record import WhiskerRecord
from ._response import free_decay, observe, pluck, tap
from ._simulate import _observe

PLUCK_KINDS = ("held", "flick", "tap", "late")


@dataclass(frozen=True)
class PluckTruth:
    """Where the free decays of a simulated pluck recording start and end (s)."""

    releases_s: tuple[float, ...]
    ends_s: tuple[float, ...]


def simulate_pluck(
    record: WhiskerRecord,
    *,
    kind: str = "held",
    observable: str = "adc",
    rate_hz: float = 860.0,
    duration_s: float = 2.0,
    release_s: float = 0.5,
    hold_s: float = 0.3,
    ramp_s: float = 0.1,
    late_s: float = 0.05,
    tip_deflection_m: float = 2e-3,
    drift: float = 0.02,
    tremor: float = 0.01,
    n_plucks: int = 1,
    gap_s: float = 1.0,
    noise_db: float | None = 40.0,
    seed: int = 0,
) -> tuple[Recording, PluckTruth]:
    """A recording of hand-made plucks, and where their free decays start and end.

    Args:
        record: The whisker (all its modes, damping, sensor and ADC are used).
        kind: ``held``, ``flick``, ``tap`` or ``late`` (see the module docstring).
        observable: ``deflection`` (m), ``voltage`` (V) or ``adc`` (codes).
        rate_hz: Host sampling rate (Hz).
        duration_s: Length of the recording (s).
        release_s: Time of the first release (s); ignored for ``late``.
        hold_s: How long a ``held`` pluck is held before its release (s).
        ramp_s: How long bending the whisker takes (s).
        late_s: For ``late``, how long after the release the recording starts (s).
        tip_deflection_m: Tip deflection at the release (m); for a tap, the tip velocity
            of the impulse is this times the first mode's angular frequency.
        drift: Relative drift of the held deflection over one second of hold.
        tremor: Relative amplitude of the hand's tremor during the hold.
        n_plucks: Plucks in the recording, ``gap_s`` apart.
        gap_s: Time from one release to the start of the next pluck's bending (s).
        noise_db: White noise at this SNR (dB) of the clean signal; none when None.
        seed: Seed for the tremor's frequency and phase, the noise and the ADC jitter.

    Returns:
        The recording (metadata ``excitation: decay``) and the true release times.
    """
    if kind not in PLUCK_KINDS:
        raise ValueError(f"kind must be one of {PLUCK_KINDS}, not {kind!r}")
    rng = np.random.default_rng(seed)
    whisker = record.whisker()
    q0 = pluck(whisker, tip_deflection_m)
    w1 = 2 * np.pi * float(whisker.natural_frequencies_hz[0])
    v0 = tap(whisker, 1.0)
    v0 = v0 * (tip_deflection_m * w1 / float(observe_tip(whisker, v0)))
    shift = -late_s if kind == "late" else release_s
    releases = [shift + k * (gap_s + _lead(kind, hold_s, ramp_s)) for k in range(n_plucks)]
    tremor_hz = rng.uniform(8.0, 12.0)
    tremor_phase = rng.uniform(0, 2 * np.pi)

    def static(a):
        """Sensor deflection of the pluck's shape scaled by ``a`` (0 = at rest)."""
        state = free_decay(whisker, jnp.zeros(1), q0=q0)
        return a * observe(whisker, state)[0]

    def deflection(t):
        t = jnp.asarray(t)
        out = jnp.zeros_like(t)
        for k, r in enumerate(releases):
            start = r - _lead(kind, hold_s, ramp_s)
            end = releases[k + 1] - _lead(kind, hold_s, ramp_s) if k + 1 < n_plucks else np.inf
            before = _before(kind, t - r, hold_s, ramp_s, drift, tremor, tremor_hz, tremor_phase)
            after = _after(kind, whisker, jnp.maximum(t - r, 0.0), q0, v0, ramp_s)
            value = jnp.where(t < r, static(1.0) * before, after)
            out = jnp.where((t >= start) & (t < end), value, out)
        return out

    if observable == "deflection":
        t = np.arange(round(duration_s * rate_hz)) / rate_hz
    else:
        t = record.adc.sample_times(rate_hz, duration_s)
    values = _observe(record, replace(record.adc, jitter_s=0.0), deflection, t, observable,
                      noise_db, rng)  # fmt: skip
    ends = [releases[k + 1] - _lead(kind, hold_s, ramp_s) for k in range(n_plucks - 1)]
    meta = {
        "rate_hz": f"{rate_hz:g}",
        "units": UNITS[observable],
        "whisker": record.name,
        "excitation": "decay",
        "pluck": kind,
        "seed": str(seed),
    }
    truth = PluckTruth(tuple(max(r, float(t[0])) for r in releases), (*ends, float(t[-1])))
    return Recording(t=t, columns={observable: values}, meta=meta), truth


def observe_tip(whisker, v0):
    """Tip velocity (m/s) of modal velocities ``v0`` at ``t = 0``."""
    state = free_decay(whisker, jnp.zeros(1), q0=jnp.zeros_like(v0), v0=v0)
    return observe(whisker, state, "velocity", x_m=whisker.length_m, static_correction=False)[0]


def _lead(kind, hold_s, ramp_s):
    """Time from the start of a pluck's bending (or the tap) to its release (s)."""
    return {"held": ramp_s + hold_s, "flick": ramp_s, "tap": 0.0, "late": 0.0}[kind]


def _before(kind, tau, hold_s, ramp_s, drift, tremor, tremor_hz, tremor_phase):
    """Fraction of the pluck's shape before the release at ``tau = t − release < 0``."""
    if kind in ("tap", "late"):
        return jnp.zeros_like(tau)
    if kind == "flick":
        # bent along a half-cosine that is released at 80 % of its way, still moving
        x = jnp.clip((tau + ramp_s) / ramp_s, 0.0, 1.0) * 0.8
        return (1 - jnp.cos(jnp.pi * x)) / (1 - jnp.cos(jnp.pi * 0.8))
    s = jnp.clip((tau + hold_s + ramp_s) / ramp_s, 0.0, 1.0)
    bend = (1 - jnp.cos(jnp.pi * s)) / 2
    held = tau > -hold_s
    wobble = drift * (tau + hold_s) + tremor * jnp.sin(2 * jnp.pi * tremor_hz * tau + tremor_phase)
    return jnp.where(held, 1.0 + wobble, bend)


def _after(kind, whisker, tau, q0, v0, ramp_s):
    if kind == "tap":
        return observe(whisker, free_decay(whisker, tau, q0=jnp.zeros_like(q0), v0=v0))
    if kind == "flick":
        # velocity of the half-cosine at 80 % of its way, in units of the shape per second
        rate = 0.8 * jnp.pi / ramp_s * jnp.sin(jnp.pi * 0.8) / (1 - jnp.cos(jnp.pi * 0.8))
        return observe(whisker, free_decay(whisker, tau, q0=q0, v0=q0 * rate))
    return observe(whisker, free_decay(whisker, tau, q0=q0))
