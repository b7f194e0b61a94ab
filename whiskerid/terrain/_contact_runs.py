"""Terrain recordings with the whisker's tip on the ground (``dataset synth --contact``).

The same runs as the linear simulator (same seed: same profile, body motion and
drivetrain), but the whisker's tip rests on the ground in the left wheel's track,
``TIP_AHEAD_M`` ahead of the front axle, and is integrated with :func:`simulate_contact`.
The base follows the body's heave (the wheel-filtered profile through the ground's
spring–damper) plus the drivetrain's vibration; the tip follows the raw profile, rounded
only by the tip's own radius (a 2 mm silicone tip rides into grooves that a 70 mm wheel
bridges). The body's perturbation is the drivetrain's shaft tone, at
``GEAR_RATIO · v/(2πR)`` (22 Hz at 0.1 m/s, 65 Hz at 0.3 m/s), which each recording's
``perturbation_hz`` metadata gives (for ``whiskerid analyze``).

Contact parameters per terrain (:data:`TERRAIN_CONTACT`) and why
-----------------------------------------------------------------
The paper's whisker has a tapered silicone-rubber tip; its tip stiffness is
``3EI/l³ ≈ 48 N/m``, its static preload here ``d₀ = 1 mm`` (about 0.05 N), and it trails
backward-down at 15° (``θ = −0.26 rad``: a dragged tip; a horizontal whisker, ``θ = 0``,
feels no bending from friction, and a pushed one jams when ``tan θ > 1/μ``).

* Hard grounds (flat tile, cement, brick): the compliance is the tip's. Hertz contact of a
  rounded elastic tip of radius ``R = 2 mm`` on a rigid plane: ``N = (4/3) E* √R δ^{3/2}``
  with silicone ``E ≈ 2 MPa``, ``ν ≈ 0.5`` (``E* = E/(1 − ν²) ≈ 2.7 MPa``):
  ``k ≈ 1.6e5 N/m^1.5`` (at 0.05 N, about 1.6 kN/m: 30 times the whisker). Silicone is
  lossy: a restitution ``e ≈ 0.7`` at ``v_i ≈ 0.05 m/s`` gives the Hunt–Crossley
  ``α = 3(1 − e)/(2v_i) ≈ 9 s/m``. Rubber friction on dry hard surfaces is high and rises
  with roughness (hysteresis on the asperities): ``μ ≈ 0.5`` on glazed tile, ``0.9`` on a
  broom-finished slab, ``0.8`` on brick.
* Carpet: the pile under a 2 mm tip, a few mm of fibres of effective modulus ~0.1 MPa over
  ~1e-4 m² (fibres spread the load): ``k ≈ 300 N/m`` linear, heavily damped
  (``α ≈ 20 s/m``), ``μ ≈ 0.5``.
* Soft grass: a few blades bending under the tip, ``k ≈ 80 N/m`` (comparable to the whisker),
  ``α ≈ 30 s/m``, moist blades ``μ ≈ 0.35``.
* Sand: a small indenter in dry sand meets a resistance that grows faster than linearly
  with depth (``n = 1.5``, ``k ≈ 1.5e4 N/m^1.5``: 0.05 N at 0.2 mm), almost plastic
  (``α ≈ 40 s/m``); granular friction ``μ = tan 31° ≈ 0.6``.
* Soft soil: ``k ≈ 600 N/m`` linear, ``α ≈ 25 s/m``, ``μ ≈ 0.7``.

Each run varies them (log-normal, σ = 0.3 in ln for ``k`` and ``α``, 0.15 for ``μ``, 0.2
for the preload). These are order-of-magnitude values from the materials, not
measurements of the paper's robot; the sideband study (``docs/physics.md``) varies the
preload and shows which conclusions depend on them.
"""

from dataclasses import dataclass, replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..io import Recording
from ..model import HallSensor, WhiskerRecord, paper_record
from ._contact import ContactInputs, ContactParams, contact_modes, simulate_contact, static_state
from ._motion import (
    GEAR_RATIO,
    INTERNAL_RATE_HZ,
    SETTLE_S,
    TAIL_S,
    _drivetrain,
    ground_transmissibility,
)
from ._profile import (
    TERRAIN_FAMILIES,
    WHEEL_RADIUS_M,
    WHEELBASE_M,
    _lognormal,
    terrain_profile,
    vary,
    wheel_filter,
)
from ._runs import _CONTACT_SOURCE, _check_runs, _run_rng
from ._sensor import amplified_hall

TIP_AHEAD_M = 0.04  # the tip's contact point ahead of the front axle (m)
TIP_RADIUS_M = 0.002  # radius of the silicone tip (m)


@dataclass(frozen=True)
class TerrainContact:
    """Contact parameters of a terrain (see the module docstring for their reasons)."""

    stiffness: float
    exponent: float
    damping: float
    friction: float


_HARD_SILICONE = {"stiffness": 1.6e5, "exponent": 1.5, "damping": 9.0}
TERRAIN_CONTACT: dict[str, TerrainContact] = {
    "flat": TerrainContact(friction=0.5, **_HARD_SILICONE),
    "cement": TerrainContact(friction=0.9, **_HARD_SILICONE),
    "brick": TerrainContact(friction=0.8, **_HARD_SILICONE),
    "carpet": TerrainContact(300.0, 1.0, 20.0, 0.5),
    "soft-grass": TerrainContact(80.0, 1.0, 30.0, 0.35),
    "sand": TerrainContact(1.5e4, 1.5, 40.0, 0.6),
    "soft-soil": TerrainContact(600.0, 1.0, 25.0, 0.7),
}
DEFAULT_PRELOAD_M = 0.001
DEFAULT_TILT_RAD = -0.26


def contact_params(terrain: str, rng: np.random.Generator | None = None, *,
                   preload_m: float = DEFAULT_PRELOAD_M, tilt_rad: float = DEFAULT_TILT_RAD,
                   slip_velocity: float = 0.01) -> ContactParams:  # fmt: skip
    """A terrain's :class:`ContactParams`, varied per run when ``rng`` is given."""
    c = TERRAIN_CONTACT[terrain]
    if rng is not None:
        c = replace(c, stiffness=c.stiffness * _lognormal(rng, 0.3),
                    damping=c.damping * _lognormal(rng, 0.3),
                    friction=c.friction * _lognormal(rng, 0.15))  # fmt: skip
        preload_m = preload_m * _lognormal(rng, 0.2)
    return ContactParams(stiffness=c.stiffness, exponent=c.exponent, damping=c.damping,
                         friction=c.friction, slip_velocity=slip_velocity, preload=preload_m,
                         tilt_rad=tilt_rad)  # fmt: skip


def perturbation_hz(speed_mps: float, *, per_rev: float = GEAR_RATIO,
                    wheel_radius_m: float = WHEEL_RADIUS_M) -> float:  # fmt: skip
    """The body's perturbation frequency ``per_rev · v/(2πR)`` (Hz): the drivetrain's shaft
    tone for the default ``per_rev`` (the gear ratio)."""
    return per_rev * speed_mps / (2 * np.pi * wheel_radius_m)


def contact_motion(terrain, speed_mps, duration_s, rng, *, rate_hz=INTERNAL_RATE_HZ,
                   vary_run=True, drive_gain=1.0):  # fmt: skip
    """Base and ground motion of one run for the contact simulation.

    Draws from ``rng`` in the order the linear simulator does, so a run of a seed has the
    same terrain, speed and drivetrain with and without contact.

    Returns:
        ``(t, base, ground, v)``: grid (s), ``(y_b, ẏ_b, ÿ_b)`` shape ``(3, n)``, the ground
        under the tip ``(z, ż)`` shape ``(2, n)``, and the run's actual speed (m/s).
    """
    fam = TERRAIN_FAMILIES[terrain] if isinstance(terrain, str) else terrain
    if vary_run:
        fam = vary(fam, rng)
    v = speed_mps * (1 + 0.03 * rng.standard_normal()) if vary_run else speed_mps
    t = np.arange(-SETTLE_S, duration_s + TAIL_S, 1.0 / rate_hz)
    margin = WHEELBASE_M + 4 * WHEEL_RADIUS_M  # as the linear run: the same profile draws
    x, z = terrain_profile(fam, v * (t[-1] - t[0]) + 2 * margin, rng)
    dx = x[1] - x[0]
    tracks = wheel_filter(z, dx, patch_m=fam.patch_m)
    pos = margin + v * (t - t[0])
    f = np.fft.rfftfreq(t.size, 1.0 / rate_hz)
    w = 2 * np.pi * f
    lowpass = 1.0 / (1.0 + (f / (0.3 * rate_hz)) ** 8)
    zw = tracks.mean(axis=0)
    heave = 0.75 * np.interp(pos + WHEELBASE_M, x, zw) + 0.25 * np.interp(pos, x, zw)
    trend = np.polyfit(t, heave, 1)
    spec = np.fft.rfft(heave - np.polyval(trend, t))
    spec = spec * ground_transmissibility(f, fam.ground_hz, fam.ground_zeta)
    drive_acc = drive_gain * _drivetrain(t, v, rng, lowpass, f)
    highpass = (f / 2.0) ** 4 / (1 + (f / 2.0) ** 4)  # chassis vibration, not a drift
    spec = spec - np.fft.rfft(drive_acc) * highpass / np.maximum(w, 1e-9) ** 2
    spec = spec * lowpass
    base = np.stack([np.fft.irfft(spec * (1j * w) ** k, t.size) for k in range(3)])
    tip_track = wheel_filter(z[0], dx, radius_m=TIP_RADIUS_M, patch_m=dx)
    ground = np.interp(pos + WHEELBASE_M + TIP_AHEAD_M, x, tip_track) - np.polyval(trend, t)
    return t, base, np.stack([ground, np.gradient(ground, t)]), v


@eqx.filter_jit
def _contact_chain(modes, contacts, hall, grid_t, base, ground, speeds, y0, t_samples,
                   conv_time, n_avg: int, rtol: float):  # fmt: skip
    """Hall voltages averaged over each conversion for a batch of contact runs (vmapped)."""
    dt = grid_t[1] - grid_t[0]

    def one(c, b, g, v, y, ts, ct):
        inputs = ContactInputs(grid_t[0], dt, b, g, v)
        # up to 50 steps per input interval (100 000 per second at 2 kHz): the budget grows
        # with the run, so that long runs of stiff grounds are not cut short
        res = simulate_contact(modes, c, inputs, grid_t, y, rtol=rtol, atol=rtol * 1e-4,
                               max_steps=50 * grid_t.shape[0])  # fmt: skip
        offsets = -(jnp.arange(n_avg) + 0.5) / n_avg * ct
        tt = ts[:, None] + offsets[None, :]
        volts = jnp.mean(hall.voltage(jnp.interp(tt, grid_t, res.deflection)), axis=1)
        in_contact = jnp.mean(res.normal > 0)
        stick = jnp.sum(jnp.where(jnp.abs(res.slide) < c.slip_velocity, res.normal, 0.0))
        return volts, in_contact, stick / jnp.maximum(jnp.sum(res.normal), 1e-30), res.steps

    return jax.vmap(one)(contacts, base, ground, speeds, y0, t_samples, conv_time)


def _stack(params: list[ContactParams]) -> ContactParams:
    return jax.tree.map(lambda *xs: jnp.stack(xs), *params)


def iter_contact_runs(
    specs,
    *,
    record: WhiskerRecord | None = None,
    duration_s: float = 30.0,
    rate_hz: float = 200.0,
    seed: int = 0,
    jitter_s: float = 2e-4,
    noise_v_rms: float = 2.5e-4,
    amplifier: float = 20.0,
    batch: int = 8,
    preload_m: float = DEFAULT_PRELOAD_M,
    tilt_rad: float = DEFAULT_TILT_RAD,
    drive_gain: float = 1.0,
    rtol: float = 1e-5,
):
    """Like :func:`whiskerid.terrain.iter_runs` (one Hall sensor), with the tip on the
    ground: yields each :class:`Recording` (ADS1115 codes) as its batch is simulated.

    Each recording's metadata adds ``contact`` (the contact law), ``perturbation_hz`` (the
    drivetrain tone at the run's speed), ``contact_fraction`` (share of time in contact)
    and ``stick_fraction`` (share of the normal impulse carried while the tip slides
    slower than the slip velocity).

    Args:
        specs: :class:`RunSpec` list.
        record: The whisker (the paper's by default).
        duration_s: Length of each recording (s).
        rate_hz: Host sampling rate (Hz).
        seed: Dataset seed (the same runs as the linear simulator's).
        jitter_s: Timestamp jitter (s).
        noise_v_rms: ADC input noise (V RMS).
        amplifier: Sensor amplifier gain.
        batch: Runs integrated per vmapped call.
        preload_m: Nominal preload ``d₀`` (m).
        tilt_rad: Whisker angle ``θ`` (rad).
        drive_gain: Factor on the drivetrain's vibration (the body perturbation).
        rtol: Solver relative tolerance.
    """
    record = paper_record() if record is None else record
    _check_runs(specs, duration_s, rate_hz, 1)
    whisker = record.whisker()
    modes = contact_modes(whisker)
    hall: HallSensor = amplified_hall(record, amplifier)
    for lo in range(0, len(specs), max(batch, 1)):
        chunk = specs[lo : lo + batch]
        rows = []
        for spec in chunk:
            rng = _run_rng(seed, spec)
            t, base, ground, v = contact_motion(spec.terrain, spec.speed_mps, duration_s, rng,
                                                drive_gain=drive_gain)  # fmt: skip
            adc = replace(record.adc, jitter_s=jitter_s,
                          clock_error=float(rng.uniform(-0.05, 0.05)))  # fmt: skip
            ts = adc.sample_times(rate_hz, duration_s, rng=rng)
            crng = _run_rng(seed, spec, 7)  # contact draws: the linear run's stream unchanged
            c = contact_params(spec.terrain, crng, preload_m=preload_m, tilt_rad=tilt_rad)
            rows.append((t, base, ground, v, ts, adc, c, rng))
        grid_t = jnp.asarray(rows[0][0])
        y0 = jnp.stack([jnp.asarray(static_state(modes, r[6], r[3])) for r in rows])

        cols = [jnp.asarray(np.stack([r[k] for r in rows])) for k in range(5)]
        volts, frac, stick, _ = _contact_chain(
            modes, _stack([r[6] for r in rows]), hall, grid_t, *cols[1:4], y0, cols[4],
            jnp.asarray([r[5].conversion_time_s for r in rows]),
            record.adc.averaging_points, rtol,
        )  # fmt: skip
        for row, v_run, fr, st, spec in zip(rows, np.asarray(volts), np.asarray(frac),
                                             np.asarray(stick), chunk, strict=True):  # fmt: skip
            _, _, _, v, ts, adc, c, rng = row
            noisy = v_run + noise_v_rms * rng.standard_normal(v_run.shape)
            codes = np.asarray(adc.quantise(noisy)).astype(np.int64)
            meta = {
                "terrain": spec.terrain, "speed_mps": f"{spec.speed_mps:g}",
                "rate_hz": f"{rate_hz:g}", "units": "code", "whisker": record.name,
                "amplifier": f"{amplifier:g}", "run": str(spec.run), "seed": str(seed),
                "source": _CONTACT_SOURCE,
                "contact": (f"hunt-crossley k={float(c.stiffness):.4g} n={float(c.exponent):g} "
                            f"alpha={float(c.damping):.3g} mu={float(c.friction):.3g} "
                            f"preload_m={float(c.preload):.3g} tilt_rad={float(c.tilt_rad):.3g}"),
                "perturbation_hz": f"{perturbation_hz(v):.4f}",
                "contact_fraction": f"{float(fr):.4f}", "stick_fraction": f"{float(st):.4f}",
            }  # fmt: skip
            yield Recording(t=ts, columns={"adc": codes}, meta=meta)
