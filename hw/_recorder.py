"""Crash-tolerant CSV recording in the whiskerid recording format.

Format: leading ``# key: value`` metadata lines, a header ``t,<column>...``, then one row per
sample with ``t`` in seconds since the start of the recording. The writer flushes and fsyncs
at least once per second, so a crash or a power cut loses at most the last second, and possibly
leaves a torn last line, which :func:`whiskerid.io.read_recording` drops with a warning.
"""

from __future__ import annotations

import datetime
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from whiskerid.io import RECORDER_KEY, Recording, fsync_folder, read_recording

from ._sampler import Sample


def unique_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` if it does not exist, else the first free ``stem-N.suffix`` (N = 1, 2...).

    Useful for a service that restarts and must not overwrite its previous recording.
    """
    p = Path(path)
    n = 0
    candidate = p
    while candidate.exists():
        n += 1
        candidate = p.with_name(f"{p.stem}-{n}{p.suffix}")
    return candidate


class Recorder:
    """Write samples to a recording CSV, durable to within ``sync_interval_s``.

    Args:
        path: Output file. It must not exist unless ``overwrite`` is True.
        columns: Signal column names after ``t`` (``"voltage"`` matches the simulator's
            observable name for volts).
        own_times: Give every column after the first its own timestamp column ``t_<name>``
            (header ``t,A0,A1,t_A1``: ``t`` is the first column's time); write rows with
            :meth:`write_round`. For inputs read one after the other.
        rate_hz: Nominal sample rate, written as metadata.
        units: Units of the signal columns, written as metadata.
        whisker: Optional whisker name or file, written as metadata.
        metadata: More ``key: value`` metadata lines.
        sync_interval_s: Longest time between flush + fsync, in seconds.
        overwrite: Replace an existing file instead of raising ``FileExistsError``.
        clock: Monotonic clock in integer nanoseconds (decides when to sync).
        fsync: Function used to sync a file descriptor (``os.fsync``; injectable for tests).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        columns: Sequence[str] = ("voltage",),
        rate_hz: float | None = None,
        units: str | None = "V",
        whisker: str | None = None,
        metadata: Mapping[str, Any] | None = None,
        own_times: bool = False,
        sync_interval_s: float = 1.0,
        overwrite: bool = False,
        clock: Callable[[], int] = time.monotonic_ns,
        fsync: Callable[[int], None] = os.fsync,
    ) -> None:
        self.columns = tuple(columns)
        if not self.columns or any(
            not c or "," in c or "\n" in c or c == "t" for c in self.columns
        ):
            raise ValueError(f"bad column names {self.columns!r}: need non-empty names without ',' "
                             "or newlines, other than 't'")  # fmt: skip
        self.own_times = bool(own_times)
        self.path = Path(path)
        self.sync_interval_ns = round(sync_interval_s * 1e9)
        self.rows = 0
        self.syncs = 0
        self._clock = clock
        self._fsync = fsync
        meta: dict[str, Any] = {}
        if rate_hz is not None:
            meta["rate_hz"] = rate_hz
        if units is not None:
            meta["units"] = units
        if whisker is not None:
            meta["whisker"] = whisker
        # Also tells the reader that rows were appended live, so that an unterminated last
        # row is a torn one.
        meta[RECORDER_KEY] = (
            datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
        )
        meta.update(metadata or {})
        for key, value in meta.items():
            if ":" in str(key) or "\n" in f"{key}{value}":
                raise ValueError(
                    f"metadata {key!r}: {value!r} cannot hold ':' in the key or newlines"
                )
        self.metadata = meta
        # newline="" writes "\n" on every platform; the reader relies on it to spot torn lines.
        self._file: TextIO | None = open(  # closed in close()
            self.path, "w" if overwrite else "x", encoding="utf-8", newline=""
        )
        lines = [f"# {k}: {v}\n" for k, v in meta.items()]
        header = ["t", *self.columns]
        if self.own_times:
            header += [f"t_{c}" for c in self.columns[1:]]
        lines.append(",".join(header) + "\n")
        self._file.write("".join(lines))
        self.sync()
        # the new directory entry too, or a power cut could lose the whole file
        fsync_folder(self.path.parent.resolve())

    def write(self, t_s: float, *values: float) -> None:
        """Append one row; sync if the last sync is ``sync_interval_s`` old.

        Args:
            t_s: Seconds since the start of the recording.
            *values: One value per signal column.
        """
        if self.own_times and len(self.columns) > 1:
            raise ValueError("this recorder stamps each column: write rows with write_round")
        self._row(f"{t_s:.9f},", values, "")

    def write_round(self, times: Sequence[float], values: Sequence[float]) -> None:
        """Append one row of several inputs, each with its own time (``own_times``).

        Args:
            times: Seconds since the start, one per column (the first is the row's ``t``).
            values: One value per column.
        """
        if len(times) != len(self.columns):
            raise ValueError(f"expected {len(self.columns)} times, got {len(times)}")
        extra = "".join(f",{t:.9f}" for t in times[1:]) if self.own_times else ""
        self._row(f"{times[0]:.9f},", values, extra)

    def _row(self, head: str, values: Sequence[float], tail: str) -> None:
        if self._file is None:
            raise ValueError("the recorder is closed")
        if len(values) != len(self.columns):
            raise ValueError(f"expected {len(self.columns)} values, got {len(values)}")
        # repr-like precision: 1 ns in t, 9 significant digits for the 16-bit signal.
        self._file.write(head + ",".join(f"{v:.9g}" for v in values) + tail + "\n")
        self.rows += 1
        self.maybe_sync()

    def write_sample(self, sample: Sample) -> None:
        """Append a :class:`Sample` as ``t, volts`` (one signal column); usable as a callback."""
        self.write(sample.t_s, sample.volts)

    __call__ = write_sample

    def maybe_sync(self) -> bool:
        """Sync if due; call it from a loop that may go a while without writing (e.g. gaps).

        Returns:
            True if it synced.
        """
        if self._clock() - self._last_sync_ns >= self.sync_interval_ns:
            self.sync()
            return True
        return False

    def sync(self) -> None:
        """Flush Python's buffer and fsync the file so the rows survive a power cut."""
        if self._file is None:
            return
        self._file.flush()
        self._fsync(self._file.fileno())
        self.syncs += 1
        self._last_sync_ns = self._clock()

    def close(self) -> None:
        """Sync and close the file (idempotent; closed even when syncing or closing fails,
        as on a full disk, so that a later call never meets a half-closed file)."""
        if self._file is None:
            return
        try:
            self.sync()
        finally:
            file, self._file = self._file, None
            file.close()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return self._file is None

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def read_recording_csv(path: str | os.PathLike[str]) -> Recording:
    """Read a recording CSV, tolerating the torn end a crash leaves; a header-only file is empty.

    The same reader as :func:`whiskerid.io.read_recording` (``allow_empty=True``): a last row
    without its newline is dropped with a :class:`whiskerid.io.TornRecordingWarning` even if
    it parses (``1.25,0.5`` may be the start of ``1.25,0.5123``), trailing NUL bytes (what
    some filesystems leave after a power cut) are ignored with the same warning, and anything
    malformed before the last row is an error.

    Raises:
        whiskerid.io.RecordingError: No header, or a complete row is malformed.
    """
    return read_recording(path, allow_empty=True)


#: The recording type :func:`read_recording_csv` returns (the library's own).
CSVRecording = Recording
