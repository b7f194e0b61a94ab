"""What a calibration fits: recordings (:class:`Observation`), static tests, and the reading
of both from files (:func:`observation_from_recording`, :func:`read_static_test`)."""

from dataclasses import dataclass
from dataclasses import replace as _replace
from pathlib import Path

import numpy as np

from ..._choices import EXCITATIONS, OBSERVABLES
from ...io import (
    Recording,
    RecordingError,
    check_samples,
    read_csv_table,
    read_recording,
    recording_rate,
    timestamp_rate,
)
from ...model import WhiskerRecord
from .._numerics import compile_cache
from ._noise_floor import quiet_stretch
from ._release import find_decays, steady_line

G0 = 9.80665  # m/s² per g


class CalibrationError(ValueError):
    """Input that cannot be calibrated (message says what)."""


# --------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class Observation:
    """One recording prepared for calibration.

    Attributes:
        t: Sample times (s), increasing, uniform or not.
        y: Samples in the observable's units (m, m/s², V or ADS1115 codes).
        excitation: ``decay`` (pluck or tap, free vibration), ``sine`` (base excitation at
            ``fb_hz``) or ``base`` (measured base acceleration ``base_acc`` at ``t``).
        observable: ``deflection`` (relative, m), ``acceleration`` (absolute, m/s²),
            ``voltage`` (Hall output, V) or ``adc`` (codes, averaged over the conversion).
        x_m: Where the signal is read, from the clamp (m); the record's sensor by default.
        fb_hz: Sine frequency (Hz), for ``sine``.
        hb_m: Sine amplitude (m); None when unknown (then only gain·h_b is fitted).
        base_acc: Base acceleration at ``t`` (m/s²), for ``base``.
        gain: Observed units per unit of the physical observable (1 for deflection and
            acceleration; V/m for voltage; codes/m for adc); None to fit it (as a product
            with the excitation amplitude).
        name: Label used in reports.
        source: File it came from (hashed into the record), if any.
        selection: How the samples were chosen (for reports), e.g. where a decay was found.
        quiet: Samples of a quiet stretch of the same recording (the hold before the release,
            or the rest after the decay), in the units of ``y``: the noise floor the fit's
            residuals are compared with (``whiskerid.fit._noise_floor``); None when unknown.
    """

    t: np.ndarray
    y: np.ndarray
    excitation: str = "decay"
    observable: str = "deflection"
    x_m: float | None = None
    fb_hz: float | None = None
    hb_m: float | None = None
    base_acc: np.ndarray | None = None
    gain: float | None = 1.0
    name: str = "recording"
    source: str | None = None
    selection: str | None = None
    quiet: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "t", np.asarray(self.t, dtype=float))
        object.__setattr__(self, "y", np.asarray(self.y, dtype=float))
        check_samples(self.t, self.y, where=self.name, min_samples=16)
        if self.excitation not in EXCITATIONS:
            raise CalibrationError(
                f"excitation must be one of {EXCITATIONS}, not {self.excitation!r}"
            )
        if self.observable not in OBSERVABLES:
            raise CalibrationError(
                f"observable must be one of {OBSERVABLES}, not {self.observable!r}"
            )
        if self.excitation == "sine" and not (self.fb_hz and self.fb_hz > 0):
            raise CalibrationError(f"{self.name}: a sine excitation needs its frequency (--fb)")
        if self.excitation == "base":
            if self.base_acc is None:
                raise CalibrationError(
                    f"{self.name}: a base excitation needs the base acceleration"
                )
            acc = np.asarray(self.base_acc, dtype=float)
            check_samples(self.t, acc, where=f"{self.name} (base acceleration)", min_samples=16)
            object.__setattr__(self, "base_acc", acc)

    def window(self, t_start: float | None = None, t_end: float | None = None) -> "Observation":
        """The samples with ``t_start ≤ t ≤ t_end`` (base acceleration cut alike)."""
        keep = np.ones(self.t.size, bool)
        if t_start is not None:
            keep &= self.t >= t_start
        if t_end is not None:
            keep &= self.t <= t_end
        acc = None if self.base_acc is None else self.base_acc[keep]
        return _replace(self, t=self.t[keep], y=self.y[keep], base_acc=acc)


@dataclass(frozen=True)
class StaticTest:
    """A static test: forces at (or near) the tip and the deflections they cause.

    ``δ_k = d₀ + F_k x²(3l − x)/(6 EI)`` (Euler–Bernoulli, force at the tip, deflection read at
    ``x``, the tip by default); ``d₀`` absorbs the zero of the gauge.

    Attributes:
        force_n: Forces (N).
        deflection_m: Deflections (m).
        x_m: Where the deflection is read (m from the clamp); the tip when None.
        source: File it came from, if any.
    """

    force_n: np.ndarray
    deflection_m: np.ndarray
    x_m: float | None = None
    source: str | None = None

    def __post_init__(self):
        f = np.asarray(self.force_n, dtype=float)
        d = np.asarray(self.deflection_m, dtype=float)
        if f.shape != d.shape or f.ndim != 1 or f.size < 3:
            raise CalibrationError("static test: need at least 3 (force, deflection) pairs")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(d))):
            raise CalibrationError("static test: non-finite force or deflection")
        if np.ptp(f) <= 0:
            raise CalibrationError("static test: the forces must differ")
        object.__setattr__(self, "force_n", f)
        object.__setattr__(self, "deflection_m", d)


def read_static_test(path: str | Path) -> StaticTest:
    """Read a static test CSV with columns ``force_n`` and ``deflection_m`` (optional ``x_m``)."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such static-test file")
    table = read_csv_table(path)
    need = ("force_n", "deflection_m")
    missing = [c for c in need if c not in table.header]
    if missing:
        raise RecordingError(
            f"{path}: static test needs columns {list(need)}; header is {table.header}"
        )
    col = {h: table.data[:, j] for j, h in enumerate(table.header)}
    x = col.get("x_m")
    return StaticTest(
        force_n=col["force_n"],
        deflection_m=col["deflection_m"],
        x_m=None if x is None else float(x[0]),
        source=str(path),
    )


def check_sampling(rec: Recording, record: WhiskerRecord) -> None:
    """Refuse ``rate_hz`` metadata at odds with the timestamps, and sampling far too slow
    for the whisker's first mode (a time column in ms read as seconds is 1000 times too
    slow): a fit to either would end with numbers, all of them wrong.

    Raises:
        RecordingError: Naming the recording, the rate and the whisker's f_1.
    """
    recording_rate(rec)
    rate = timestamp_rate(rec.t, where=str(rec.source))
    f1 = float(record.whisker().natural_frequencies_hz[0])
    if f1 > 5 * rate:
        raise RecordingError(
            f"{rec.source}: sampled at {rate:.4g} Hz, far too slowly for the whisker's first "
            f"mode ({f1:.4g} Hz from its record): is the time column in seconds?"
        )


def nominal_gain(record: WhiskerRecord, observable: str) -> float:
    """Observed units per physical unit from the record (V/m, codes/m) or 1."""
    g = float(record.hall.gain_v_per_m)
    return {"voltage": g, "adc": g / record.adc.lsb_v}.get(observable, 1.0)


def observation_from_recording(
    rec: Recording,
    record: WhiskerRecord,
    *,
    signal_col: str | None = None,
    base_col: str | None = None,
    observable: str = "auto",
    excitation: str = "auto",
    scale: float = 1.0,
    units_g: bool = False,
    fb_hz: float | None = None,
    hb_m: float | None = None,
    sensor_x_m: float | None = None,
    fit_gain: bool = False,
    gain_known: bool = False,
    t_start: float | None = None,
    t_end: float | None = None,
) -> Observation:
    """An :class:`Observation` of one recording, as ``whiskerid calibrate`` reads it.

    Args:
        rec: The recording (:func:`whiskerid.read_recording`).
        record: The whisker's record (its Hall gain and ADC when the gain is known).
        signal_col: The signal column; the first column that is not ``base_col`` by default.
        base_col: Column holding the measured base acceleration (m/s²).
        observable: What the signal is, or ``auto``: from the column's name or the
            ``units`` metadata.
        excitation: ``decay``, ``sine``, ``base`` or ``auto``: from the ``excitation``
            metadata, ``base`` when ``base_col`` is given, else ``decay``.
        scale: Multiply the signal by this.
        units_g: The signal is acceleration in g (also when the ``units`` metadata says g).
        fb_hz: Sine frequency (Hz); the ``fb_hz`` metadata by default.
        hb_m: Sine amplitude (m); the ``hb_m`` metadata by default, else unknown.
        sensor_x_m: Where the signal is read (m from the clamp); the record's sensor
            by default.
        fit_gain: Fit the sensor gain (as a product with the excitation amplitude).
        gain_known: Take a voltage's or ADC's gain from the record instead of fitting it.
        t_start: Use samples from this time (s); for a decay the free decay is found
            (:func:`whiskerid.fit.find_decays`) when None: the first one, see
            :func:`observations_from_recording` for all of them.
        t_end: Use samples up to this time (s).

    Raises:
        RecordingError: A missing column, or fewer than 16 samples in the window.
        CalibrationError: What the signal is cannot be told, or a sine without its frequency.
    """
    path = rec.source or "recording"
    name = Path(path).name
    signal_cols = [c for c in rec.columns if c != base_col]
    if signal_col is not None:
        col = signal_col
        if col not in rec.columns:
            raise RecordingError(f"{path}: no column {col!r}; columns are {['t', *rec.columns]}")
    elif signal_cols:
        col = signal_cols[0]
    else:
        raise RecordingError(f"{path}: no signal column")
    observable = _observable(observable, rec, col)
    y = (
        np.asarray(rec.columns[col], dtype=float)
        * scale
        * (G0 if units_g or rec.meta.get("units") == "g" else 1.0)
    )
    if excitation == "auto":
        excitation = _excitation(rec, base_col, y, path)
    fb = fb_hz if fb_hz is not None else _meta_float(rec, "fb_hz")
    hb = hb_m if hb_m is not None else _meta_float(rec, "hb_m")
    base_acc = None
    if excitation == "base":
        if not base_col:
            raise CalibrationError("--excitation base needs --base-col (base acceleration column)")
        if base_col not in rec.columns:
            raise RecordingError(
                f"{path}: no column {base_col!r}; columns are {['t', *rec.columns]}"
            )
        base_acc = rec.columns[base_col]
    if excitation == "sine" and fb is None:
        raise CalibrationError(f"{path}: a sine excitation needs --fb (or fb_hz metadata)")
    gain: float | None = 1.0
    if observable in ("voltage", "adc") and not gain_known:
        gain = None
    if fit_gain:
        gain = None
    if gain is not None and observable in ("voltage", "adc"):
        gain = nominal_gain(record, observable)
    obs = Observation(
        t=rec.t,
        y=y,
        excitation=excitation,
        observable=observable,
        x_m=sensor_x_m,
        fb_hz=fb,
        hb_m=hb,
        base_acc=base_acc,
        gain=gain,
        name=name,
        source=None if rec.source is None else str(rec.source),
    )
    if t_start is None and excitation == "decay":
        return _decay_windows(obs, t_end, path, first_only=True,
                              settle_s=_settle_s(obs, record))[0]  # fmt: skip
    return _cut(obs, t_start, t_end, path)


def observations_from_recording(
    rec: Recording, record: WhiskerRecord, **options
) -> list[Observation]:
    """Like :func:`observation_from_recording`, but one :class:`Observation` per free decay
    when the recording holds several plucks (and ``t_start`` is not given).

    A decay recording yields its decays as :func:`whiskerid.fit.find_decays` finds them,
    each named ``FILE#k`` with its window in ``Observation.selection``; they are meant to be
    calibrated jointly (shared κ and ζ, their own amplitudes and offsets). Any other
    recording yields one observation.

    Raises:
        CalibrationError: As :func:`observation_from_recording`; also a decay recording in
            which no free decay is found.
    """
    t_start = options.pop("t_start", None)
    t_end = options.pop("t_end", None)
    obs = observation_from_recording(rec, record, t_start=rec.t[0], **options)
    path = rec.source or "recording"
    if t_start is None and obs.excitation == "decay":
        return _decay_windows(obs, t_end, path, first_only=False,
                              settle_s=_settle_s(obs, record))  # fmt: skip
    return [_cut(obs, t_start, t_end, path)]


def observations_from_file(
    path: str | Path, record: WhiskerRecord, *, time_col: str = "t", **options
) -> list[Observation]:
    """Read a recording file and turn it into observations, as the command line does.

    The file is read by :func:`whiskerid.io.read_recording`, its sampling checked against
    the whisker (:func:`check_sampling`), then converted by
    :func:`observations_from_recording` with ``options``.

    Args:
        path: A recording (CSV, NPZ or NPY).
        record: The whisker's record (its f_1 judges the sampling rate).
        time_col: The time column's name (CSV) or array's (NPZ).
        **options: As :func:`observation_from_recording` (``signal_col``, ``observable``,
            ``excitation``, ...), and ``t_start``/``t_end``.

    Raises:
        RecordingError: A file that cannot be read, or sampled at odds with the whisker.
        CalibrationError: As :func:`observations_from_recording`.
    """
    rec = read_recording(path, time_col=time_col)
    with compile_cache():  # its small programs from the cache, as the command line's
        check_sampling(rec, record)
        return observations_from_recording(rec, record, **options)


def _cut(obs: Observation, t_start, t_end, path) -> Observation:
    obs = obs.window(t_start, t_end)
    if obs.t.size < 16:
        raise RecordingError(f"{path}: only {obs.t.size} samples between --t-start and --t-end")
    return obs


def _settle_s(obs: Observation, record: WhiskerRecord) -> float:
    """How long after a decay's first sample its samples may still hold the release (s).

    The ADS1115 averages its input over the conversion period before each sample: the first
    sample of a decay (the first the hold does not predict) averages over the release
    itself, part held and part free, which the free-decay model cannot describe (at 860 Hz
    and 60 dB it left residuals 1.7 times the noise). Samples whose conversion may have
    begun before that first sample are left out; other observables are instantaneous.
    """
    return float(record.adc.conversion_time_s) if obs.observable == "adc" else 0.0


def _decay_windows(obs: Observation, t_end, path, *, first_only: bool,
                   settle_s: float = 0.0) -> list[Observation]:  # fmt: skip
    """The free decays of a decay recording, each as its own observation (each starting
    ``settle_s`` after its first sample, see :func:`_settle_s`)."""
    if t_end is not None:
        obs = obs.window(None, t_end)
    decays = [
        d
        for d in find_decays(obs.t, obs.y)
        if np.sum((obs.t >= d.start_s) & (obs.t <= d.end_s)) >= 16
    ]
    if not decays:
        f = steady_line(obs.t, obs.y)
        hint = (
            f" It looks like a steady sine at {f:.4g} Hz: give --excitation sine --fb {f:.4g}."
            if f is not None
            else " Give --t-start at the release, or the right --excitation."
        )
        raise CalibrationError(f"{path}: no free decay (a pluck or tap ringing down) found.{hint}")
    found, decays = decays, (decays[:1] if first_only else decays)
    out = []
    for k, d in enumerate(decays):
        name = obs.name if len(decays) == 1 else f"{obs.name}#{k + 1}"
        # a sample exactly one conversion after the first is clear of the release
        o = obs.window(d.start_s + settle_s * (1.0 - 1e-9), d.end_s)
        quiet = quiet_stretch(obs.t, obs.y, found, k)
        out.append(_replace(o, name=name, selection=f"decay {d.describe()}", quiet=quiet))
    return out


def release_time(t: np.ndarray, y: np.ndarray) -> float:
    """When the first free decay in ``(t, y)`` starts (s): see :func:`whiskerid.fit.find_decays`.

    Raises:
        CalibrationError: No free decay is found.
    """
    decays = find_decays(t, y)
    if not decays:
        raise CalibrationError("no free decay (a pluck or tap ringing down) found")
    return decays[0].start_s


def _excitation(rec: Recording, base_col, y, path) -> str:
    """The excitation of a recording: its metadata, ``base`` with a base column, else told
    from the data (a steady line is a sine, which needs its frequency: refused)."""
    if base_col:
        return "base"
    meta = rec.meta.get("excitation")
    if meta is not None:
        if meta not in EXCITATIONS:
            raise CalibrationError(
                f"{path}: excitation {meta!r} in the metadata is not one of {EXCITATIONS}; "
                "give --excitation"
            )
        return meta
    f = steady_line(rec.t, y)
    if f is not None:
        raise CalibrationError(
            f"{path}: the recording does not say its excitation, and it holds a steady line at "
            f"{f:.4g} Hz that does not decay, like a sine base excitation: give --excitation "
            f"sine --fb <drive frequency in Hz> (and --hb if known), or --excitation decay"
        )
    return "decay"


def _observable(observable: str, rec: Recording, col: str) -> str:
    if observable != "auto":
        return observable
    if col in OBSERVABLES:
        return col
    units = rec.meta.get("units", "")
    by_units = {
        "m": "deflection",
        "m/s^2": "acceleration",
        "V": "voltage",
        "code": "adc",
        "g": "acceleration",
    }
    if units in by_units:
        return by_units[units]
    raise CalibrationError(
        f"{rec.source}: cannot tell what column {col!r} is; "
        f"give --observable ({', '.join(OBSERVABLES)})"
    )


def _meta_float(rec, key):
    v = rec.meta.get(key)
    try:
        return None if v is None else float(v)
    except ValueError:
        return None
