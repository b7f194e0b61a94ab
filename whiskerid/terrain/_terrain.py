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
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from ..io import Recording, read_recording, write_csv
from ..model import (
    WhiskerRecord,
    paper_record,
)
from ._contact_runs import DEFAULT_PRELOAD_M, iter_contact_runs
from ._motion import base_acceleration, base_acceleration_planes
from ._profile import TERRAINS
from ._runs import _CONTACT_SOURCE, _SOURCE, RunSpec, _check_runs, _run_rng
from ._sensor import (
    AMPLIFIER,
    PLANE_COLUMNS,
    SensorPlanes,
    _sensor_chain,
    _sensor_chain_planes,
    amplified_hall,
)

SPEEDS_MPS = (0.10, 0.15, 0.20, 0.25, 0.30)
MIN_DATASET_DURATION_S = 2.0  # shortest recording synthesize_dataset makes: a window is 1 s


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
    contact: bool = False,
    preload_m: float | None = None,
    progress: bool = False,
    resume: bool = False,
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
        contact: The whisker's tip on the ground (:func:`iter_contact_runs`: unilateral
            contact with friction, one Hall sensor) instead of the base motion alone.
        preload_m: With ``contact``: the nominal preload (m); the default otherwise.
        progress: A progress bar on stderr, one step per recording written.
        resume: Keep the recordings an interrupted call with the same settings finished
            (the simulator's own, same seed, whisker and length) and simulate only the rest;
            each recording depends on its terrain, speed, run and the seed alone, so the
            dataset is the one an uninterrupted call writes.

    Each recording is written as soon as its batch of runs is simulated, so memory does
    not grow with the number of runs; they are written beside ``out``'s recordings and
    moved in together at the end, so a full disk leaves none of them. An interruption
    (Ctrl-C, SIGTERM: a ``KeyboardInterrupt``) moves in the recordings already whole, for
    ``resume``.

    Returns:
        The CSV paths, in terrain, speed, run order.

    Raises:
        ValueError: Repeated terrains or speeds, a duration that is not a number or too
            short, or an ``out`` that is a file or already holds recordings.
    """
    if runs < 1:
        raise ValueError("runs must be at least 1")
    if contact and channels != 1:
        raise ValueError("the contact simulator has one Hall sensor (the vertical plane): "
                         "use channels = 1 with contact")  # fmt: skip
    _check_dataset_args(terrains, speeds, duration_s)
    specs = [RunSpec(t, float(v), r) for t in terrains for v in speeds for r in range(runs)]
    paths = dataset_paths(out, specs)
    _check_dataset_folder(Path(out), paths if replace_synthetic or resume else [])
    all_paths = paths
    if resume:
        name = (record or paper_record()).name
        done = {p for p in paths if p.exists() and _finished(p, seed, name, duration_s)}
        specs = [sp for sp, p in zip(specs, paths, strict=True) if p not in done]
        paths = [p for p in paths if p not in done]
    if contact:
        preload = DEFAULT_PRELOAD_M if preload_m is None else preload_m
        recs = iter_contact_runs(specs, record=record, duration_s=duration_s, seed=seed,
                                 preload_m=preload)  # fmt: skip
    else:
        recs = iter_runs(specs, record=record, duration_s=duration_s, seed=seed,
                         channels=channels)  # fmt: skip
    if progress:
        recs = tqdm(recs, total=len(specs), desc="dataset synth", unit="run", file=sys.stderr,
                    leave=False)  # fmt: skip
    out = Path(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    # All or nothing: the recordings are written into a hidden folder beside their places
    # and moved in (renames, which need no space) only when every one is whole.
    stage = Path(tempfile.mkdtemp(prefix=".synth-", suffix=".tmp", dir=out))
    staged: list[tuple[Path, Path]] = []
    try:
        for p, rec in zip(paths, recs, strict=True):
            staged.append((write_csv(stage / p.relative_to(out), rec), p))
        _move_in(staged)
    except KeyboardInterrupt:  # keep the recordings written whole, for resume
        _move_in(staged)
        shutil.rmtree(stage, ignore_errors=True)
        raise
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()
        raise
    shutil.rmtree(stage, ignore_errors=True)
    return all_paths


def _move_in(staged: list[tuple[Path, Path]]) -> None:
    for src, dst in staged:
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src, dst)


def _finished(path: Path, seed: int, whisker: str, duration_s: float) -> bool:
    """Whether ``path`` is a recording this simulator finished with these settings."""
    if not _is_synthetic(path):
        return False
    try:
        rec = read_recording(path)
        rate = float(rec.meta["rate_hz"])
    except (OSError, ValueError, KeyError):
        return False
    same = rec.meta.get("seed") == str(seed) and rec.meta.get("whisker") == whisker
    return same and abs(rec.t.size / rate - duration_s) < 1.5 / rate


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
            if line.strip() in (f"# source: {_SOURCE}", f"# source: {_CONTACT_SOURCE}"):
                return True
    return False
