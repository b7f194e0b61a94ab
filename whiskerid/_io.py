"""Recordings on disk (NOTES §6): CSV with ``# key: value`` metadata lines, NPZ, NPY.

CSV layout::

    # rate_hz: 200
    # units: V
    t,voltage
    0.0021,1.6502
    ...

``t`` is in seconds and need not be uniform. NPZ files hold a ``t`` array and one array per
signal column (metadata under ``meta_<key>``); NPY files hold a ``(2, N)`` or ``(N, 2)``
array of time and one signal (the layout of the cantilever recordings in ``shared/data``).
"""

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class RecordingError(ValueError):
    """A recording that cannot be read or is unfit for use (message says what and where)."""


@dataclass
class Recording:
    """Timestamped samples of one or more signals.

    Attributes:
        t: Sample times (s), shape ``(n,)``.
        columns: Signal name → samples, each shape ``(n,)``.
        meta: Metadata (``rate_hz``, ``units``, ``terrain``, ``speed_mps``, ``whisker``, ...).
        source: Where it was read from, if anywhere.
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    source: str | None = None

    def signal(self, name: str | None = None) -> np.ndarray:
        """The named column, or the only/first one when ``name`` is None."""
        if name is None:
            return next(iter(self.columns.values()))
        if name not in self.columns:
            raise RecordingError(
                f"{self.source or 'recording'}: no column {name!r}; "
                f"columns are {['t', *self.columns]}"
            )
        return self.columns[name]


def write_csv(path: str | Path, rec: Recording, *, precision: int = 10) -> Path:
    """Write a recording as CSV with metadata lines; integer columns stay integers."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    for key, value in rec.meta.items():
        buf.write(f"# {key}: {value}\n")
    writer = csv.writer(buf, lineterminator="\n")
    names = list(rec.columns)
    writer.writerow(["t", *names])
    cols = [np.asarray(rec.t, dtype=float)] + [np.asarray(rec.columns[n]) for n in names]
    fmt = [_formatter(c, precision) for c in cols]
    for row in zip(*cols, strict=True):
        writer.writerow([f(v) for f, v in zip(fmt, row, strict=True)])
    path.write_text(buf.getvalue())
    return path


def _formatter(col: np.ndarray, precision: int):
    if np.issubdtype(col.dtype, np.integer):
        return lambda v: str(int(v))
    return lambda v: f"{float(v):.{precision}g}"


def read_recording(path: str | Path, *, time_col: str = "t") -> Recording:
    """Read a CSV, NPZ or NPY recording.

    Raises:
        RecordingError: Missing file, unknown format, no time column, unparsable numbers.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    readers = {".csv": _read_csv, ".npz": _read_npz, ".npy": _read_npy}
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise RecordingError(
            f"{path}: unknown recording format {path.suffix!r}; use .csv, .npz or .npy"
        )
    rec = reader(path, time_col)
    rec.source = str(path)
    return rec


def _read_csv(path: Path, time_col: str) -> Recording:
    meta: dict[str, str] = {}
    lines = path.read_text().splitlines()
    body_start = 0
    for i, line in enumerate(lines):
        if not line.startswith("#"):
            body_start = i
            break
        key, _, value = line[1:].partition(":")
        meta[key.strip()] = value.strip()
    else:
        raise RecordingError(f"{path}: no header row")
    rows = list(csv.reader(lines[body_start:]))
    header = [h.strip() for h in rows[0]]
    if time_col not in header:
        raise RecordingError(f"{path}: no time column {time_col!r}; header is {header}")
    try:
        data = np.array([[float(v) for v in r] for r in rows[1:] if r], dtype=float)
    except ValueError as err:
        raise RecordingError(f"{path}: a value is not a number ({err})") from None
    if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] != len(header):
        raise RecordingError(f"{path}: no data rows, or rows of unequal length")
    cols = {h: data[:, j] for j, h in enumerate(header)}
    t = cols.pop(time_col)
    return Recording(t=t, columns=cols, meta=meta)


def _read_npz(path: Path, time_col: str) -> Recording:
    with np.load(path, allow_pickle=False) as z:
        if time_col not in z:
            raise RecordingError(f"{path}: no array {time_col!r}; arrays are {list(z)}")
        meta = {k[5:]: str(z[k]) for k in z if k.startswith("meta_")}
        cols = {k: np.asarray(z[k]) for k in z if k != time_col and not k.startswith("meta_")}
        return Recording(t=np.asarray(z[time_col], dtype=float), columns=cols, meta=meta)


def _read_npy(path: Path, time_col: str) -> Recording:
    arr = np.load(path, allow_pickle=False)
    if arr.ndim != 2 or 2 not in arr.shape:
        raise RecordingError(
            f"{path}: expected a (2, N) array of time and signal, got shape {arr.shape}"
        )
    arr = arr if arr.shape[0] == 2 else arr.T
    return Recording(t=arr[0].astype(float), columns={"signal": arr[1].astype(float)})


def check_samples(t: np.ndarray, x: np.ndarray, *, where: str = "recording", min_samples: int = 8):
    """Refuse NaN/inf samples, non-increasing or duplicate timestamps, and too few samples."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.shape != x.shape or t.ndim != 1:
        raise RecordingError(f"{where}: time and signal must be 1-D of equal length")
    if t.size < min_samples:
        raise RecordingError(f"{where}: only {t.size} samples; at least {min_samples} needed")
    for name, arr in (("time", t), ("signal", x)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise RecordingError(
                f"{where}: {bad.size} non-finite {name} value(s), first at "
                f"row {bad[0]}; remove or interpolate them"
            )
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        kind = "duplicate" if steps[bad[0]] == 0 else "decreasing"
        raise RecordingError(
            f"{where}: {kind} timestamp at row {bad[0] + 1} "
            f"(t = {t[bad[0] + 1]!r}); timestamps must increase"
        )
