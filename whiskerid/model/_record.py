"""Whisker records: TOML files in ``fits/`` that describe one physical whisker.

A record holds the structure (coil spring or uniform beam: geometry and material), the
modal damping, an optional tip mass, the sensor (position, Hall gain and offset) and the
ADS1115 settings. Later stages (calibration, posteriors) add their own tables; tables this
module does not know are kept verbatim, so loading and saving never loses them.

Example (``fits/paper-whisker.toml``)::

    schema = "whiskerid.whisker/1"
    name = "paper-whisker"

    [structure]
    kind = "coil"
    length_m = 0.06
    wire_radius_m = 0.0005
    mean_coil_radius_m = 0.0045
    n_coils = 13
    wire_density_kg_m3 = 8050.0
    shear_modulus_pa = 70000000000.0

    [damping]
    zeta = 0.04        # or one value per mode: [0.04, 0.03, ...]
    n_modes = 5

    [sensor]
    position_m = 0.005
    ...
"""

import difflib
import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ..io import atomic_write
from ._sensor import ADS1115Model, HallSensor
from ._whisker import CoilSpring, Structure, UniformBeam, Whisker, whisker_from_structure

SCHEMA = "whiskerid.whisker/1"


class RecordError(ValueError):
    """A whisker record that is missing a value, holds a non-physical one, or cannot load."""


@dataclass(frozen=True)
class WhiskerRecord:
    """Everything known about one whisker (the contents of a ``fits/*.toml`` file).

    Attributes:
        name: Short identifier.
        structure: :class:`CoilSpring` or :class:`UniformBeam`.
        zeta: Modal damping, one value or one per mode.
        n_modes: Number of modes used by the models.
        tip_mass_kg: Point mass at the tip (kg).
        sensor_position_m: Sensor position from the clamp (m).
        hall: Hall-sensor parameters.
        adc: ADS1115 settings.
        description: Free text.
        extra: Other top-level tables (fits, posteriors, provenance), kept as loaded.
    """

    name: str
    structure: Structure
    zeta: float | tuple[float, ...] = 0.04
    n_modes: int = 5
    tip_mass_kg: float = 0.0
    sensor_position_m: float = 0.005
    hall: HallSensor = field(default_factory=HallSensor)
    adc: ADS1115Model = field(default_factory=ADS1115Model)
    description: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        _check_record(self)

    def whisker(self) -> Whisker:
        """The :class:`Whisker` pytree the models take."""
        return whisker_from_structure(
            self.structure,
            zeta=np.asarray(self.zeta, dtype=float),
            n_modes=self.n_modes,
            tip_mass_kg=self.tip_mass_kg,
            sensor_x_m=self.sensor_position_m,
        )

    def to_toml(self) -> str:
        """TOML text of this record."""
        return tomli_w.dumps(self.to_dict())

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (what is written to TOML)."""
        structure = {"kind": self.structure.kind}
        for f in fields(self.structure):
            value = getattr(self.structure, f.name)
            if f.name != "kind" and value is not None:
                structure[f.name] = value
        zeta = list(self.zeta) if isinstance(self.zeta, tuple) else self.zeta
        out: dict[str, Any] = {"schema": SCHEMA, "name": self.name}
        if self.description:
            out["description"] = self.description
        out["structure"] = structure
        out["damping"] = {"zeta": zeta, "n_modes": self.n_modes}
        out["tip_mass_kg"] = self.tip_mass_kg
        out["sensor"] = {
            "position_m": self.sensor_position_m,
            "hall_gain_v_per_m": float(self.hall.gain_v_per_m),
            "hall_offset_v": float(self.hall.offset_v),
            "hall_quadratic_v_per_m2": float(self.hall.quadratic_v_per_m2),
        }
        out["adc"] = {f.name: getattr(self.adc, f.name) for f in fields(self.adc)}
        # Scalars first: TOML cannot put a key after a table at the same level.
        out = dict(sorted(out.items(), key=lambda kv: isinstance(kv[1], dict)))
        for key, value in self.extra.items():
            out[key] = value
        return out

    def save(self, path: str | Path) -> Path:
        """Write the record as TOML (parent folders are created), whole or not at all."""
        return atomic_write(Path(path), self.to_toml())

    def replace(self, **changes) -> "WhiskerRecord":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


_KNOWN = {"schema", "name", "description", "structure", "damping", "tip_mass_kg", "sensor", "adc"}
_DAMPING = {"zeta", "n_modes"}
_SENSOR = {"position_m", "hall_gain_v_per_m", "hall_offset_v", "hall_quadratic_v_per_m2"}


def _check_keys(table: dict, known, where: str) -> None:
    """Refuse a key this record does not know, naming the nearest known one: a misspelt
    key (``tip_mas_kg``) would otherwise leave its default in place without a word."""
    unknown = sorted(set(table) - set(known))
    if unknown:
        key = unknown[0]
        near = difflib.get_close_matches(key, sorted(known), n=1, cutoff=0.5)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        raise RecordError(
            f"{where}{key} is not a known key{hint} (known: {', '.join(sorted(known))})"
        )


def _check_finite(value, where: str) -> None:
    """Refuse a NaN or infinite number in the tables later stages add (the record's own
    values have their ranges checked): it would be copied into every record made from
    this one. An uncertainty
    (``std``) may be NaN: a fit whose covariance could not be estimated says so that way."""
    if isinstance(value, dict):
        for k, v in value.items():
            if k != "std":
                _check_finite(v, f"{where}.{k}" if where else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_finite(v, f"{where}[{i}]")
    elif isinstance(value, float) and not math.isfinite(value):
        raise RecordError(
            f"{where} = {value} is not a number: mend the record, or make it again "
            "(whiskerid calibrate)"
        )


def _check_top_level(data: dict) -> None:
    """Top-level scalars must be known ones; tables other stages add (``[fit]``,
    ``[posterior]``, ``[planes]``) are kept, unless the name is a near-miss of a known one
    (``[sensr]``)."""
    scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
    _check_keys(scalars, _KNOWN - {"structure", "damping", "sensor", "adc"}, "")
    for key in set(data) - _KNOWN - set(scalars):
        near = difflib.get_close_matches(key, sorted(_KNOWN), n=1, cutoff=0.8)
        if near:
            raise RecordError(f"[{key}] is not a known table; did you mean [{near[0]}]?")


def load_record(path: str | Path) -> WhiskerRecord:
    """Load and validate a whisker record.

    Raises:
        RecordError: The file is missing or not TOML, or a value is missing or non-physical
            (the message names the field).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise RecordError(f"{path}: no such whisker record") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise RecordError(f"{path}: not a valid TOML file ({err})") from None
    try:
        return record_from_dict(data)
    except RecordError as err:
        raise RecordError(f"{path}: {err}") from None


def record_from_dict(data: dict[str, Any]) -> WhiskerRecord:
    """Build a :class:`WhiskerRecord` from parsed TOML."""
    schema = data.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise RecordError(f"schema = {schema!r} is not supported (expected {SCHEMA!r})")
    _check_top_level(data)
    _check_finite({k: v for k, v in data.items() if k not in _KNOWN}, "")  # own ranges below
    structure = _structure(_table(data, "structure"))
    damping = _table(data, "damping")
    _check_keys(damping, _DAMPING, "damping.")
    # Only a Hall sensor needs its [sensor] gain and offset; without the table (an
    # accelerometer, a laser) the signal is read at the tip and the Hall values are unused.
    sensor = data.get("sensor", {"position_m": structure.length_m})
    if not isinstance(sensor, dict):
        raise RecordError("[sensor] must be a table")
    _check_keys(sensor, _SENSOR, "sensor.")
    if isinstance(data.get("adc"), dict):
        _check_keys(data["adc"], {f.name for f in fields(ADS1115Model)}, "adc.")
    zeta = _get(damping, "zeta", "damping")
    zeta = tuple(float(z) for z in zeta) if isinstance(zeta, list) else zeta
    n_modes = len(zeta) if isinstance(zeta, tuple) else damping.get("n_modes", 5)
    if isinstance(zeta, tuple) and damping.get("n_modes", n_modes) != n_modes:
        raise RecordError(
            f"damping.zeta lists {n_modes} modes but damping.n_modes = "
            f"{damping['n_modes']!r}: give one zeta per mode, or one zeta for all"
        )
    hall_keys = {
        "hall_gain_v_per_m": "gain_v_per_m",
        "hall_offset_v": "offset_v",
        "hall_quadratic_v_per_m2": "quadratic_v_per_m2",
    }
    try:
        hall = HallSensor(**{v: sensor[k] for k, v in hall_keys.items() if k in sensor})
        adc = ADS1115Model(**data.get("adc", {}))
    except (TypeError, ValueError) as err:
        raise RecordError(f"[sensor]/[adc]: {err}") from None
    return WhiskerRecord(
        name=str(data.get("name", "whisker")),
        description=str(data.get("description", "")),
        structure=structure,
        zeta=zeta,
        n_modes=n_modes,
        tip_mass_kg=data.get("tip_mass_kg", 0.0),
        sensor_position_m=_get(sensor, "position_m", "sensor"),
        hall=hall,
        adc=adc,
        extra={k: v for k, v in data.items() if k not in _KNOWN},
    )


def _table(data: dict, name: str) -> dict:
    table = data.get(name)
    if not isinstance(table, dict):
        raise RecordError(f"the [{name}] table is missing")
    return table


def _get(table: dict, key: str, where: str):
    if key not in table:
        raise RecordError(f"{where}.{key} is missing")
    return table[key]


def _structure(table: dict) -> Structure:
    kind = table.get("kind")
    classes = {"coil": CoilSpring, "beam": UniformBeam}
    if kind not in classes:
        raise RecordError(f"structure.kind = {kind!r} must be 'coil' or 'beam'")
    cls = classes[kind]
    names = {f.name for f in fields(cls)} - {"kind"}
    unknown = set(table) - names - {"kind"}
    if unknown:
        near = difflib.get_close_matches(min(unknown), sorted(names), n=1, cutoff=0.5)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise RecordError(
            f"structure: unknown field(s) {sorted(unknown)} for kind {kind!r}{hint}; "
            f"known: {sorted(names)}"
        )
    for key, value in table.items():  # before the classes' own checks: say the range
        if f"structure.{key}" in RANGES and isinstance(value, int | float):
            _check_range(f"structure.{key}", value)
    try:
        return cls(**{k: v for k, v in table.items() if k != "kind"})
    except TypeError as err:  # a required field is absent, or a value is not a number
        missing = sorted(n for n in names if n not in table)
        if not missing:
            raise RecordError(f"structure: {err}") from None
        raise RecordError(f"structure: missing field(s) {missing} ({err})") from None
    except ValueError as err:
        raise RecordError(f"structure.{err}") from None


#: Plausible ranges (inclusive, SI) of a record's numbers: a value outside is a typing or
#: unit slip (1e9 m for 1 m, kg for g), and a model built on it answers without meaning.
RANGES = {
    "structure.length_m": (1e-4, 10.0, "m"),
    "structure.wire_radius_m": (1e-6, 0.1, "m"),
    "structure.mean_coil_radius_m": (1e-5, 1.0, "m"),
    "structure.n_coils": (0.5, 1e4, ""),
    "structure.wire_density_kg_m3": (100.0, 25e3, "kg/m^3"),
    "structure.shear_modulus_pa": (1e5, 1e12, "Pa"),
    "structure.youngs_modulus_pa": (1e5, 1.5e12, "Pa"),
    "structure.density_kg_m3": (100.0, 25e3, "kg/m^3"),
    "structure.width_m": (1e-6, 1.0, "m"),
    "structure.thickness_m": (1e-6, 1.0, "m"),
    "structure.diameter_m": (1e-6, 1.0, "m"),
    "tip_mass_kg": (0.0, 100.0, "kg"),
    "sensor.hall_gain_v_per_m": (-1e9, 1e9, "V/m"),
    "sensor.hall_offset_v": (-1e3, 1e3, "V"),
    "sensor.hall_quadratic_v_per_m2": (-1e15, 1e15, "V/m^2"),
}


def _check_range(key: str, value) -> None:
    lo, hi, unit = RANGES[key]
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not (ok and math.isfinite(value) and lo <= value <= hi):
        raise RecordError(
            f"{key} = {value!r} is outside the plausible range {lo:g} .. {hi:g}"
            + (f" {unit}" if unit else "")
            + " (a finite number): check the value and its unit"
        )


def _check_ranges(rec: WhiskerRecord) -> None:
    """Refuse absurd numbers, naming the key and the range allowed."""
    st = rec.structure
    for f in fields(st):
        key = f"structure.{f.name}"
        value = getattr(st, f.name)
        if key in RANGES and value is not None:
            _check_range(key, value)
    if isinstance(st, CoilSpring) and st.wire_radius_m >= st.mean_coil_radius_m:
        raise RecordError(
            f"structure.wire_radius_m = {st.wire_radius_m!r} must be smaller than "
            f"structure.mean_coil_radius_m = {st.mean_coil_radius_m!r} (a wire thicker "
            "than its coil cannot be wound)"
        )
    _check_range("tip_mass_kg", rec.tip_mass_kg)
    for name in ("gain_v_per_m", "offset_v", "quadratic_v_per_m2"):
        _check_range(f"sensor.hall_{name}", float(getattr(rec.hall, name)))
    gain = float(rec.hall.gain_v_per_m)
    if abs(gain) < 1e-3:  # volts are divided by it: a zero gain reads no deflection at all
        raise RecordError(
            f"sensor.hall_gain_v_per_m = {gain!r}: a Hall sensor's gain must not be 0 (below "
            "1e-3 V/m in size it reads no deflection); give the sensor's V/m"
        )


def _check_record(rec: WhiskerRecord) -> None:
    _check_ranges(rec)
    zetas = rec.zeta if isinstance(rec.zeta, tuple) else (rec.zeta,)
    if not all(isinstance(z, int | float) and math.isfinite(z) and 0 <= z < 1 for z in zetas):
        raise RecordError(f"damping.zeta = {rec.zeta!r} must satisfy 0 <= zeta < 1")
    if not isinstance(rec.n_modes, int) or not 1 <= rec.n_modes <= 40:
        raise RecordError(f"damping.n_modes = {rec.n_modes!r} must be an integer from 1 to 40")
    if not isinstance(rec.tip_mass_kg, int | float) or not 0 <= rec.tip_mass_kg < math.inf:
        raise RecordError(f"tip_mass_kg = {rec.tip_mass_kg!r} must be zero or positive")
    x = rec.sensor_position_m
    if not isinstance(x, int | float) or not 0 <= x <= rec.structure.length_m:
        raise RecordError(
            f"sensor.position_m = {x!r} must lie on the beam, between 0 and "
            f"structure.length_m = {rec.structure.length_m} m"
        )


def paper_record() -> WhiskerRecord:
    """The paper's whisker as a record (its Section III); ``fits/paper-whisker.toml`` holds it."""
    from ._whisker import paper_coil

    return WhiskerRecord(
        name="paper-whisker",
        description=(
            "Coil-spring whisker of Yu et al. (Section III): 60 mm, wire 1 mm, OD/ID 10/8 mm, "
            "13 coils, steel; Hall sensor 5 mm from the base. Hall gain/offset and ADC settings "
            "are nominal values, not from the paper."
        ),
        structure=paper_coil(),
        zeta=0.04,
        n_modes=5,
        sensor_position_m=0.005,
    )
