"""Run specifications and their random streams, shared by the linear and the contact
simulators (:mod:`._terrain` and :mod:`._contact_runs` both import from here, so that
neither imports the other's internals)."""

from dataclasses import dataclass

import numpy as np

from ._profile import TERRAIN_FAMILIES, TERRAINS

_SOURCE = "whiskerid terrain simulator"  # metadata that marks the simulator's recordings
_CONTACT_SOURCE = "whiskerid contact simulator"  # the same, with the tip on the ground


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
