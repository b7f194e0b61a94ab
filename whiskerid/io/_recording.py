"""Recordings on disk: CSV with ``# key: value`` metadata lines, NPZ, NPY.

CSV layout::

    # rate_hz: 200
    # units: V
    t,voltage
    0.0021,1.6502
    ...

``t`` is in seconds and need not be uniform. A column ``t_<name>`` holds the own timestamps
of signal ``<name>`` where they differ from ``t`` (inputs of an ADC read one after the other:
``t,A0,A1,t_A1``); the reader keeps them in :attr:`Recording.times`, and tools that take one
time axis use ``t``. NPZ files hold a ``t`` array and one array per
signal column (metadata under ``meta_<key>``); NPY files hold a ``(2, N)`` or ``(N, 2)``
array of time and one signal (the layout of the cantilever recordings).

A CSV may end in a torn row: the Raspberry Pi's recorder appends rows while it runs, so a
crash or a power cut can cut the last row mid-number or leave NUL bytes behind it. The reader
drops such a tail with a :class:`TornRecordingWarning` that names the file; a malformed row
anywhere before the end is still an error.
"""

import csv
import hashlib
import io
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._atomic import atomic_write


class RecordingError(ValueError):
    """A recording that cannot be read or is unfit for use (message says what and where)."""


class TornRecordingWarning(UserWarning):
    """The end of a CSV recording was cut off while it was written; the torn part was dropped.

    A crash or a power cut while a recorder appends rows leaves a last row without its
    newline (cut mid-number, or short) and sometimes NUL bytes after it. The message names
    the file and what was dropped.
    """


#: The metadata key that :class:`whiskerid.hw.Recorder` writes in every file. Such a file
#: is appended row by row and every complete row ends in a newline, so a last row without
#: one was cut mid-write and is dropped even when it parses (``…,131`` of ``…,13188``).
RECORDER_KEY = "started_utc"


@dataclass
class Recording:
    """Timestamped samples of one or more signals.

    Attributes:
        t: Sample times (s), shape ``(n,)``.
        columns: Signal name → samples, each shape ``(n,)``.
        meta: Metadata (``rate_hz``, ``units``, ``terrain``, ``speed_mps``, ``whisker``, ...).
        source: Where it was read from, if anywhere.
        times: Signal name → its own sample times (s), for signals not sampled at ``t``
            (a CSV's ``t_<name>`` columns).
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    source: str | None = None
    times: dict[str, np.ndarray] = field(default_factory=dict)

    def time_of(self, name: str | None = None) -> np.ndarray:
        """The sample times of a signal (its own where it has them, else ``t``)."""
        if name is None:
            name = next(iter(self.columns), "")
        return self.times.get(name, self.t)

    def signal(self, name: str | None = None) -> np.ndarray:
        """The named column, or the only/first one when ``name`` is None."""
        if name is None:
            if not self.columns:
                raise RecordingError(f"{self.source or 'recording'}: no signal column")
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
    buf = io.StringIO()
    for key, value in rec.meta.items():
        buf.write(f"# {key}: {value}\n")
    writer = csv.writer(buf, lineterminator="\n")
    names = list(rec.columns)
    timed = [n for n in names if n in rec.times]
    writer.writerow(["t", *names, *(f"t_{n}" for n in timed)])
    cols = [np.asarray(rec.t, dtype=float)] + [np.asarray(rec.columns[n]) for n in names]
    cols += [np.asarray(rec.times[n], dtype=float) for n in timed]
    fmt = [_formatter(c, precision) for c in cols]
    for row in zip(*cols, strict=True):
        writer.writerow([f(v) for f, v in zip(fmt, row, strict=True)])
    return atomic_write(path, buf.getvalue())


def _formatter(col: np.ndarray, precision: int):
    if np.issubdtype(col.dtype, np.integer):
        return lambda v: str(int(v))
    return lambda v: f"{float(v):.{precision}g}"


def read_recording(
    path: str | Path, *, time_col: str = "t", allow_empty: bool = False
) -> Recording:
    """Read a CSV, NPZ or NPY recording.

    A torn end of a CSV (see :class:`TornRecordingWarning`) is dropped with that warning.

    Args:
        path: The file.
        time_col: Name of the time column (CSV) or array (NPZ).
        allow_empty: Return a recording without samples for a CSV holding only its header
            (a recorder stopped before its first row was on disk) instead of raising.

    Raises:
        RecordingError: Missing file, unknown format, no time or signal column, unparsable
            numbers (the message names the file, line and column), a corrupt NumPy file.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.is_dir():
        raise RecordingError(f"{path}: is a folder, not a recording file")
    readers = {".csv": _read_csv, ".npz": _read_npz, ".npy": _read_npy}
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise RecordingError(
            f"{path}: unknown recording format {path.suffix!r}; use .csv, .npz or .npy"
        )
    rec = _read_csv(path, time_col, allow_empty) if reader is _read_csv else reader(path, time_col)
    if not rec.columns:
        raise RecordingError(
            f"{path}: no signal column, only the time column {time_col!r}; "
            "a recording needs time and at least one signal"
        )
    rec.source = str(path)
    return rec


@dataclass
class CsvTable:
    """A numeric CSV table as read by :func:`read_csv_table`.

    Attributes:
        header: Column names (whitespace-stripped, unique).
        data: Values, shape ``(rows, len(header))``.
        meta: The leading ``# key: value`` lines.
    """

    header: list[str]
    data: np.ndarray
    meta: dict[str, str]


def read_csv_table(path: str | Path, *, allow_empty: bool = False) -> CsvTable:
    """Read a numeric CSV: ``# key: value`` lines, a header row, then numbers.

    Accepts a UTF-8 byte-order mark, CRLF line ends, blank lines, and comma, tab or
    semicolon delimiters (detected from the header row). A torn end (NUL bytes, or a last
    row without its newline that is short, not numeric, or in a recorder's file) is dropped
    with a :class:`TornRecordingWarning`.

    Args:
        path: The file.
        allow_empty: Return a table without rows for a file holding only its header
            instead of raising.

    Raises:
        RecordingError: Not UTF-8, no header, empty or duplicate column names, a comment
            line inside the data, a row of the wrong length or a cell that is not a number
            (named by line and column).
    """
    path = Path(path)
    text = _decode(path)
    lines = text.splitlines()
    meta, at = _metadata(lines)
    if at is None:
        raise RecordingError(f"{path}: no header row")
    delimiter = _delimiter(lines[at])
    header = [h.strip() for h in _split(lines[at], delimiter)]
    _check_header(path, header, at + 1)
    if _torn_last_row(text, lines, at, delimiter, len(header), RECORDER_KEY in meta):
        warnings.warn(
            f"{path} line {len(lines)}: dropped the torn last row {lines[-1][:40]!r} (no "
            "newline: the file was cut while it was written, e.g. by a crash or power cut)",
            TornRecordingWarning,
            stacklevel=2,
        )
        lines = lines[:-1]
    rows, numbers = [], []
    for i in range(at + 1, len(lines)):
        line = lines[i]
        if not line.strip():
            continue
        if line.lstrip().startswith("#"):
            raise RecordingError(
                f"{path} line {i + 1}: a comment line inside the data ({line.strip()[:40]!r}); "
                "remove it (metadata lines go above the header)"
            )
        cells = [c.strip() for c in _split(line, delimiter)]
        if len(cells) != len(header):
            raise RecordingError(_ragged(path, i + 1, cells, header))
        rows.append(cells)
        numbers.append(i + 1)
    if not rows:
        if allow_empty:
            return CsvTable(header=header, data=np.empty((0, len(header))), meta=meta)
        raise RecordingError(f"{path}: no data rows after the header")
    try:
        data = np.array(rows, dtype=float)
    except ValueError:
        raise RecordingError(_first_bad_cell(path, rows, numbers, header)) from None
    return CsvTable(header=header, data=data, meta=meta)


def _decode(path: Path) -> str:
    raw = path.read_bytes()
    kept = raw.rstrip(b"\0")
    if len(kept) < len(raw):
        warnings.warn(
            f"{path}: ignored {len(raw) - len(kept)} NUL byte(s) at the end (what a power cut "
            "can leave after the last write)",
            TornRecordingWarning,
            stacklevel=2,
        )
        raw = kept
    try:
        # utf-8-sig drops the byte-order mark that spreadsheet programs put in front.
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise RecordingError(
            f"{path} line {line}: not UTF-8 text (byte 0x{raw[err.start]:02x}); "
            "save the file as UTF-8"
        ) from None


def _torn_last_row(
    text: str, lines: list[str], header_at: int, delimiter: str, width: int, recorder: bool
) -> bool:
    """Whether the last line is a row cut mid-write.

    It has no newline, and it is in a recorder's file (where every complete row ends in
    one), or it looks cut: every cell but the last is a number, and the row is short or its
    last cell is not a number (empty, ``-``, ``1e``).
    """
    last = len(lines) - 1
    if last <= header_at or text.endswith(("\n", "\r")) or not lines[last].strip():
        return False
    if recorder:
        return True
    cells = [c.strip() for c in _split(lines[last], delimiter)]
    if len(cells) > width or not all(_is_number(c) for c in cells[:-1]):
        return False
    return len(cells) < width or not _is_number(cells[-1])


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _metadata(lines: list[str]) -> tuple[dict[str, str], int | None]:
    """The leading ``# key: value`` lines (blank lines skipped) and the header's index."""
    meta: dict[str, str] = {}
    for i, line in enumerate(lines):
        text = line.strip()
        if not text:
            continue
        if not text.startswith("#"):
            return meta, i
        key, colon, value = text[1:].partition(":")
        if colon:  # a '#' line without a colon is a comment, not metadata
            meta[key.strip()] = value.strip()
    return meta, None


def _delimiter(header: str) -> str:
    """Comma, tab or semicolon: whichever the header row holds most of (comma on a tie)."""
    return max((",", "\t", ";"), key=header.count)


def _split(line: str, delimiter: str) -> list[str]:
    if '"' not in line:
        return line.split(delimiter)
    return next(csv.reader([line], delimiter=delimiter))


def _check_header(path: Path, header: list[str], line: int) -> None:
    for j, name in enumerate(header):
        if not name:
            hint = "; remove the trailing delimiter" if j == len(header) - 1 else ""
            raise RecordingError(f"{path} line {line}: column {j + 1} has no name{hint}")
    dups = sorted({h for h in header if header.count(h) > 1})
    if dups:
        raise RecordingError(
            f"{path} line {line}: column name(s) {dups} appear more than once; "
            "give every column its own name"
        )


def _ragged(path: Path, line: int, cells: list[str], header: list[str]) -> str:
    hint = " (a trailing delimiter?)" if len(cells) == len(header) + 1 and not cells[-1] else ""
    return (
        f"{path} line {line}: {len(cells)} value(s) but the header has {len(header)} "
        f"column(s) {header}{hint}; every row needs one value per column"
    )


def _first_bad_cell(path: Path, rows: list[list[str]], numbers: list[int], header) -> str:
    for cells, line in zip(rows, numbers, strict=True):
        for name, cell in zip(header, cells, strict=True):
            try:
                float(cell)
            except ValueError:
                return _bad_cell(path, line, name, cell)
    return f"{path}: a value is not a number"


def _bad_cell(path: Path, line: int, column: str, cell: str) -> str:
    where = f"{path} line {line}, column {column!r}: {cell!r} is not a number"
    try:
        float(cell.replace(",", "."))
    except ValueError:
        what = "fill in the value or remove the row" if not cell else "use plain numbers"
        return f"{where}; {what}"
    return f"{where}; use a decimal point, not a comma"


def _read_csv(path: Path, time_col: str, allow_empty: bool = False) -> Recording:
    table = read_csv_table(path, allow_empty=allow_empty)
    if time_col not in table.header:
        raise RecordingError(f"{path}: no time column {time_col!r}; header is {table.header}")
    cols = {h: table.data[:, j] for j, h in enumerate(table.header)}
    t = cols.pop(time_col)
    own = {h[2:]: cols.pop(h) for h in list(cols) if h.startswith("t_") and h[2:] in cols}
    return Recording(t=t, columns=cols, meta=table.meta, times=own)


# What a corrupt, truncated or non-array NumPy file raises inside np.load.
_NUMPY_LOAD_ERRORS = (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def _not_numpy(path: Path, err: Exception) -> RecordingError:
    kind = ".npz archive" if path.suffix.lower() == ".npz" else ".npy array file"
    return RecordingError(
        f"{path}: not a valid NumPy {kind} (truncated, corrupt, or holding Python objects "
        f"rather than numbers: {type(err).__name__}); save numeric arrays with numpy.save "
        "or numpy.savez"
    )


def _read_npz(path: Path, time_col: str) -> Recording:
    try:
        # Our own file handle: np.load leaks its own when the archive is corrupt.
        with open(path, "rb") as fh:
            z = np.load(fh, allow_pickle=False)
            if isinstance(z, np.lib.npyio.NpzFile):
                with z:
                    arrays = {k: np.asarray(z[k]) for k in z.files}
    except _NUMPY_LOAD_ERRORS as err:
        raise _not_numpy(path, err) from None
    if not isinstance(z, np.lib.npyio.NpzFile):  # one array: a .npy file misnamed
        raise RecordingError(
            f"{path}: a single NumPy array (a .npy file) named .npz; an .npz archive holds "
            "named arrays (t and the signals): rename it to .npy"
        )
    if time_col not in arrays:
        raise RecordingError(f"{path}: no array {time_col!r}; arrays are {list(arrays)}")
    t = _numeric(path, time_col, arrays.pop(time_col)).astype(float)
    meta = {k[5:]: str(v) for k, v in arrays.items() if k.startswith("meta_")}
    cols = {k: _numeric(path, k, v) for k, v in arrays.items() if not k.startswith("meta_")}
    for name, col in cols.items():
        if col.shape != t.shape or t.ndim != 1:
            raise RecordingError(
                f"{path}: array {name!r} has shape {col.shape} but {time_col!r} has "
                f"{t.shape}; each signal must be 1-D and as long as the time array"
            )
    return Recording(t=t, columns=cols, meta=meta)


def _numeric(path: Path, name: str, arr: np.ndarray) -> np.ndarray:
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise RecordingError(f"{path}: array {name!r} holds {arr.dtype} values, not numbers")
    return arr


def _read_npy(path: Path, time_col: str) -> Recording:
    try:
        with open(path, "rb") as fh:
            arr = np.load(fh, allow_pickle=False)
            if not isinstance(arr, np.ndarray):  # an .npz archive named .npy
                arr.close()
    except _NUMPY_LOAD_ERRORS as err:
        raise _not_numpy(path, err) from None
    if not isinstance(arr, np.ndarray):
        raise RecordingError(f"{path}: an .npz archive named .npy; rename it to .npz")
    arr = _numeric(path, "(the array)", arr)
    if arr.ndim != 2 or 2 not in arr.shape:
        raise RecordingError(
            f"{path}: expected a (2, N) array of time and signal, got shape {arr.shape}"
        )
    arr = arr if arr.shape[0] == 2 else arr.T
    return Recording(t=arr[0].astype(float), columns={"signal": arr[1].astype(float)})


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same file (also through links, or when not yet there)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_out_path(path: Path, flag: str, *, inputs: dict[str, Path | list | None]) -> None:
    """Refuse an output file that is one of the inputs, a folder, or under a file.

    Checked before any work, so that a bad ``--out`` neither destroys an input nor wastes
    a long computation.

    Args:
        path: The file to write.
        flag: Its option name, for the message (``--out``).
        inputs: Option name → input path(s) (None for an option not given).

    Raises:
        ValueError: What is wrong, on one line.
    """
    path = Path(path)
    for name, given in inputs.items():
        for p in given if isinstance(given, list | tuple) else [given]:
            if p is not None and same_file(path, p):
                raise ValueError(
                    f"{flag} {path} is also the input {name} {p}; writing it would destroy "
                    "the input: give another file name"
                )
    if path.is_dir():
        raise ValueError(f"{flag} {path} is a folder; give a file name")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{flag} {path}: {parent} is a file, not a folder")
            break


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
            f"(t = {float(t[bad[0] + 1])!r}); timestamps must increase"
        )


def sha256_of(path: str | Path) -> str:
    """SHA-256 of a file's bytes (the provenance of calibration records and model files)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
