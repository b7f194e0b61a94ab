"""Datasets of labelled recordings, cut into windows at one uniform rate.

A dataset is a folder ``ROOT/<label>/<recording>.csv`` (``.npz`` and ``.npy`` recordings too;
hidden and system entries are skipped). Each recording is resampled to one uniform rate (from
its ``rate_hz`` metadata or its timestamps: a Raspberry Pi's are not uniform) and cut into
windows (1 s and no overlap by default, as the paper); a recording's ``speed_mps`` metadata,
when present, goes with its windows. A recording sampled faster than the rate asked for is
low-passed first, so that nothing above the new Nyquist frequency folds back into the band.
"""

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..io import (
    Recording,
    RecordingError,
    check_samples,
    read_recording,
    recording_rate,
)
from ..io import timestamp_rate as timestamp_rate  # the package re-exports it, as before
from ..io._rate import RATE_TOLERANCE as RATE_TOLERANCE  # in io: the stream checks it without JAX

RECORDING_SUFFIXES = (".csv", ".npz", ".npy")
#: Fewest samples a window may hold: a spectrum of fewer bins says nothing of a terrain.
MIN_WINDOW = 16
#: Timestamp steps longer than this many median steps are gaps that windows never span.
GAP_STEPS = 10.0


@dataclass
class WindowSet:
    """Labelled windows cut from recordings.

    Attributes:
        windows: Uniformly sampled windows, shape ``(n, window)``, or ``(n, channels,
            window)`` for several signals per window (e.g. six IMU axes).
        labels: Class index per window, shape ``(n,)``.
        label_names: Class names, indexed by ``labels``.
        recording: Index into ``sources`` per window, shape ``(n,)``.
        speeds: Robot speed per window (m/s), NaN where unknown.
        sources: Recording names.
        rate_hz: Sample rate of the windows (Hz).
        start_s: Start of each window within its recording (s), shape ``(n,)``; None
            when unknown (windows are then taken as consecutive and non-overlapping, in
            recording order, for :func:`fuse_context`).
        metas: Each recording's metadata (indexed like ``sources``), where known.
        channel: The recorded column the windows come from, where known; several
            columns joined by commas (``"hall_a,hall_b"``) for multi-channel windows.
    """

    windows: np.ndarray
    labels: np.ndarray
    label_names: tuple[str, ...]
    recording: np.ndarray
    speeds: np.ndarray
    sources: list[str]
    rate_hz: float
    start_s: np.ndarray | None = None
    channel: str | None = None
    metas: list[dict] | None = None

    def __len__(self) -> int:
        return int(self.labels.size)

    def subset(self, mask: np.ndarray) -> "WindowSet":
        """The windows where ``mask`` is true (index arrays work too)."""
        return replace(
            self,
            windows=self.windows[mask],
            labels=self.labels[mask],
            recording=self.recording[mask],
            speeds=self.speeds[mask],
            start_s=None if self.start_s is None else self.start_s[mask],
        )

    @property
    def has_speed(self) -> bool:
        """Whether every window has a known speed."""
        return bool(len(self) and np.isfinite(self.speeds).all())

    def starts(self) -> np.ndarray:
        """:attr:`start_s`, or consecutive window lengths within each recording."""
        if self.start_s is not None:
            return np.asarray(self.start_s, dtype=float)
        out = np.zeros(len(self))
        for r in np.unique(self.recording):
            idx = np.flatnonzero(self.recording == r)
            out[idx] = np.arange(idx.size) * self.windows.shape[-1] / self.rate_hz
        return out


def check_rate(rec: Recording, rate_hz: float) -> float:
    """The recording's rate, refused when below ``rate_hz`` (resampling up cannot add
    the frequencies between the two Nyquist limits; the features would see an empty
    band and a model would read it as a terrain)."""
    return _not_slower(rec, recording_rate(rec), rate_hz)


def _not_slower(rec: Recording, own: float, rate_hz: float) -> float:
    """:func:`check_rate` given the recording's own rate ``own``."""
    if own < rate_hz * (1 - RATE_TOLERANCE):
        hint = " (is the time column in seconds?)" if own < rate_hz / 50 else ""
        raise RecordingError(
            f"{rec.source or 'recording'}: sampled at {own:.4g} Hz{hint}, below the "
            f"{rate_hz:g} Hz needed: record at {rate_hz:g} Hz or more, or use a model "
            f"(train --rate) at {own:.4g} Hz"
        )
    return own


def windows_of(
    t: np.ndarray, x: np.ndarray, *, rate_hz: float, window: int, hop: int
) -> tuple[np.ndarray, np.ndarray]:
    """Resample ``x(t)`` onto a uniform grid at ``rate_hz`` and cut windows.

    Steps longer than :data:`GAP_STEPS` median steps are gaps (a paused logger, lost
    samples): windows never straddle them, rather than hold a straight line drawn across.
    A recording sampled faster than ``rate_hz`` is low-passed first (zero-phase
    Butterworth at 0.45 ``rate_hz``), so that what lies above the new Nyquist frequency
    does not fold back into the band.

    Returns:
        Windows ``(k, window)`` and their start times (s after the first sample).
    """
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0 / rate_hz
    cuts = np.flatnonzero(np.diff(t) > GAP_STEPS * step) + 1
    wins, starts = [], []
    for ts, xs in zip(np.split(t, cuts), np.split(x, cuts), strict=True):
        n = int(np.floor((ts[-1] - ts[0]) * rate_hz * (1 + 1e-9))) + 1
        if n < window:
            continue
        if 1 / step > rate_hz * (1 + RATE_TOLERANCE):
            xs = _anti_alias(ts, xs, step, rate_hz)
        xu = np.interp(ts[0] + np.arange(n) / rate_hz, ts, xs)
        first = np.arange(0, n - window + 1, hop)
        wins.extend(xu[s : s + window] for s in first)
        starts.append(ts[0] - t[0] + first / rate_hz)
    if not wins:
        return np.zeros((0, window)), np.zeros(0)
    return np.stack(wins), np.concatenate(starts)


def _anti_alias(t: np.ndarray, x: np.ndarray, step: float, rate_hz: float) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt

    sos = butter(8, 0.45 * rate_hz, fs=1 / step, output="sos")
    if x.size <= 3 * (2 * len(sos) + 1):  # too short for filtfilt's padding
        return x
    grid = t[0] + np.arange(x.size) * step  # the filter wants a uniform grid
    return np.interp(t, grid, sosfiltfilt(sos, np.interp(grid, t, x)))


def cut_windows(
    t: np.ndarray, x: np.ndarray, *, rate_hz: float, window: int, hop: int
) -> np.ndarray:
    """The windows of :func:`windows_of`, shape ``(k, window)``."""
    return windows_of(t, x, rate_hz=rate_hz, window=window, hop=hop)[0]


def window_samples(window_s: float, hop_s: float | None, rate_hz: float) -> tuple[int, int]:
    """Window and hop in samples, refused when a window is too short to mean anything."""
    if not (np.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window {window_s!r} s must be a positive number of seconds")
    if hop_s is not None and not (np.isfinite(hop_s) and hop_s > 0):
        raise ValueError(f"hop {hop_s!r} s must be a positive number of seconds")
    window = round(window_s * rate_hz)
    if window < MIN_WINDOW:
        raise ValueError(
            f"a {window_s:g} s window holds {window} samples at {rate_hz:.4g} Hz (at least "
            f"{MIN_WINDOW} needed): pass a longer window, and check that the time column "
            "is in seconds"
        )
    hop = window if hop_s is None else round(hop_s * rate_hz)
    if hop < 1:
        raise ValueError(f"hop {hop_s:g} s is under one sample at {rate_hz:.4g} Hz")
    return window, hop


def recording_signal(rec: Recording, channel: str | None, *, only_column_ok: bool = False
                     ) -> np.ndarray:  # fmt: skip
    """The channel to classify (the first signal column by default), checked.

    Args:
        rec: The recording.
        channel: Column name; None: the first signal column.
        only_column_ok: When ``channel`` is missing but the recording has a single signal
            column, take that one (a model trained on CSV column ``adc`` reading an NPY
            recording, whose column is always ``signal``).

    Raises:
        RecordingError: No such column, bad samples, or a constant signal (a disconnected
            or saturated sensor: any label given to it would be made up).
    """
    name = signal_column(rec, channel, only_column_ok=only_column_ok)
    x = np.asarray(rec.signal(name), dtype=float)
    where = rec.source or "recording"
    check_samples(rec.t, x, where=where)
    if np.ptp(x) == 0:
        raise RecordingError(
            f"{where}: column {name!r} is constant ({x[0]:g}): a disconnected or saturated "
            "sensor? There is no vibration to classify"
        )
    return x


def signal_column(rec: Recording, channel: str | None, *, only_column_ok: bool = False) -> str:
    """The name of the column :func:`recording_signal` reads (same arguments)."""
    if not rec.columns:
        raise RecordingError(f"{rec.source or 'recording'}: no signal column")
    if channel is None or (only_column_ok and channel not in rec.columns and len(rec.columns) == 1):
        return next(iter(rec.columns))
    return channel


def channel_names(channel) -> tuple[str, ...] | None:
    """Several columns from ``"a,b"``, ``["a", "b"]`` or ``"all"`` (kept as ``("all",)``);
    None for the default (the first signal column)."""
    if channel is None:
        return None
    names = channel.split(",") if isinstance(channel, str) else list(channel)
    names = tuple(n.strip() for n in names if n.strip())
    if not names:
        raise ValueError(f"no column named in {channel!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"column(s) named twice in {channel!r}")
    return names


def recording_signals(rec: Recording, names: tuple[str, ...]) -> np.ndarray:
    """Several channels of a recording, shape ``(channels, samples)``, each checked as by
    :func:`recording_signal` (a missing column is refused, naming the ones there are)."""
    missing = [n for n in names if n not in rec.columns]
    if missing:
        raise RecordingError(
            f"{rec.source or 'recording'}: no column(s) {missing} (columns: "
            f"{list(rec.columns)}): record every channel the model reads"
        )
    return np.stack([recording_signal(rec, n) for n in names])


def multi_windows(t, xs, *, rate_hz: float, window: int, hop: int):
    """:func:`windows_of` for ``(channels, samples)``: windows ``(k, channels, window)``
    (``(k, window)`` for one channel) and their start times."""
    per = [windows_of(t, x, rate_hz=rate_hz, window=window, hop=hop) for x in xs]
    if len(per) == 1:
        return per[0]
    return np.stack([w for w, _ in per], axis=1), per[0][1]


def _visible(p: Path) -> bool:
    """Not a hidden or system entry (``.ipynb_checkpoints``, macOS ``._x.csv`` and
    ``__MACOSX``): those are never recordings or labels."""
    return not p.name.startswith((".", "__"))


def _is_recording(f: Path) -> bool:
    return f.is_file() and _visible(f) and f.suffix.lower() in RECORDING_SUFFIXES


def list_dataset(root: str | Path) -> dict[str, list[Path]]:
    """``label → recording files`` of a dataset folder ``ROOT/<label>/<recording>``.

    Raises:
        RecordingError: ``root`` is not a folder, holds no recordings, or has a label
            folder without recordings (the class would silently vanish).
    """
    root = Path(root)
    if not root.is_dir():
        raise RecordingError(
            f"{root}: not a dataset folder (expected ROOT/<label>/<recording>.csv)"
        )
    out, empty = {}, []
    for d in sorted(p for p in root.iterdir() if p.is_dir() and _visible(p)):
        files = sorted(f for f in d.iterdir() if _is_recording(f))
        if files:
            out[d.name] = files
        else:
            empty.append(d.name)
    if not out:
        raise RecordingError(f"{root}: no recordings in ROOT/<label>/ folders")
    if empty:
        raise RecordingError(
            f"{root}: label folder(s) {empty} hold no recordings "
            f"({'/'.join(RECORDING_SUFFIXES)}): add recordings or move the folder(s) away"
        )
    return out


def _first_channel(recs: list[tuple[str, Recording]], root) -> str:
    """The column every recording has first, refused when they disagree (a dataset whose
    files list their axes in different orders would mix the axes)."""
    firsts = {}
    for _, rec in recs:
        firsts.setdefault(next(iter(rec.columns), ""), str(rec.source))
    if len(firsts) > 1:
        seen = ", ".join(f"{c!r} in {Path(src).name}" for c, src in firsts.items())
        raise RecordingError(
            f"{root}: the recordings' first signal columns differ ({seen}): pass --channel"
        )
    return next(iter(firsts))


def load_dataset(
    root: str | Path,
    *,
    channel: str | None = None,
    window_s: float = 1.0,
    hop_s: float | None = None,
    rate_hz: float | None = None,
    labels: tuple[str, ...] | None = None,
) -> WindowSet:
    """Read a dataset folder into labelled windows.

    Args:
        root: ``ROOT/<label>/<recording>.csv``.
        channel: Column to classify (the first signal column by default); several, as
            ``"hall_a,hall_b"`` or a list, give windows ``(n, channels, window)``, and
            ``"all"`` takes every signal column (the same in every recording).
        window_s: Window length (s).
        hop_s: Step between windows (s); ``window_s`` (no overlap) by default.
        rate_hz: Rate to resample to (no recording may be slower); by default the
            recordings' own rate, which must then agree within :data:`RATE_TOLERANCE`.
        labels: Class names in model order (a model's); the folder names by default.
            With ``labels`` (evaluating a model), a recording with a single signal column
            is read whatever its name.

    Raises:
        RecordingError: Unreadable or unfit recordings (see :func:`recording_rate`,
            :func:`check_rate`, :func:`recording_signal`), or a label folder none of whose
            recordings holds one window.
    """
    files = list_dataset(root)
    names = tuple(files) if labels is None else tuple(labels)
    unknown = sorted(set(files) - set(names))
    if unknown:
        raise RecordingError(f"{root}: labels {unknown} are not among the classes {list(names)}")
    recs = [(lab, read_recording(f)) for lab in files for f in files[lab]]
    rates = [recording_rate(rec) for _, rec in recs]
    rate = _dataset_rate(rates, recs, root) if rate_hz is None else float(rate_hz)
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate {rate_hz!r} Hz must be a positive number")
    window, hop = window_samples(window_s, hop_s, rate)
    cols = _dataset_channels(recs, root, channel)
    if cols is not None and len(cols) == 1:
        channel, cols = cols[0], None
    elif cols is None:
        channel = _first_channel(recs, root) if channel is None else channel
    else:
        channel = ",".join(cols)
    chunks, ys, groups, speeds, sources, starts = [], [], [], [], [], []
    for i, ((lab, rec), own) in enumerate(zip(recs, rates, strict=True)):
        _not_slower(rec, own, rate)
        if cols is None:
            x = recording_signal(rec, channel, only_column_ok=labels is not None)
            w, st = windows_of(rec.t, x, rate_hz=rate, window=window, hop=hop)
        else:
            xs = recording_signals(rec, cols)
            w, st = multi_windows(rec.t, xs, rate_hz=rate, window=window, hop=hop)
        chunks.append(w)
        ys.append(np.full(len(w), names.index(lab)))
        groups.append(np.full(len(w), i))
        speeds.append(np.full(len(w), recording_speed(rec)))
        sources.append(str(rec.source))
        starts.append(st)
    ws = WindowSet(
        np.concatenate(chunks),
        np.concatenate(ys).astype(int),
        names,
        np.concatenate(groups).astype(int),
        np.concatenate(speeds),
        sources,
        rate,
        np.concatenate(starts),
        channel,
        [dict(rec.meta) for _, rec in recs],
    )
    if len(ws) == 0:
        raise RecordingError(f"{root}: recordings are shorter than one window ({window_s} s)")
    empty = sorted(set(files) - {names[k] for k in np.unique(ws.labels)})
    if empty:
        raise RecordingError(
            f"{root}: no windows of {empty}: their recordings are shorter than one window "
            f"({window_s:g} s); record longer, pass a shorter window, or move them away"
        )
    return ws


def _dataset_channels(recs, root, channel) -> tuple[str, ...] | None:
    """The columns ``channel`` names (``"all"``: every signal column of the first
    recording, which all recordings must have); None for one plain column name."""
    if channel is None or (isinstance(channel, str) and "," not in channel and channel != "all"):
        return None
    if channel == "all":
        first = tuple(recs[0][1].columns)
        for _, rec in recs:
            if tuple(rec.columns) != first:
                raise RecordingError(
                    f"{root}: --channel all needs the same columns in every recording; "
                    f"{Path(str(recs[0][1].source)).name} has {list(first)}, "
                    f"{Path(str(rec.source)).name} has {list(rec.columns)}: name the columns"
                )
        return first
    try:
        return channel_names(channel)
    except ValueError as err:
        raise RecordingError(f"{root}: {err}") from None


def _dataset_rate(rates: list[float], recs: list[tuple[str, Recording]], root) -> float:
    """The recordings' common rate (the first one's), refused when they differ: windows
    of one length in samples would then span different times and bands."""
    rates = np.asarray(rates)
    lo, hi = int(np.argmin(rates)), int(np.argmax(rates))
    if rates[hi] > rates[lo] * (1 + RATE_TOLERANCE):
        raise RecordingError(
            f"{root}: recordings are sampled at {rates[lo]:.4g} Hz "
            f"({Path(str(recs[lo][1].source)).name}) to {rates[hi]:.4g} Hz "
            f"({Path(str(recs[hi][1].source)).name}): pass --rate (at most {rates[lo]:.4g}) "
            "to resample them all to one rate"
        )
    return float(rates[0])


def recorded_whiskers(ws: WindowSet) -> dict[str, str]:
    """``whisker`` metadata of each recording that has it: ``source → whisker name``."""
    return {src: str(m["whisker"]) for src, m in zip(ws.sources, ws.metas or [], strict=False)
            if "whisker" in m}  # fmt: skip


def recorded_amplifier(metas: list[dict], default: float = 1.0) -> float:
    """The recordings' common ``amplifier`` metadata (the sensor amplifier's gain on top of
    the whisker record's Hall gain); ``default`` when none says.

    Raises:
        RecordingError: The recordings disagree, or a value is not a positive number.
    """
    values = set()
    for m in metas:
        if "amplifier" in m:
            try:
                a = float(m["amplifier"])
            except ValueError:
                a = float("nan")
            if not (np.isfinite(a) and a > 0):
                raise RecordingError(f"amplifier {m['amplifier']!r} is not a positive number")
            values.add(a)
    if len(values) > 1:
        raise RecordingError(
            f"the recordings were made through amplifiers of different gains {sorted(values)}: "
            "one model takes one sensor chain"
        )
    return values.pop() if values else default


#: Fastest plausible robot speed (m/s), as the stream's (``whiskerid.hw``): a ground robot
#: carrying a whisker moves at up to a few metres per second; more is a unit error (mm/s,
#: km/h) or a corrupt value, and would only change the labels.
MAX_SPEED_MPS = 5.0


def check_speed(speed) -> None:
    """Refuse speeds that are not positive, finite and plausible (m/s, at most
    :data:`MAX_SPEED_MPS`): the speed-normalised features divide by them."""
    v = np.asarray(speed, dtype=float)
    ok = np.isfinite(v) & (v > 0) & (v <= MAX_SPEED_MPS)
    if not ok.all():
        bad = v[~ok].ravel()[0]
        raise ValueError(
            f"speed {bad:g} m/s: the robot speed must be a positive number of metres per "
            f"second, at most {MAX_SPEED_MPS:g} (a larger one is a unit error: mm/s, km/h?)"
        )


def recording_speed(rec: Recording) -> float:
    """``speed_mps`` (m/s) from the metadata; NaN when absent.

    Raises:
        RecordingError: present but not a positive finite number.
    """
    if "speed_mps" not in rec.meta:
        return float("nan")
    try:
        v = float(rec.meta["speed_mps"])
    except ValueError:
        v = float("nan")
    if not (np.isfinite(v) and 0 < v <= MAX_SPEED_MPS):
        raise RecordingError(
            f"{rec.source or 'recording'}: speed_mps {rec.meta['speed_mps']!r} is not a "
            f"positive number of metres per second up to {MAX_SPEED_MPS:g} (a unit error?)"
        )
    return v
