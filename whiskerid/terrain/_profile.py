"""Terrain profiles and the wheel that rides on them (stages 1 and 2 of the simulator).

The terrain families (``TERRAIN_FAMILIES``, documented in :mod:`whiskerid.terrain`'s
simulator overview), their run-to-run variation, the ISO 8608 roughness, the periodic
textures and bumps, and the rigid wheel with its contact patch that low-passes them.
"""

from dataclasses import dataclass, replace

import numpy as np

WHEEL_RADIUS_M = 0.035
WHEELBASE_M = 0.17
PROFILE_DX_M = 5e-4


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
