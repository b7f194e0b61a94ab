"""Terrain simulator: labelled whisker recordings of the paper's 7 terrains at any speed.

A wheeled robot (the paper's: 70 mm wheels, 0.27 m long) drives at speed ``v`` over a
random surface profile ``z(x)``; its body moves, the whisker base moves with it, and the
whisker's Hall sensor is read by an ADS1115 on a Pi at 200 Hz. Each stage is physical:

1. **Profile** (per track, on a 0.5 mm spatial grid). Every terrain is a *family*:

   * random roughness with an ISO 8608-style displacement PSD
     ``G_d(n) = G₀ (n/n₀)^(−w)`` (``n`` in cycles/m, ``n₀ = 0.1`` cycles/m; ISO road class
     A is ``G₀ = 16e-6 m³`` with ``w = 2``), high-passed below 0.5 cycles/m (hills do not
     shake a whisker);
   * periodic texture: tile or brick joints (spacing, width, depth; bricks also have a
     random height step per unit), carpet pile (a few-mm period), sand ripples and the
     transverse striations of a broom-finished concrete (a shared texture whose wavelength
     wanders by ±15 %);
   * random discrete bumps: grass tufts and stems, soil clods (Poisson positions, raised
     cosine shapes).

   Terrain parameters (``TERRAIN_FAMILIES``):

   ============  ========  ====  ==========================================  =====  =====  =====
   terrain       G₀ (m³)   w     texture                                      f_g    ζ_g    patch
   ============  ========  ====  ==========================================  =====  =====  =====
   flat          0.5e-6    2.0   tile joints every 0.30 m, 3 mm × 0.4 mm      45 Hz  0.12   4 mm
   cement        2e-6      1.5   broom striations, 12 mm, 0.3 mm; joints      45 Hz  0.12   4 mm
                                 every 1.5 m, 10 × 4 mm
   brick         2e-6      2.0   joints every 0.10 m, 5 × 2 mm, steps 1.2 mm  45 Hz  0.12   4 mm
   carpet        1e-6      2.0   pile, 4 mm period, 0.25 mm                   24 Hz  0.35   12 mm
   soft-grass    40e-6     2.2   tufts, 40 per m, 0.5–2 mm high, 8 mm wide    10 Hz  0.5    20 mm
   sand          20e-6     2.4   ripples, 80 mm wavelength, 1.5 mm            7 Hz   0.65   25 mm
   soft-soil     30e-6     2.0   clods, 8 per m, 3–6 mm high, 25 mm wide      20 Hz  0.35   14 mm
   ============  ========  ====  ==========================================  =====  =====  =====

   A broom-finished cement has a flatter PSD slope (more fine texture) than tiles, and the
   broom's transverse striations (a few mm to 15 mm apart, a fraction of a millimetre
   deep); brick pavers' main excitation is the height step (lippage) between units.
   (Revised: cement first had only its 1.5 m joints on top of the roughness, so most 1 s
   windows held no joint and cement differed from brick by the roughness slope alone,
   which is not what a broom-finished slab looks like.)
   The paper's seventh terrain is called asphalt in its Section IV and soft soil in its
   results; it is modelled here as soft soil.

2. **Wheel** (the 70 mm wheels). A rigid wheel of radius ``R`` rides on the upper envelope
   ``z_w(x) = max_{|s|≤R} [z(x+s) + √(R² − s²) − R]`` (it bridges joints narrower than its
   contact: a 10 mm joint lowers it by only 0.36 mm), then the tyre's (or the sinking
   wheel's) contact patch averages over ``patch`` metres. Together they low-pass the profile:
   wavelengths much shorter than the contact are lost (:func:`wheel_filter`).
3. **Ground and tyre compliance**: the wheel–ground contact is a spring–damper, so the body
   follows the filtered profile through the base-excitation transmissibility
   ``H_g(f) = (ω_g² + 2iζ_gω_gω)/(ω_g² − ω² + 2iζ_gω_gω)``; soft ground (grass, sand, soil,
   carpet) has a low ``f_g`` and high damping ``ζ_g``, hard ground only the tyre.
4. **Body**: the whisker sits near the front: heave ``0.75 z_front + 0.25 z_rear`` (front
   and rear wheels 0.17 m apart see the same profile, delayed), averaged over the left and
   right tracks (independent roughness and bumps, shared joints). Speed enters only through
   ``x = v t``: a texture of wavelength ``λ`` excites ``f = v/λ``, so every texture moves
   in frequency with speed. The drivetrain adds class-independent vibration at the motor
   shaft frequency (gear ratio 48, so ``f_m = 48 v/(2πR)``: 22 Hz at 0.1 m/s, 65 Hz at
   0.3 m/s) and its second harmonic, and broadband chassis noise.
5. **Whisker, sensor, ADC**: the base acceleration (on a 2 kHz grid, well above the 288 Hz
   second mode) drives the exact modal model (:func:`base_motion_response`, jitted and
   vmapped over runs; :func:`hall_voltage` is the same whisker and sensor for one run, which
   the online stream feeds to the register-level emulated chip); the relative deflection at
   the sensor goes through the Hall sensor, the ADS1115's averaging over its conversion (the
   anti-alias filter), its noise and quantisation, sampled at 200 Hz with timestamp jitter
   and a per-run oscillator error.

**Run-to-run variation** (so that classes overlap, as real terrain does): ``G₀`` varies by a
log-normal factor (σ = 0.35 in ln), ``w`` by ±0.1, spacings by 8 %, depths and heights by
30 %, ``f_g``/``ζ_g`` by 15 %, the patch by 20 %, the actual speed by 3 % around the
nominal one, and the drivetrain vibration level by a factor of 2. Everything is drawn from
``numpy.random.default_rng([seed, terrain, speed, run])``: a dataset is deterministic for
a seed and does not depend on which other terrains or speeds are synthesised with it.
"""

import os
import shutil
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..io import Recording, write_csv
from ..model import (
    HallSensor,
    Whisker,
    WhiskerRecord,
    base_motion_response,
    observe,
    paper_record,
)

SPEEDS_MPS = (0.10, 0.15, 0.20, 0.25, 0.30)
WHEEL_RADIUS_M = 0.035
WHEELBASE_M = 0.17
GEAR_RATIO = 48.0
PROFILE_DX_M = 5e-4
INTERNAL_RATE_HZ = 2000.0
SETTLE_S = 1.0  # simulated before t = 0 and dropped: the whisker starts from rest
TAIL_S = 0.5  # simulated after the end: the FFT filtering wraps around at the ends
AMPLIFIER = 20.0  # gain of the paper's sensor amplifier, on top of the bare Hall gain
MIN_DATASET_DURATION_S = 2.0  # shortest recording synthesize_dataset makes: a window is 1 s
_SOURCE = "whiskerid terrain simulator"  # metadata that marks the simulator's recordings


@dataclass(frozen=True)
class TerrainFamily:
    """A documented family of random terrain profiles (see the module docstring).

    Attributes:
        name: Label.
        g0_m3: ISO 8608 roughness ``G_d(n₀)`` at ``n₀ = 0.1`` cycles/m (m³).
        waviness: PSD slope ``w``.
        joint_spacing_m: Distance between joints (m); 0 for none.
        joint_width_m: Joint width (m).
        joint_depth_m: Joint depth (m).
        unit_step_m: Standard deviation of the height of each unit between joints (m).
        pile_period_m: Period of a fine periodic texture (carpet pile) (m); 0 for none.
        pile_height_m: Its amplitude (m).
        ripple_m: Wavelength of a texture shared by both tracks (sand ripples, broom
            striations) (m); 0 for none.
        ripple_height_m: Their amplitude (m).
        bumps_per_m: Mean number of discrete bumps per metre (Poisson).
        bump_height_m: ``(low, high)`` heights (m), uniform.
        bump_width_m: Bump width (m).
        ground_hz: Natural frequency ``f_g`` of the wheel–ground contact (Hz).
        ground_zeta: Its damping ratio ``ζ_g``.
        patch_m: Contact patch length (m).
    """

    name: str
    g0_m3: float
    waviness: float
    joint_spacing_m: float = 0.0
    joint_width_m: float = 0.0
    joint_depth_m: float = 0.0
    unit_step_m: float = 0.0
    pile_period_m: float = 0.0
    pile_height_m: float = 0.0
    ripple_m: float = 0.0
    ripple_height_m: float = 0.0
    bumps_per_m: float = 0.0
    bump_height_m: tuple[float, float] = (0.0, 0.0)
    bump_width_m: float = 0.0
    ground_hz: float = 45.0
    ground_zeta: float = 0.12
    patch_m: float = 0.004


_HARD = {"ground_hz": 45.0, "ground_zeta": 0.12, "patch_m": 0.004}
TERRAIN_FAMILIES: dict[str, TerrainFamily] = {
    f.name: f
    for f in (
        TerrainFamily("flat", 0.5e-6, 2.0, joint_spacing_m=0.30, joint_width_m=0.003,
                      joint_depth_m=0.0004, **_HARD),
        TerrainFamily("cement", 2e-6, 1.5, joint_spacing_m=1.5, joint_width_m=0.010,
                      joint_depth_m=0.004, ripple_m=0.012, ripple_height_m=0.0003, **_HARD),
        TerrainFamily("brick", 2e-6, 2.0, joint_spacing_m=0.10, joint_width_m=0.005,
                      joint_depth_m=0.002, unit_step_m=0.0012, **_HARD),
        TerrainFamily("carpet", 1e-6, 2.0, pile_period_m=0.004, pile_height_m=0.00025,
                      ground_hz=24.0, ground_zeta=0.35, patch_m=0.012),
        TerrainFamily("soft-grass", 40e-6, 2.2, bumps_per_m=40.0, bump_height_m=(0.0005, 0.002),
                      bump_width_m=0.008, ground_hz=10.0, ground_zeta=0.5, patch_m=0.020),
        TerrainFamily("sand", 20e-6, 2.4, ripple_m=0.08, ripple_height_m=0.0015,
                      ground_hz=7.0, ground_zeta=0.65, patch_m=0.025),
        TerrainFamily("soft-soil", 30e-6, 2.0, bumps_per_m=8.0, bump_height_m=(0.003, 0.006),
                      bump_width_m=0.025, ground_hz=20.0, ground_zeta=0.35, patch_m=0.014),
    )
}  # fmt: skip
TERRAINS = tuple(TERRAIN_FAMILIES)


def _lognormal(rng, sigma):
    return float(np.exp(sigma * rng.standard_normal()))


def vary(family: TerrainFamily, rng: np.random.Generator) -> TerrainFamily:
    """One run's terrain: the family's parameters with run-to-run random variation."""
    return replace(
        family,
        g0_m3=family.g0_m3 * _lognormal(rng, 0.35),
        waviness=family.waviness + 0.1 * rng.uniform(-1, 1),
        joint_spacing_m=family.joint_spacing_m * (1 + 0.08 * rng.standard_normal()),
        joint_depth_m=family.joint_depth_m * _lognormal(rng, 0.3),
        unit_step_m=family.unit_step_m * _lognormal(rng, 0.3),
        pile_period_m=family.pile_period_m * (1 + 0.08 * rng.standard_normal()),
        pile_height_m=family.pile_height_m * _lognormal(rng, 0.3),
        ripple_m=family.ripple_m * (1 + 0.08 * rng.standard_normal()),
        ripple_height_m=family.ripple_height_m * _lognormal(rng, 0.3),
        bumps_per_m=family.bumps_per_m * _lognormal(rng, 0.3),
        ground_hz=family.ground_hz * _lognormal(rng, 0.15),
        ground_zeta=min(family.ground_zeta * _lognormal(rng, 0.15), 0.95),
        patch_m=family.patch_m * _lognormal(rng, 0.2),
    )


def iso8608_roughness(
    n_points: int, dx_m: float, g0_m3: float, waviness: float, rng: np.random.Generator
) -> np.ndarray:
    """A Gaussian random profile (m) with PSD ``G₀ (n/0.1)^(−w)`` above 0.5 cycles/m.

    Synthesised in the frequency domain: each rFFT bin ``n_k`` contributes a cosine of
    random phase and mean-square ``G_d(n_k) Δn`` (the one-sided PSD), so the profile
    variance is ``Σ G_d Δn ≈ ∫ G_d dn``.
    """
    n = np.fft.rfftfreq(n_points, dx_m)
    dn = n[1]
    psd = np.where(n >= 0.5, g0_m3 * (np.maximum(n, 1e-9) / 0.1) ** (-waviness), 0.0)
    coeff = (
        0.5 * np.sqrt(psd * dn) * (rng.standard_normal(n.size) + 1j * rng.standard_normal(n.size))
    )
    return np.fft.irfft(coeff * n_points, n_points)


def _joints(x, fam: TerrainFamily, rng) -> np.ndarray:
    """Rectangular joints (depth, width) at jittered spacing, plus a height step per unit."""
    z = np.zeros_like(x)
    if fam.joint_spacing_m <= 0:
        return z
    count = int((x[-1] - x[0]) / fam.joint_spacing_m) + 2
    steps = fam.joint_spacing_m * (1 + 0.03 * rng.standard_normal(count))
    edges = x[0] - rng.uniform(0, fam.joint_spacing_m) + np.cumsum(steps)
    unit = np.searchsorted(edges, x)
    z += fam.unit_step_m * rng.standard_normal(count + 1)[unit]
    nearest = np.minimum(np.abs(x - edges[np.clip(unit, 0, count - 1)]),
                         np.abs(x - edges[np.clip(unit - 1, 0, count - 1)]))  # fmt: skip
    depth = fam.joint_depth_m * (1 + 0.2 * rng.standard_normal(count))[np.clip(unit, 0, count - 1)]
    return z - np.where(nearest < fam.joint_width_m / 2, depth, 0.0)


def _periodic(x, period, height, wander, rng) -> np.ndarray:
    """A sinusoidal texture whose local wavelength wanders by ``±wander`` (fraction)."""
    if period <= 0:
        return np.zeros_like(x)
    dx = x[1] - x[0]
    slow = iso8608_roughness(x.size, dx, 1.0, 2.0, rng)
    slow = wander * slow / (np.std(slow) + 1e-30)
    phase = 2 * np.pi * np.cumsum(dx / (period * (1 + slow))) + rng.uniform(0, 2 * np.pi)
    return height * np.sin(phase)


def _bumps(x, fam: TerrainFamily, rng) -> np.ndarray:
    """Raised-cosine bumps at Poisson positions (tufts, stems, clods)."""
    z = np.zeros_like(x)
    if fam.bumps_per_m <= 0:
        return z
    count = rng.poisson(fam.bumps_per_m * (x[-1] - x[0]))
    dx = x[1] - x[0]
    half = max(int(fam.bump_width_m / dx / 2), 1)
    shape = 0.5 * (1 + np.cos(np.pi * np.arange(-half, half + 1) / half))
    centres = rng.integers(0, x.size, count)
    heights = rng.uniform(*fam.bump_height_m, count)
    for c, h in zip(centres, heights, strict=True):
        lo, hi = max(c - half, 0), min(c + half + 1, x.size)
        z[lo:hi] = np.maximum(z[lo:hi], h * shape[lo - c + half : hi - c + half])
    return z


def terrain_profile(
    fam: TerrainFamily, length_m: float, rng: np.random.Generator, *, dx_m: float = PROFILE_DX_M
) -> tuple[np.ndarray, np.ndarray]:
    """Two tracks (left, right) of one run's surface profile ``z(x)`` (m), shape ``(2, n)``.

    Joints are shared by both tracks (they run across the path); roughness and bumps are
    independent per track.

    Returns:
        ``(x, z)``: positions (m) and heights (m).
    """
    n = int(np.ceil(length_m / dx_m))
    x = np.arange(n) * dx_m
    shared = _joints(x, fam, rng) + _periodic(x, fam.ripple_m, fam.ripple_height_m, 0.15, rng)
    tracks = []
    for _ in range(2):
        z = iso8608_roughness(n, dx_m, fam.g0_m3, fam.waviness, rng)
        z = z + _periodic(x, fam.pile_period_m, fam.pile_height_m, 0.1, rng) + _bumps(x, fam, rng)
        tracks.append(shared + z)
    return x, np.stack(tracks)


def wheel_filter(
    z: np.ndarray, dx_m: float, *, radius_m: float = WHEEL_RADIUS_M, patch_m: float = 0.004
) -> np.ndarray:
    """Height of a rigid wheel's hub riding on ``z`` (m): upper envelope, then patch average.

    ``z_w(x) = max_{|s|≤R} [z(x+s) + √(R² − s²) − R]`` is where a rigid wheel of radius
    ``R`` rests; a box average over the contact patch models the tyre (or a wheel sunk into
    soft ground). Edges are padded with the end values. Works on the last axis.
    """
    z = np.asarray(z, dtype=float)
    k = int(radius_m / dx_m)
    s = np.arange(-k, k + 1) * dx_m
    lift = np.sqrt(np.maximum(radius_m**2 - s**2, 0.0)) - radius_m
    pad = np.pad(z, [(0, 0)] * (z.ndim - 1) + [(k, k)], mode="edge")
    n = z.shape[-1]
    env = np.full_like(z, -np.inf)
    for j in range(2 * k + 1):
        np.maximum(env, pad[..., j : j + n] + lift[j], out=env)
    return _box_average(env, max(round(patch_m / dx_m), 1))


def _box_average(z: np.ndarray, m: int) -> np.ndarray:
    """Centred moving average over ``m`` samples on the last axis (edges padded)."""
    if m <= 1:
        return z
    left = m // 2
    pad = np.pad(z, [(0, 0)] * (z.ndim - 1) + [(left + 1, m - left)], mode="edge")
    c = np.cumsum(pad, axis=-1)
    return (c[..., m:] - c[..., :-m])[..., : z.shape[-1]] / m


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


def amplified_hall(record: WhiskerRecord, amplifier: float = AMPLIFIER) -> HallSensor:
    """The record's Hall sensor behind an amplifier of gain ``amplifier`` (offset unchanged)."""
    return HallSensor(
        gain_v_per_m=record.hall.gain_v_per_m * amplifier,
        offset_v=record.hall.offset_v,
        quadratic_v_per_m2=record.hall.quadratic_v_per_m2 * amplifier,
    )


def _deflection(whisker: Whisker, grid_t, acc):
    """Relative deflection at the sensor (m), the whisker starting from rest at ``grid_t[0]``."""
    state = base_motion_response(whisker, grid_t, acc, uniform=True)
    return observe(whisker, state, "deflection")


@eqx.filter_jit
def hall_voltage(whisker: Whisker, hall: HallSensor, grid_t, acc):
    """Hall-sensor voltage of a whisker whose base moves with acceleration ``acc``.

    The exact modal model from rest, then the sensor: the signal at the ADS1115's input,
    before its averaging over a conversion. Compiled once per grid length: the whisker's and
    the sensor's parameters are traced, not baked in.

    Args:
        whisker: The whisker.
        hall: The Hall sensor (with its amplifier, see :func:`amplified_hall`).
        grid_t: Uniform time grid (s), e.g. from :func:`base_acceleration`.
        acc: Base acceleration on the grid (m/s²).

    Returns:
        Volts on the grid.
    """
    return hall.voltage(_deflection(whisker, grid_t, acc))


#: Column names of a two-sensor recording: sensor A reads the vertical plane, B the lateral.
PLANE_COLUMNS = ("hall_a", "hall_b")
_PLANE_KEYS = {"lateral_frequency_ratio", "lateral_zeta", "gain_ratio_b", "offset_b_v",
               "cross_talk"}  # fmt: skip


@dataclass(frozen=True)
class SensorPlanes:
    """The whisker's two bending planes and its two orthogonal Hall sensors.

    A record's optional ``[planes]`` table holds these (:meth:`from_record`); an
    axisymmetric coil without one has the same modes in both planes.

    Attributes:
        lateral_frequency_ratio: Natural frequencies in the lateral plane over those in the
            vertical one (a slightly flattened coil: a few per cent off 1); the lateral
            ``κ`` is the vertical one times its square.
        lateral_zeta: Modal damping in the lateral plane (one value or one per mode); the
            record's ``[damping] zeta`` when None.
        gain_ratio_b: Gain of sensor B (lateral) over sensor A's (the record's Hall gain).
        offset_b_v: Output of sensor B at rest (V); sensor A's when None.
        cross_talk: Fraction of the other plane's deflection each sensor reads (a sensor
            tilted by an angle θ off its plane reads ``sin θ`` of the other one).
    """

    lateral_frequency_ratio: float = 1.0
    lateral_zeta: float | tuple[float, ...] | None = None
    gain_ratio_b: float = 1.0
    offset_b_v: float | None = None
    cross_talk: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.lateral_frequency_ratio) and
                0.2 < self.lateral_frequency_ratio < 5):  # fmt: skip
            raise ValueError(
                f"planes.lateral_frequency_ratio = {self.lateral_frequency_ratio!r} must lie "
                "between 0.2 and 5"
            )
        if not (np.isfinite(self.gain_ratio_b) and self.gain_ratio_b != 0):
            raise ValueError(f"planes.gain_ratio_b = {self.gain_ratio_b!r} must be non-zero")
        if not (np.isfinite(self.cross_talk) and abs(self.cross_talk) < 0.5):
            raise ValueError(f"planes.cross_talk = {self.cross_talk!r} must lie within ±0.5")
        zetas = np.atleast_1d(np.asarray(
            0.0 if self.lateral_zeta is None else self.lateral_zeta, dtype=float))  # fmt: skip
        if not (np.isfinite(zetas).all() and (zetas >= 0).all() and (zetas < 1).all()):
            raise ValueError(
                f"planes.lateral_zeta = {self.lateral_zeta!r} must satisfy 0 <= zeta < 1"
            )

    @classmethod
    def from_record(cls, record: WhiskerRecord) -> "SensorPlanes":
        """The record's ``[planes]`` table (defaults where it has none).

        Raises:
            ValueError: Unknown keys or values out of range, named.
        """
        table = dict(record.extra.get("planes", {}))
        unknown = sorted(set(table) - _PLANE_KEYS)
        if unknown:
            raise ValueError(f"[planes]: unknown key(s) {unknown}; known: {sorted(_PLANE_KEYS)}")
        if isinstance(table.get("lateral_zeta"), list):
            table["lateral_zeta"] = tuple(float(z) for z in table["lateral_zeta"])
        return cls(**table)

    def to_table(self) -> dict:
        """The ``[planes]`` table (None values left out)."""
        out = {k: getattr(self, k) for k in sorted(_PLANE_KEYS) if getattr(self, k) is not None}
        if isinstance(out.get("lateral_zeta"), tuple):
            out["lateral_zeta"] = list(out["lateral_zeta"])
        return out

    def whiskers(self, record: WhiskerRecord) -> tuple[Whisker, Whisker]:
        """The vertical and lateral :class:`Whisker` of ``record``."""
        vertical = record.whisker()
        zeta = vertical.zeta if self.lateral_zeta is None else jnp.broadcast_to(
            jnp.asarray(self.lateral_zeta, dtype=float), vertical.zeta.shape)  # fmt: skip
        lateral = eqx.tree_at(lambda w: (w.EI, w.zeta), vertical,
                              (vertical.EI * self.lateral_frequency_ratio**2, zeta))  # fmt: skip
        return vertical, lateral

    def halls(self, record: WhiskerRecord, amplifier: float = AMPLIFIER) -> tuple[HallSensor, ...]:
        """Sensors A and B, amplifier included."""
        a = amplified_hall(record, amplifier)
        b = HallSensor(
            gain_v_per_m=a.gain_v_per_m * self.gain_ratio_b,
            offset_v=a.offset_v if self.offset_b_v is None else self.offset_b_v,
            quadratic_v_per_m2=a.quadratic_v_per_m2 * self.gain_ratio_b,
        )
        return a, b

    def mixing(self) -> np.ndarray:
        """What each sensor reads of each plane's deflection: rows A, B; columns vertical,
        lateral."""
        c = self.cross_talk
        return np.array([[1.0, c], [c, 1.0]])


@eqx.filter_jit
def _sensor_chain_planes(whiskers, halls, mix, grid_t, acc, t_samples, conv_time, n_avg: int):
    """Two sensors' voltages averaged over each conversion, for a batch of runs (vmapped).

    ``acc`` is ``(runs, 2, grid)``: vertical and lateral base acceleration.
    """

    def one(acc, t_samples, conv_time):
        w = jnp.stack([_deflection(wk, grid_t, a) for wk, a in zip(whiskers, acc, strict=True)])
        field = mix @ w
        offsets = -(jnp.arange(n_avg) + 0.5) / n_avg * conv_time
        tt = t_samples[:, None] + offsets[None, :]
        return jnp.stack([jnp.mean(h.voltage(jnp.interp(tt, grid_t, f)), axis=1)
                          for h, f in zip(halls, field, strict=True)])  # fmt: skip

    return jax.vmap(one)(acc, t_samples, conv_time)


@eqx.filter_jit
def _sensor_chain(whisker, hall, grid_t, acc, t_samples, conv_time, n_avg: int):
    """Hall voltage averaged over each conversion, for a batch of runs (vmapped)."""

    def one(acc, t_samples, conv_time):
        w = _deflection(whisker, grid_t, acc)
        offsets = -(jnp.arange(n_avg) + 0.5) / n_avg * conv_time
        tt = t_samples[:, None] + offsets[None, :]
        return jnp.mean(hall.voltage(jnp.interp(tt, grid_t, w)), axis=1)

    return jax.vmap(one)(acc, t_samples, conv_time)


@dataclass(frozen=True)
class RunSpec:
    """One synthetic recording to make: terrain, nominal speed and run number."""

    terrain: str
    speed_mps: float
    run: int


def _run_rng(seed: int, spec: RunSpec, *stream: int) -> np.random.Generator:
    return np.random.default_rng(
        [seed, TERRAINS.index(spec.terrain), round(spec.speed_mps * 1000), spec.run, *stream]
    )


def run_base_motion(
    spec: RunSpec, *, duration_s: float = 30.0, seed: int = 0, channels: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """The base acceleration :func:`synthesize_runs` drives one run's whisker with.

    Returns:
        ``(t, acc)`` on the internal grid (s, m/s²): ``acc`` of shape ``(n,)`` (vertical),
        or ``(2, n)`` (vertical, lateral) for ``channels = 2``.
    """
    return _run_motion(spec, duration_s, seed, channels)[:2]


def _run_motion(spec: RunSpec, duration_s: float, seed: int, channels: int):
    rng = _run_rng(seed, spec)
    if channels == 1:
        t, acc = base_acceleration(spec.terrain, spec.speed_mps, duration_s, rng)
    else:
        t, acc = base_acceleration_planes(spec.terrain, spec.speed_mps, duration_s, rng,
                                          _run_rng(seed, spec, 1))  # fmt: skip
    return t, acc, rng


def _check_runs(specs, duration_s, rate_hz, channels) -> None:
    for s in specs:
        if s.terrain not in TERRAIN_FAMILIES:
            raise ValueError(f"unknown terrain {s.terrain!r}; known: {', '.join(TERRAINS)}")
        if not 0 < s.speed_mps < 5:
            raise ValueError(f"speed {s.speed_mps!r} m/s is not plausible (0 < v < 5)")
    if not (np.isfinite(duration_s) and np.isfinite(rate_hz)) or duration_s * rate_hz < 2:
        raise ValueError(
            f"duration_s = {duration_s!r} and rate_hz = {rate_hz!r} must be numbers giving "
            "at least 2 samples"
        )
    if channels not in (1, 2):
        raise ValueError(f"channels must be 1 (one Hall sensor) or 2 (two), not {channels!r}")


def synthesize_runs(
    specs: list[RunSpec],
    *,
    record: WhiskerRecord | None = None,
    duration_s: float = 30.0,
    rate_hz: float = 200.0,
    seed: int = 0,
    jitter_s: float = 2e-4,
    noise_v_rms: float = 2.5e-4,
    amplifier: float = AMPLIFIER,
    batch: int = 24,
    channels: int = 1,
) -> list[Recording]:
    """Synthesise recordings (ADS1115 codes) of the given runs.

    Args:
        specs: What to synthesise.
        record: The whisker (the paper's by default).
        duration_s: Length of each recording (s).
        rate_hz: Host sampling rate (Hz).
        seed: Dataset seed; each run draws from ``default_rng([seed, terrain, speed, run])``.
        jitter_s: Timestamp jitter (s).
        noise_v_rms: ADC input noise (V RMS), about 2 LSB at ±4.096 V.
        amplifier: Gain of the sensor's amplifier (the paper's whisker has one) applied to
            the record's bare Hall gain; ×20 makes terrain vibration span tens to hundreds
            of codes around the offset.
        batch: Runs simulated per vmapped call (bounds memory).
        channels: 1: one Hall sensor in the vertical plane, column ``adc``; 2: the paper's
            two orthogonal sensors, columns ``hall_a`` (vertical) and ``hall_b`` (lateral),
            the record's ``[planes]`` table giving the lateral plane and sensor B
            (:class:`SensorPlanes`, :data:`LATERAL_MODEL`). Both channels are converted
            together (one two-channel sample per host tick). The vertical plane of a
            two-channel run is the one-channel run's.
    """
    return list(iter_runs(specs, record=record, duration_s=duration_s, rate_hz=rate_hz,
                          seed=seed, jitter_s=jitter_s, noise_v_rms=noise_v_rms,
                          amplifier=amplifier, batch=batch, channels=channels))  # fmt: skip


def iter_runs(
    specs: list[RunSpec],
    *,
    record: WhiskerRecord | None = None,
    duration_s: float = 30.0,
    rate_hz: float = 200.0,
    seed: int = 0,
    jitter_s: float = 2e-4,
    noise_v_rms: float = 2.5e-4,
    amplifier: float = AMPLIFIER,
    batch: int = 24,
    channels: int = 1,
):
    """:func:`synthesize_runs` one batch at a time: yields each recording as soon as its
    batch is simulated (memory bounded by ``batch`` runs, whatever the number of runs)."""
    record = paper_record() if record is None else record
    _check_runs(specs, duration_s, rate_hz, channels)
    planes = SensorPlanes.from_record(record) if channels == 2 else None
    for lo in range(0, len(specs), max(batch, 1)):
        chunk = specs[lo : lo + batch]
        rows = []
        for spec in chunk:
            t_grid, acc, rng = _run_motion(spec, duration_s, seed, channels)
            adc = replace(record.adc, jitter_s=jitter_s,
                          clock_error=float(rng.uniform(-0.05, 0.05)))  # fmt: skip
            rows.append((t_grid, acc, adc.sample_times(rate_hz, duration_s, rng=rng), adc, rng))
        volts = _chunk_volts(rows, record, amplifier, planes)
        for (_, _, ts, adc, rng), v, spec in zip(rows, volts, chunk, strict=True):
            noisy = v + noise_v_rms * rng.standard_normal(v.shape)
            codes = np.asarray(adc.quantise(noisy)).astype(np.int64)
            meta = {
                "terrain": spec.terrain,
                "speed_mps": f"{spec.speed_mps:g}",
                "rate_hz": f"{rate_hz:g}",
                "units": "code",
                "whisker": record.name,
                "amplifier": f"{amplifier:g}",
                "run": str(spec.run),
                "seed": str(seed),
                "source": _SOURCE,
            }
            if planes is None:
                columns = {"adc": codes}
            else:
                columns = dict(zip(PLANE_COLUMNS, codes, strict=True))
                meta["planes"] = "hall_a vertical, hall_b lateral"
            yield Recording(t=ts, columns=columns, meta=meta)


def _chunk_volts(rows, record, amplifier, planes) -> np.ndarray:
    """Sensor voltages of a batch of runs: ``(runs, samples)`` or ``(runs, 2, samples)``."""
    args = (
        jnp.asarray(rows[0][0]),
        jnp.asarray(np.stack([r[1] for r in rows])),
        jnp.asarray(np.stack([r[2] for r in rows])),
        jnp.asarray([r[3].conversion_time_s for r in rows]),
        record.adc.averaging_points,
    )
    if planes is None:
        return np.asarray(_sensor_chain(record.whisker(), amplified_hall(record, amplifier),
                                        *args))  # fmt: skip
    return np.asarray(_sensor_chain_planes(planes.whiskers(record),
                                           planes.halls(record, amplifier),
                                           jnp.asarray(planes.mixing()), *args))  # fmt: skip


def speed_tag(speed_mps: float) -> str:
    """A speed in file names: mm/s resolution (what seeds a run), two decimals when exact.

    ``0.2`` → ``"0.20"`` (the names of the default speeds), ``0.201`` → ``"0.201"``.
    """
    text = f"{round(speed_mps * 1000) / 1000:.3f}"
    return text[:-1] if text.endswith("0") else text


def dataset_paths(out: str | Path, specs: list[RunSpec]) -> list[Path]:
    """Where :func:`synthesize_dataset` writes each run.

    ``out/<terrain>/<terrain>_v<speed>_r<run>.csv``, the speed as :func:`speed_tag` writes it.
    """
    return [
        Path(out) / s.terrain / f"{s.terrain}_v{speed_tag(s.speed_mps)}_r{s.run:02d}.csv"
        for s in specs
    ]


def synthesize_dataset(
    out: str | Path,
    *,
    record: WhiskerRecord | None = None,
    terrains: tuple[str, ...] = TERRAINS,
    speeds: tuple[float, ...] = SPEEDS_MPS,
    runs: int = 4,
    duration_s: float = 30.0,
    seed: int = 0,
    replace_synthetic: bool = False,
    channels: int = 1,
) -> list[Path]:
    """Write a labelled dataset ``out/<terrain>/<terrain>_v<speed>_r<run>.csv`` as CSV recordings.

    Args:
        out: A new or empty folder (one holding CSV files is refused: old and new
            recordings would be mixed in one dataset).
        record: The whisker (the paper's by default).
        terrains: Terrains, each once.
        speeds: Nominal speeds (m/s), distinct to 1 mm/s.
        runs: Runs per terrain and speed.
        duration_s: Length of each recording (s), at least ``MIN_DATASET_DURATION_S``.
        seed: Dataset seed.
        replace_synthetic: Replace the simulator's own recordings at the very paths this
            call writes (for re-running the demo); any other CSV under ``out`` is still
            refused.
        channels: Hall sensors: 1 (column ``adc``) or 2 (``hall_a``, ``hall_b``; see
            :func:`synthesize_runs`).

    Each recording is written as soon as its batch of runs is simulated, so memory does
    not grow with the number of runs; they are written beside ``out``'s recordings and
    moved in together at the end, so a full disk or an interruption leaves none of them.

    Returns:
        The CSV paths, in terrain, speed, run order.

    Raises:
        ValueError: Repeated terrains or speeds, a duration that is not a number or too
            short, or an ``out`` that is a file or already holds recordings.
    """
    if runs < 1:
        raise ValueError("runs must be at least 1")
    _check_dataset_args(terrains, speeds, duration_s)
    specs = [RunSpec(t, float(v), r) for t in terrains for v in speeds for r in range(runs)]
    paths = dataset_paths(out, specs)
    _check_dataset_folder(Path(out), paths if replace_synthetic else [])
    recs = iter_runs(specs, record=record, duration_s=duration_s, seed=seed, channels=channels)
    out = Path(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    # All or nothing: the recordings are written into a hidden folder beside their places
    # and moved in (renames, which need no space) only when every one is whole.
    stage = Path(tempfile.mkdtemp(prefix=".synth-", suffix=".tmp", dir=out))
    try:
        staged = [write_csv(stage / p.relative_to(out), rec)
                  for p, rec in zip(paths, recs, strict=True)]  # fmt: skip
        for src, dst in zip(staged, paths, strict=True):
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(src, dst)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()
        raise
    shutil.rmtree(stage, ignore_errors=True)
    return paths


def _check_dataset_args(terrains, speeds, duration_s) -> None:
    twice = sorted({t for t in terrains if list(terrains).count(t) > 1})
    if twice:
        raise ValueError(f"terrain(s) {', '.join(twice)} given more than once; name each once")
    tags: dict[str, float] = {}
    for v in speeds:
        if not np.isfinite(v):
            raise ValueError(f"speed {v!r} m/s is not a number")
        tag = speed_tag(v)
        if tag in tags:
            raise ValueError(
                f"speeds {tags[tag]:g} and {v:g} m/s are the same to 1 mm/s (they would make "
                "the same recordings under one file name); give distinct speeds"
            )
        tags[tag] = v
    if not (np.isfinite(duration_s) and duration_s >= MIN_DATASET_DURATION_S):
        raise ValueError(
            f"duration {duration_s!r} s: each recording must last at least "
            f"{MIN_DATASET_DURATION_S:g} s (a classifier window is 1 s)"
        )


def _check_dataset_folder(out: Path, replaceable: list[Path]) -> None:
    """Refuse a file, or a folder already holding recordings (but ``replaceable`` ones)."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file; give a new or empty folder")
    if not out.exists():
        return
    stray = sorted(p.name for p in out.iterdir() if p.is_file() and not p.name.startswith("."))
    if stray:  # a model folder (model.json), a recording's folder: not a dataset's
        raise ValueError(
            f"{out} holds files of its own (e.g. {stray[0]}), not a dataset's "
            "<terrain>/ folders; give a new or empty folder (even with --force)"
        )
    own = {p for p in replaceable if p.exists() and _is_synthetic(p)}
    found = sorted(p for p in out.rglob("*.csv") if p not in own)
    if found:
        raise ValueError(
            f"{out} already holds {len(found)} recording(s) (e.g. {found[0]}); pass a new or "
            "empty folder: the old recordings would be mixed with the new ones"
        )


def _is_synthetic(path: Path) -> bool:
    """Whether a CSV's metadata says this simulator wrote it."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if not line.startswith("#"):
                return False
            if line.strip() == f"# source: {_SOURCE}":
                return True
    return False
