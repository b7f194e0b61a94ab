"""The robot's body on the ground (stages 3 and 4 of the simulator): the wheel–ground
contact spring–damper, the heave (and roll) of the whisker's mount, and the drivetrain.
"""

import numpy as np

from ._profile import (
    TERRAIN_FAMILIES,
    WHEEL_RADIUS_M,
    WHEELBASE_M,
    TerrainFamily,
    _lognormal,
    terrain_profile,
    vary,
    wheel_filter,
)

GEAR_RATIO = 48.0
INTERNAL_RATE_HZ = 2000.0
SETTLE_S = 1.0  # simulated before t = 0 and dropped: the whisker starts from rest
TAIL_S = 0.5  # simulated after the end: the FFT filtering wraps around at the ends


def ground_transmissibility(f_hz: np.ndarray, ground_hz: float, ground_zeta: float) -> np.ndarray:
    """``H_g(f)``: body motion per unit of filtered profile through the contact spring–damper."""
    w, wg = 2 * np.pi * np.asarray(f_hz), 2 * np.pi * ground_hz
    num = wg**2 + 2j * ground_zeta * wg * w
    return num / (wg**2 - w**2 + 2j * ground_zeta * wg * w)


def base_acceleration(
    terrain: str | TerrainFamily,
    speed_mps: float,
    duration_s: float,
    rng: np.random.Generator,
    *,
    rate_hz: float = INTERNAL_RATE_HZ,
    vary_run: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Vertical acceleration of the whisker base (m/s²) on a uniform grid.

    The grid starts ``SETTLE_S`` before 0 and ends ``TAIL_S`` after ``duration_s``.

    Returns:
        ``(t, acc)`` (s, m/s²).
    """
    t, acc, _ = _body_motion(terrain, speed_mps, duration_s, rng, rate_hz, vary_run, None)
    return t, acc


def base_acceleration_planes(
    terrain: str | TerrainFamily,
    speed_mps: float,
    duration_s: float,
    rng: np.random.Generator,
    lateral_rng: np.random.Generator,
    *,
    rate_hz: float = INTERNAL_RATE_HZ,
    vary_run: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Base acceleration in the whisker's two bending planes (m/s²), shape ``(2, n)``.

    Row 0 is the vertical plane, exactly :func:`base_acceleration` for the same ``rng``;
    row 1 the lateral plane (see :data:`LATERAL_MODEL`), whose own random draws come from
    ``lateral_rng``, so that adding the second plane leaves the first unchanged.

    Returns:
        ``(t, acc)`` (s, m/s²).
    """
    t, vert, lat = _body_motion(terrain, speed_mps, duration_s, rng, rate_hz, vary_run,
                                lateral_rng)  # fmt: skip
    return t, np.stack([vert, lat])


#: How the simulator moves the whisker base sideways (the lateral bending plane).
LATERAL_MODEL = """
The whisker points forward, horizontally, from a mount ``MOUNT_HEIGHT_M`` above the wheel
hubs. Sideways, the base moves for two reasons on rough ground:

* roll: the left and right wheels ride on different heights, so the body rolls by
  ``(z_left − z_right)/TRACK_M`` (front and rear axle weighted like the heave) through the
  same contact spring–damper as the heave, and the mount sways by the roll angle times its
  height. Shared texture (joints, ripples, striations) lifts both tracks alike and does
  not roll the body; independent roughness, tufts and clods do. This is the part of the
  lateral motion that carries the terrain;
* skid: a four-wheeled robot without steering scrubs its tyres sideways; on uneven ground
  the normal loads and so the side forces fluctuate, a broadband lateral vibration (up to
  about 40 Hz, the tyres' lateral compliance) whose level follows the vertical vibration
  (``SKID_LEVEL`` times its RMS, with a run-to-run factor of 1.4).

The drivetrain's shaft tone reaches the mount in both planes (at half the level sideways,
with its own phase). Why this model: it uses only what the paper states of the robot (a
270 mm long, 130 mm wide four-wheeled car with 30 mm wide, 70 mm wheels and a whisker
mounted on a platform above it) and the profiles already simulated, and it makes the two
planes partly coherent (the drivetrain, the vertical level) and partly independent (roll
and skid), as two orthogonal sensors on one whisker are.

What this means for telling terrains apart: the lateral plane sees the terrain only
through the difference of the two tracks. Their roughness and bumps are drawn from one
spectrum per run, so the roll has the spectral shape of the heave's roughness (about six
times its power), and the skid only follows the vertical level: a second look at what the
vertical plane already shows, less its shared texture (joints, ripples, striations), which
rolls nothing. The two planes are nearly incoherent (the heave is the tracks' sum, the roll
their difference). Nothing in this model gives the lateral plane a terrain property the
vertical one lacks (no side slip that depends on the ground, no lateral texture); a
classifier gains from the second sensor only what a second, noisier view of the same
run's roughness is worth.
"""
TRACK_M = 0.10  # wheel centre to centre across a 130 mm wide robot on 30 mm wheels
MOUNT_HEIGHT_M = 0.12  # whisker base above the wheel hubs (m)
SKID_LEVEL = 0.3


def _body_motion(terrain, speed_mps, duration_s, rng, rate_hz, vary_run, lateral_rng):
    """Vertical (and, with ``lateral_rng``, lateral) base acceleration on one grid."""
    fam = TERRAIN_FAMILIES[terrain] if isinstance(terrain, str) else terrain
    if vary_run:
        fam = vary(fam, rng)
    v = speed_mps * (1 + 0.03 * rng.standard_normal()) if vary_run else speed_mps
    t = np.arange(-SETTLE_S, duration_s + TAIL_S, 1.0 / rate_hz)
    margin = WHEELBASE_M + 4 * WHEEL_RADIUS_M
    x, z = terrain_profile(fam, v * (t[-1] - t[0]) + 2 * margin, rng)
    tracks = wheel_filter(z, x[1] - x[0], patch_m=fam.patch_m)
    pos = margin + v * (t - t[0])
    f = np.fft.rfftfreq(t.size, 1.0 / rate_hz)
    lowpass = 1.0 / (1.0 + (f / (0.3 * rate_hz)) ** 8)  # keep the grid's content band-limited
    h_g = ground_transmissibility(f, fam.ground_hz, fam.ground_zeta)

    def to_acc(height):
        height = height - np.polyval(np.polyfit(t, height, 1), t)  # a slope is no vibration
        spec = np.fft.rfft(height) * h_g
        return np.fft.irfft(-((2 * np.pi * f) ** 2) * lowpass * spec, t.size)

    def axles(zw):
        return 0.75 * np.interp(pos + WHEELBASE_M, x, zw) + 0.25 * np.interp(pos, x, zw)

    terrain_acc = to_acc(axles(tracks.mean(axis=0)))
    vert = terrain_acc + _drivetrain(t, v, rng, lowpass, f)
    if lateral_rng is None:
        return t, vert, None
    sway = to_acc(MOUNT_HEIGHT_M * axles(tracks[0] - tracks[1]) / TRACK_M)
    skid = np.fft.irfft(np.fft.rfft(lateral_rng.standard_normal(t.size))
                        / (1.0 + (f / 40.0) ** 4), t.size)  # fmt: skip
    skid *= (
        SKID_LEVEL * _lognormal(lateral_rng, 0.35) * np.std(terrain_acc) / (np.std(skid) + 1e-30)
    )
    lat = sway + skid + 0.5 * _drivetrain(t, v, lateral_rng, lowpass, f)
    return t, vert, lat


def _drivetrain(t, v, rng, lowpass, f) -> np.ndarray:
    """Class-independent vibration: motor shaft tone (and 2nd harmonic) and chassis noise."""
    fm = GEAR_RATIO * v / (2 * np.pi * WHEEL_RADIUS_M)
    level = 0.15 * _lognormal(rng, 0.7)  # m/s²
    tone = level * (np.sin(2 * np.pi * fm * t + rng.uniform(0, 2 * np.pi))
                    + 0.4 * np.sin(4 * np.pi * fm * t + rng.uniform(0, 2 * np.pi)))  # fmt: skip
    noise = np.fft.irfft(np.fft.rfft(rng.standard_normal(t.size)) * lowpass, t.size)
    return tone + 0.05 * _lognormal(rng, 0.5) * noise / (np.std(noise) + 1e-30)
