"""A simulated fleet on disk, with known damage: to try fleet calibration and change detection.

Every whisker is a coil spring of its own (length, wire and coil radius, number of coils,
sensor position, damping ζ scattered around the paper whisker's), and its record
(``whisker.toml``) is what its maker would write: the nominal material and ζ, not the truth.
Each session moves the truth a little (the mount, the temperature: f_1 by ``day_f1`` and ζ by
``day_zeta``, relative standard deviations), and each pluck is a hand-made pluck
(:func:`whiskerid.model.simulate_pluck`: held, flicked or tapped, every mode, the Hall sensor
and the ADS1115's averaging and quantisation, white noise) in a file of its own. A damaged
whisker changes from a random session after the baseline on: ζ × 1.5 or f_1 × 0.97.
"""

from dataclasses import dataclass, replace
from pathlib import Path

import jax
import numpy as np

from ..io import write_csv
from ..model import CoilSpring, paper_record, simulate_pluck


@dataclass
class FleetTruth:
    """What :func:`simulate_fleet` made.

    Attributes:
        sessions: One dict per whisker and session: ``whisker``, ``session``, ``f1_hz``,
            ``zeta`` (the truth of that session), ``damaged`` (from this session on).
        damage: Whisker → ``(first damaged session, "zeta" or "f1")`` for damaged whiskers.
    """

    sessions: list[dict]
    damage: dict[str, tuple[str, str]]


def simulate_fleet(
    root: str | Path,
    *,
    whiskers: int = 3,
    sessions: int = 3,
    plucks: int = 2,
    damaged: int = 0,
    baseline: int = 3,
    kinds: tuple[str, ...] = ("held", "flick", "tap"),
    rate_hz: float = 860.0,
    duration_s: float = 0.74,
    noise_db: float = 35.0,
    day_f1: float = 0.002,
    day_zeta: float = 0.05,
    seed: int = 0,
) -> FleetTruth:
    """Write ``ROOT/whisker-NNN/session-NN/pluck-N.csv`` and each whisker's record.

    Args:
        root: Folder to write into (created).
        whiskers: Number of whiskers.
        sessions: Sessions per whisker.
        plucks: Plucks per session (one file each).
        damaged: Number of whiskers damaged (ζ × 1.5 or f_1 × 0.97, alternately) from a
            random session after the first ``baseline`` on.
        baseline: Sessions before which no damage starts.
        kinds: Pluck kinds drawn from (see :func:`whiskerid.model.simulate_pluck`).
        rate_hz: Sampling rate (Hz).
        duration_s: Length of each recording (s); the release comes 0.15–0.3 s in.
        noise_db: SNR of the white noise (dB).
        day_f1: Relative standard deviation of f_1 from one session to the next.
        day_zeta: Relative standard deviation of ζ from one session to the next.
        seed: Seed of everything drawn.

    Returns:
        The truth (:class:`FleetTruth`).
    """
    root = Path(root)
    rng = np.random.default_rng(seed)
    base = paper_record()
    base = base.replace(adc=replace(base.adc, data_rate_sps=860 if rate_hz > 475 else 475))
    hit = set(rng.choice(whiskers, size=min(damaged, whiskers), replace=False).tolist())
    out, damage = [], {}
    for w in range(whiskers):
        name = f"whisker-{w:03d}"
        coil = CoilSpring(
            length_m=rng.uniform(0.050, 0.070),
            wire_radius_m=rng.uniform(0.45e-3, 0.55e-3),
            mean_coil_radius_m=rng.uniform(4.0e-3, 5.0e-3),
            n_coils=int(rng.integers(11, 16)),
            wire_density_kg_m3=8050.0,
            shear_modulus_pa=70e9,
        )
        nominal = base.replace(
            name=name, structure=coil, sensor_position_m=rng.uniform(0.06, 0.12) * coil.length_m
        )
        nominal.save(root / name / "whisker.toml")
        # the whisker as made: its material and damping off the nominal
        g_true = 70e9 * rng.normal(1.0, 0.05)
        zeta_true = 0.04 * float(np.exp(rng.normal(0.0, 0.25)))
        first = int(rng.integers(min(baseline, sessions - 1), sessions)) if w in hit else None
        kind = ("zeta", "f1")[len(damage) % 2] if w in hit else None
        if first is not None:
            damage[name] = (f"session-{first:02d}", kind)
        for s in range(sessions):
            g = g_true * rng.normal(1.0, day_f1) ** 2
            zeta = zeta_true * float(np.exp(rng.normal(0.0, day_zeta)))
            hurt = first is not None and s >= first
            if hurt and kind == "zeta":
                zeta *= 1.5
            if hurt and kind == "f1":
                g *= 0.97**2
            rec = nominal.replace(structure=replace(coil, shear_modulus_pa=g), zeta=zeta)
            folder = root / name / f"session-{s:02d}"
            for k in range(plucks):
                with jax.disable_jit():  # the same numbers, without a compile per pluck
                    r, _ = simulate_pluck(
                        rec,
                        kind=str(rng.choice(kinds)),
                        observable="adc",
                        rate_hz=rate_hz,
                        duration_s=duration_s,
                        release_s=float(rng.uniform(0.15, 0.3)),
                        hold_s=0.1,
                        tip_deflection_m=float(rng.uniform(1.5e-3, 2.5e-3)),
                        noise_db=noise_db,
                        seed=int(rng.integers(2**31)),
                    )
                write_csv(folder / f"pluck-{k + 1}.csv", r)
            f1 = float(rec.whisker().natural_frequencies_hz[0])
            out.append({"whisker": name, "session": f"session-{s:02d}", "f1_hz": f1,
                        "zeta": zeta, "damaged": hurt})  # fmt: skip
    return FleetTruth(out, damage)
