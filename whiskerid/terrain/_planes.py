"""Two-plane recordings of one whisker: a pluck, a sine or a measured base motion read by
the two orthogonal Hall sensors (columns ``hall_a``, ``hall_b``).

Each bending plane is its own modal model (the lateral one from the record's ``[planes]``
table, :class:`SensorPlanes`); each sensor reads its plane's deflection plus the cross-talk
fraction of the other's, through its own gain and offset; both are averaged over the
ADS1115's conversion and sampled on the host's schedule, as one-plane recordings are.
"""

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np

from ..io import Recording
from ..model import (
    BaseMotion,
    WhiskerRecord,
    base_motion_response,
    free_decay,
    harmonic_from_rest,
    observe,
    pluck,
)
from ._sensor import PLANE_COLUMNS, SensorPlanes

#: Excitations a two-plane recording can have.
PLANE_EXCITATIONS = ("decay", "sine", "base")
#: Observables of a two-plane recording: what the two Hall sensors give.
PLANE_OBSERVABLES = ("voltage", "adc")


def plane_records(record: WhiskerRecord) -> tuple[WhiskerRecord, WhiskerRecord]:
    """The vertical and the lateral plane of ``record`` as one-plane records.

    The lateral record's stiffness is the vertical one's times ``lateral_frequency_ratio²``
    (its natural frequencies times the ratio) and its damping the ``[planes]`` table's
    ``lateral_zeta``; the ``[planes]`` table itself is left out of both.
    """
    planes = SensorPlanes.from_record(record)
    extra = {k: v for k, v in record.extra.items() if k != "planes"}
    vertical = record.replace(extra=extra)
    s = record.structure
    r2 = planes.lateral_frequency_ratio**2
    stiffer = (
        replace(s, shear_modulus_pa=s.shear_modulus_pa * r2)
        if s.kind == "coil"
        else replace(s, youngs_modulus_pa=s.youngs_modulus_pa * r2)
    )
    zeta = record.zeta if planes.lateral_zeta is None else planes.lateral_zeta
    lateral = vertical.replace(name=f"{record.name}-lateral", structure=stiffer, zeta=zeta)
    return vertical, lateral


def simulate_planes(
    record: WhiskerRecord,
    *,
    excitation: str = "decay",
    observable: str = "adc",
    angle_deg: float = 45.0,
    tip_deflection_m: float = 1e-3,
    fb_hz: float = 100.0,
    hb_m: float = 1e-4,
    base: BaseMotion | None = None,
    lateral_base: BaseMotion | None = None,
    rate_hz: float = 200.0,
    duration_s: float = 10.0,
    noise_db: float | None = None,
    jitter_s: float | None = None,
    amplifier: float = 1.0,
    seed: int = 0,
) -> Recording:
    """A recording of both Hall sensors (columns ``hall_a``: vertical, ``hall_b``: lateral).

    Args:
        record: The whisker; its ``[planes]`` table gives the lateral plane and sensor B
            (:class:`SensorPlanes`; an axisymmetric whisker with equal sensors without one).
        excitation: ``decay`` (a pluck released at rest), ``sine`` (base excitation from
            rest) or ``base`` (a sampled base acceleration).
        observable: ``voltage`` (V) or ``adc`` (ADS1115 codes).
        angle_deg: Direction of the pluck, the sine or ``base`` from the vertical plane
            (degrees): 0 excites the vertical plane only, 90 the lateral one.
        tip_deflection_m: Tip deflection of the pluck (m), along ``angle_deg``.
        fb_hz: Sine frequency (Hz).
        hb_m: Sine amplitude (m), along ``angle_deg``.
        base: Base acceleration (m/s²) along ``angle_deg``, or of the vertical plane when
            ``lateral_base`` is given.
        lateral_base: Base acceleration of the lateral plane (m/s²), on ``base``'s times.
        rate_hz: Host sampling rate (Hz).
        duration_s: Length (s).
        noise_db: White noise added to each sensor at this SNR (dB, of that sensor's own
            signal); none when None.
        jitter_s: Timestamp jitter (s); the record's ADC value when None.
        amplifier: Gain of the sensors' amplifier on top of the record's Hall gain.
        seed: Seed of jitter and noise.

    Raises:
        ValueError: An excitation or observable that is not one of the above, a base
            excitation without its base motion, or numbers out of range.
    """
    _check(excitation, observable, angle_deg, rate_hz, duration_s, base, lateral_base)
    rng = np.random.default_rng(seed)
    planes = SensorPlanes.from_record(record)
    records = plane_records(record)
    adc = record.adc
    adc = replace(adc, jitter_s=adc.jitter_s if jitter_s is None else float(jitter_s))
    t = adc.sample_times(rate_hz, duration_s, rng=rng)
    theta = np.deg2rad(angle_deg)
    along = (np.cos(theta), np.sin(theta))
    fns = [
        _deflection_fn(
            r.whisker(),
            excitation,
            share,
            tip_deflection_m,
            fb_hz,
            hb_m,
            base,
            lateral_base,
            k,
            rate_hz,
            float(t[-1]),
        )
        for k, (r, share) in enumerate(zip(records, along, strict=True))
    ]
    mix = jnp.asarray(planes.mixing())
    halls = planes.halls(record, amplifier)
    columns = {}
    for name, hall, row in zip(PLANE_COLUMNS, halls, mix, strict=True):

        def volts(tt, hall=hall, row=row):
            return hall.voltage(row[0] * fns[0](tt) + row[1] * fns[1](tt))

        fn = jax.jit(volts)
        clean = np.asarray(
            adc.average(fn, jnp.asarray(t)) if observable == "adc" else fn(jnp.asarray(t))
        )
        noisy = clean + _noise(clean, noise_db, rng)
        if observable == "adc":
            if adc.noise_v_rms > 0:
                noisy = noisy + adc.noise_v_rms * rng.standard_normal(noisy.shape)
            noisy = np.asarray(adc.quantise(noisy)).astype(np.int64)
        columns[name] = noisy
    meta = {
        "rate_hz": f"{rate_hz:g}",
        "units": "code" if observable == "adc" else "V",
        "whisker": record.name,
        "model": "exact",
        "excitation": excitation,
        "planes": "hall_a vertical, hall_b lateral",
        "angle_deg": f"{angle_deg:g}",
    }
    if excitation == "decay":
        meta["tip_deflection_m"] = f"{tip_deflection_m:g}"
    if excitation == "sine":
        meta.update(fb_hz=f"{fb_hz:g}", hb_m=f"{hb_m:g}")
    if amplifier != 1.0:
        meta["amplifier"] = f"{amplifier:g}"
    if noise_db is not None:
        meta["noise_db"] = f"{noise_db:g}"
    meta["seed"] = str(seed)
    return Recording(t=t, columns=columns, meta=meta)


def _deflection_fn(
    whisker, excitation, share, tip_m, fb_hz, hb_m, base, lateral, plane, rate_hz, t_end
):
    """``t ↦`` relative deflection at the sensor of one plane (m), vectorised JAX."""
    if excitation == "decay":
        q0 = pluck(whisker, share * tip_m)
        return lambda t: observe(whisker, free_decay(whisker, jnp.maximum(t, 0.0), q0=q0))
    if excitation == "sine":
        return lambda t: observe(
            whisker,
            harmonic_from_rest(whisker, jnp.maximum(t, 0.0), fb_hz=fb_hz, hb_m=share * hb_m),
        )
    if lateral is None:
        acc = share * np.asarray(base.acc, dtype=float)
    else:
        acc = np.asarray((base if plane == 0 else lateral).acc, dtype=float)
    # The response on a fine uniform grid (input linearly interpolated), then interpolated.
    dt = min(float(np.median(np.diff(base.t))), 0.05 / rate_hz)
    grid = np.arange(base.t[0], min(float(base.t[-1]), t_end + 2 * dt) + 0.5 * dt, dt)
    state = base_motion_response(
        whisker, jnp.asarray(grid), jnp.asarray(np.interp(grid, base.t, acc)), uniform=True
    )
    values = observe(whisker, state)
    return lambda t: jnp.interp(t, jnp.asarray(grid), values)


def _noise(clean: np.ndarray, noise_db: float | None, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise with power ``var(clean) / 10^(SNR/10)``."""
    if noise_db is None:
        return np.zeros_like(clean)
    return np.std(clean) / 10 ** (noise_db / 20) * rng.standard_normal(clean.shape)


def _check(excitation, observable, angle_deg, rate_hz, duration_s, base, lateral) -> None:
    if excitation not in PLANE_EXCITATIONS:
        raise ValueError(
            f"excitation must be one of {', '.join(PLANE_EXCITATIONS)}, not {excitation!r}"
        )
    if observable not in PLANE_OBSERVABLES:
        raise ValueError(
            f"two Hall sensors record {' or '.join(PLANE_OBSERVABLES)}, not {observable!r}"
        )
    for name, value in (("rate_hz", rate_hz), ("duration_s", duration_s)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} = {value!r} must be a positive number")
    if not np.isfinite(angle_deg):
        raise ValueError(f"angle_deg = {angle_deg!r} must be a finite number")
    if excitation == "base":
        if base is None:
            raise ValueError("a base excitation needs the base motion")
        if lateral is not None and np.shape(lateral.acc) != np.shape(base.acc):
            raise ValueError("the lateral base motion must be sampled at the vertical one's times")
        if base.t[-1] < duration_s - 1.0 / rate_hz:
            raise ValueError(
                f"the base motion ends at {base.t[-1]:.6g} s, before the {duration_s:g} s "
                "asked for: give a shorter duration"
            )
