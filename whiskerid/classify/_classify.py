"""Terrain classification: labelled windows, training, evaluation and model files.

* A dataset is a folder ``ROOT/<label>/<recording>.csv`` (NOTES §6). Each recording is
  resampled to one uniform rate (from its ``rate_hz`` metadata or its timestamps: a Pi's
  are not uniform) and cut into windows (1 s and no overlap by default, as the paper);
  a recording's ``speed_mps`` metadata, when present, goes with its windows.
* :func:`train_classifier` computes features (:mod:`._features`), standardises them and
  trains the MLP (:mod:`._mlp`) with early stopping on validation *recordings* (windows of
  one recording are strongly correlated; a random window split would flatter the
  validation loss).
* Honest evaluation (NOTES §6): :func:`split_by_recording` (no recording's windows in both
  train and test) and the paper's protocol :func:`paper_protocol` (random 75/25 window
  split, 20 repeats) for comparability.
* :class:`ClassifierModel` is what a stream calls: :meth:`ClassifierModel.predict_window`
  (one window → label and confidence; jitted, well under a millisecond warm) and
  :meth:`ClassifierModel.predict_windows` (a batch). Model files are a folder with
  ``model.json`` (format, versions, feature spec, rate, window, hop, labels, normalisation,
  network sizes) and ``weights.npz``; no pickle anywhere.
"""

import functools
import json
import sys
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from .._version import __version__
from ..io._recording import Recording, RecordingError, check_samples, read_recording
from ._features import FeatureSpec, batch_features, compute_features, window_features
from ._mlp import (
    MLP,
    TrainConfig,
    default_config,
    from_arrays,
    pad_rows,
    to_arrays,
    train_mlp,
)

MODEL_FORMAT = "whiskerid.classifier/2"  # /2: spectral-shape and envelope features
MODEL_JSON = "model.json"
MODEL_WEIGHTS = "weights.npz"
#: Windows a ``fitted`` model's label rests on by default (see :func:`fuse_context`):
#: chosen on a separately seeded synthetic dataset, split by recording, where three 1 s
#: windows took per-window errors from about 7 % to about 4 % (five: 3.7 %, eight: 3.5 %)
#: for a label that lags a change of terrain by at most 2 s.
CONTEXT_WINDOWS = 3
RECORDING_SUFFIXES = (".csv", ".npz", ".npy")
#: Fewest samples a window may hold: a spectrum of fewer bins says nothing of a terrain.
MIN_WINDOW = 16
#: How far apart the rates of one dataset's recordings, or of a recording and the rate
#: asked for, may be (one ADS1115's oscillator is good to a few per cent).
RATE_TOLERANCE = 0.05
#: How far ``rate_hz`` metadata and the timestamps may disagree (the ADS1115's rate is
#: specified to ±10 %; a time column in ms is off by a factor of 1000).
RATE_METADATA_TOLERANCE = 0.15
#: Timestamp steps longer than this many median steps are gaps that windows never span.
GAP_STEPS = 10.0


class ModelError(ValueError):
    """A classifier model file that is missing, corrupt or from an incompatible version."""


# --------------------------------------------------------------------------- windows
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
        channel: The recorded column the windows come from, where known.
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


def timestamp_rate(t: np.ndarray) -> float:
    """Sample rate from timestamps (Hz): one over the median step."""
    return 1.0 / float(np.median(np.diff(np.asarray(t, dtype=float))))


def recording_rate(rec: Recording) -> float:
    """A recording's sample rate: its ``rate_hz`` metadata, else the median timestamp step.

    Raises:
        RecordingError: ``rate_hz`` is not a positive number, or disagrees with the
            timestamps by more than :data:`RATE_METADATA_TOLERANCE` (time in ms or ns,
            or the wrong rate written down: either would silently shift every spectrum).
    """
    src = rec.source or "recording"
    stamped = timestamp_rate(rec.t)
    if "rate_hz" not in rec.meta:
        return stamped
    try:
        rate = float(rec.meta["rate_hz"])
    except ValueError:
        rate = float("nan")
    if not (np.isfinite(rate) and rate > 0):
        raise RecordingError(f"{src}: rate_hz {rec.meta['rate_hz']!r} is not a positive number")
    if abs(stamped / rate - 1) > RATE_METADATA_TOLERANCE:
        raise RecordingError(
            f"{src}: rate_hz says {rate:g} Hz but the timestamps step by "
            f"{1 / stamped:.4g} ({stamped:.4g} Hz): the time column must be in seconds "
            "(convert it), or correct rate_hz"
        )
    return rate


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
        channel: Column to classify (the first signal column by default).
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
    channel = _first_channel(recs, root) if channel is None else channel
    chunks, ys, groups, speeds, sources, starts = [], [], [], [], [], []
    for i, ((lab, rec), own) in enumerate(zip(recs, rates, strict=True)):
        _not_slower(rec, own, rate)
        x = recording_signal(rec, channel, only_column_ok=labels is not None)
        w, st = windows_of(rec.t, x, rate_hz=rate, window=window, hop=hop)
        chunks.append(w)
        ys.append(np.full(len(w), names.index(lab)))
        groups.append(np.full(len(w), i))
        speeds.append(np.full(len(w), _speed(rec)))
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


def check_speed(speed) -> None:
    """Refuse speeds that are not positive and finite (m/s): the speed-normalised features
    divide by them."""
    v = np.asarray(speed, dtype=float)
    if not (np.isfinite(v).all() and (v > 0).all()):
        bad = v[~(np.isfinite(v) & (v > 0))].ravel()[0]
        raise ValueError(f"speed {bad:g} m/s: the robot speed must be a positive number")


def _speed(rec: Recording) -> float:
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
    if not (np.isfinite(v) and v > 0):
        raise RecordingError(
            f"{rec.source or 'recording'}: speed_mps {rec.meta['speed_mps']!r} is not a "
            "positive number of metres per second"
        )
    return v


# --------------------------------------------------------------------------- splits
def _strata(ws: WindowSet) -> np.ndarray:
    """Stratum per window: label, and speed where known (so splits cover every speed)."""
    sp = np.where(np.isfinite(ws.speeds), np.round(ws.speeds, 3), -1.0)
    return ws.labels * 100_000 + np.round(sp * 1000).astype(int)


def grouped_split(ws: WindowSet, fraction: float, seed: int) -> np.ndarray:
    """Mask of windows in a held-out set of whole recordings, about ``fraction`` per stratum.

    Strata with a single recording are split by windows instead (contiguous blocks would
    still be correlated, so this only happens when there is no other choice).
    """
    rng = np.random.default_rng(seed)
    held = np.zeros(len(ws), bool)
    strata = _strata(ws)
    for s in np.unique(strata):
        in_s = strata == s
        recs = np.unique(ws.recording[in_s])
        if recs.size >= 2:
            k = min(max(round(fraction * recs.size), 1), recs.size - 1)
            pick = rng.choice(recs, k, replace=False)
            held |= in_s & np.isin(ws.recording, pick)
        else:
            idx = np.flatnonzero(in_s)
            k = min(max(round(fraction * idx.size), 1), max(idx.size - 1, 0))
            held[rng.choice(idx, k, replace=False)] = True
    return held


def split_by_recording(ws: WindowSet, test_fraction: float = 0.25, seed: int = 0):
    """``(train, test)`` with no recording in both (stratified by label and speed)."""
    test = grouped_split(ws, test_fraction, seed)
    return ws.subset(~test), ws.subset(test)


def recording_folds(ws: WindowSet, folds: int, seed: int = 0) -> np.ndarray:
    """Fold (``0 … folds − 1``) of every window for cross-validation by recording.

    Whole recordings go to one fold each, stratified: the recordings of each stratum
    (label, and speed where known) are shuffled and dealt to the folds in turn, the
    dealing running on across strata, so every fold gets about ``1/folds`` of each
    stratum and ``folds`` equal to the number of recordings is leave-one-recording-out.

    Raises:
        ValueError: ``folds`` below 2 or above the number of recordings.
    """
    recs = np.unique(ws.recording)
    if not 2 <= folds <= recs.size:
        raise ValueError(
            f"folds = {folds} for {recs.size} recordings: pass 2 to {recs.size} "
            f"({recs.size}: leave one recording out)"
        )
    rng = np.random.default_rng(seed)
    strata = _strata(ws)
    first = np.array([np.flatnonzero(ws.recording == r)[0] for r in recs])
    order = np.concatenate(
        [rng.permutation(recs[strata[first] == s]) for s in np.unique(strata[first])]
    )
    dealt = (np.arange(order.size) + rng.integers(folds)) % folds
    fold_of = dict(zip(order.tolist(), dealt.tolist(), strict=True))
    return np.array([fold_of[r] for r in ws.recording.tolist()], dtype=int)


# --------------------------------------------------------------------------- context
def fuse_context(
    proba: np.ndarray, recording: np.ndarray, start_s: np.ndarray, *, lookback_s: float
) -> np.ndarray:
    """Causal evidence fusion: each window's probabilities from itself and the windows
    before it.

    The terrain under a robot persists for seconds while one window holds a second of it:
    a brick joint or a soil clod may fall between windows, a window of carpet may look
    like tiles. Window ``i`` is labelled from every window ``j`` of the same recording
    (or stream) that started in ``[start_i − lookback_s, start_i]``: the mean of their
    log-probabilities, renormalised — the product of their likelihoods, as if the windows
    were independent (naive Bayes), tempered by their number so that confidences stay
    those of one window. Only past windows are used, so a stream can do the same; the
    price is a label that lags a change of terrain by up to ``lookback_s``.

    Args:
        proba: Per-window class probabilities, shape ``(n, classes)``.
        recording: Recording of each window, shape ``(n,)``; windows never borrow
            evidence across recordings.
        start_s: Start time of each window in its recording (s), shape ``(n,)``.
        lookback_s: How far back to fuse (s); 0 returns ``proba`` unchanged.

    Returns:
        Fused probabilities, shape ``(n, classes)``.
    """
    proba = np.asarray(proba, dtype=float)
    if lookback_s < 0:
        raise ValueError(f"lookback_s = {lookback_s!r} must be >= 0")
    if lookback_s == 0 or len(proba) == 0:
        return proba
    logp = np.log(np.maximum(proba, 1e-12))
    out = np.empty_like(logp)
    recording, start_s = np.asarray(recording), np.asarray(start_s, dtype=float)
    for r in np.unique(recording):
        idx = np.flatnonzero(recording == r)
        idx = idx[np.argsort(start_s[idx], kind="stable")]
        s = start_s[idx]
        c = np.vstack([np.zeros(logp.shape[1]), np.cumsum(logp[idx], axis=0)])
        lo = np.searchsorted(s, s - lookback_s - 1e-9, side="left")
        hi = np.arange(1, idx.size + 1)
        out[idx] = (c[hi] - c[lo]) / (hi - lo)[:, None]
    out = np.exp(out - out.max(axis=1, keepdims=True))
    return out / out.sum(axis=1, keepdims=True)


# --------------------------------------------------------------------------- model
def _mean_proba(nets, z):
    """The ensemble's mean class probabilities of standardised features ``z`` (one row or
    a batch)."""
    if z.ndim == 1:
        return sum(jax.nn.softmax(n(z)) for n in nets) / len(nets)
    return sum(jax.nn.softmax(jax.vmap(n)(z), axis=-1) for n in nets) / len(nets)


@functools.partial(jax.jit, static_argnums=0)
def _batch_proba(structure, numbers, nets, mean, std, windows, speeds):
    """Class probabilities of a batch of windows: compiled once per feature structure,
    network sizes and (padded) batch shape, for every model of that architecture."""
    feats = batch_features(structure, numbers, windows, speeds)
    return _mean_proba(nets, (feats.astype(jnp.float32) - mean) / std)


@functools.partial(jax.jit, static_argnums=0)
def _window_proba(structure, numbers, nets, mean, std, window, speed):
    """Class probabilities of one window (see :func:`_batch_proba`)."""
    feats = window_features(structure, window, speed, numbers)
    return _mean_proba(nets, (feats.astype(jnp.float32) - mean) / std)


class ClassifierModel:
    """A trained terrain classifier: feature spec, normalisation, network, labels.

    The online stream calls :meth:`predict_window` on each new window of ``window``
    samples at ``rate_hz`` (uniformly resampled), or :meth:`predict_windows` on a batch.
    ``net`` is one network or a sequence of them (an ensemble: their class probabilities
    are averaged).

    ``context_s`` is how much signal a label rests on: the window itself and the windows
    that started up to ``context_s − window_s`` before it, fused by :func:`fuse_context`
    (recordings, evaluation and the online stream alike). Equal to the window length,
    every window is labelled on its own, as in the paper.
    """

    def __init__(self, spec: FeatureSpec, labels, mean, std, net: "MLP | list[MLP]", *,
                 hop: int, channel: str | None = None, info: dict | None = None,
                 context_s: float | None = None):  # fmt: skip
        self.spec = spec
        self.labels = tuple(labels)
        self.mean = np.asarray(mean, dtype=np.float32)
        self.std = np.asarray(std, dtype=np.float32)
        self.nets = (net,) if isinstance(net, MLP) else tuple(net)
        self.net = self.nets[0]
        self.hop = int(hop)
        self.channel = channel
        self.info = dict(info or {})
        self.context_s = self.window_s if context_s is None else context_s
        # Device-resident arguments of the module-level compiled functions, which depend on
        # the architecture only: a warm call is one dispatch and one small transfer.
        self._structure = spec.structure()
        self._args = (spec.numbers(), self.nets, jnp.asarray(self.mean), jnp.asarray(self.std))

    @property
    def rate_hz(self) -> float:
        """Sample rate the model expects (Hz)."""
        return self.spec.rate_hz

    @property
    def window(self) -> int:
        """Samples per window."""
        return self.spec.window

    @property
    def window_s(self) -> float:
        """Window length (s)."""
        return self.spec.window / self.spec.rate_hz

    @property
    def context_s(self) -> float:
        """Signal a label rests on (s), at least one window (see the class docstring)."""
        return self._context_s

    @context_s.setter
    def context_s(self, value: float) -> None:
        self._context_s = check_context(value, self.window_s)

    @property
    def lookback_s(self) -> float:
        """How far back a label looks for windows to fuse (s): ``context_s − window_s``."""
        return max(self.context_s - self.window_s, 0.0)

    def fuse(self, proba, recording, start_s) -> np.ndarray:
        """:func:`fuse_context` with this model's look-back."""
        return fuse_context(proba, recording, start_s, lookback_s=self.lookback_s)

    @property
    def needs_speed(self) -> bool:
        """Whether windows must come with the robot speed."""
        return self.spec.kind == "fitted" and self.spec.use_speed

    def _speeds(self, n: int, speeds) -> np.ndarray:
        if speeds is None:
            if self.needs_speed:
                raise ValueError("this model needs the robot speed (m/s) of each window")
            return np.full(n, np.nan)
        speeds = np.broadcast_to(np.asarray(speeds, dtype=float), (n,))
        if self.needs_speed:
            check_speed(speeds)
        return speeds

    def predict_proba(self, windows, speeds=None) -> np.ndarray:
        """Class probabilities, shape ``(n, classes)``, for windows ``(n, window)``."""
        windows = np.asarray(windows, dtype=float)
        if windows.shape[1:] != self.spec.window_shape:
            shape = ", ".join(map(str, ("n", *self.spec.window_shape)))
            raise ValueError(f"windows must have shape ({shape}), got {windows.shape}")
        speeds = self._speeds(len(windows), speeds)
        n = len(windows)
        if n == 0:
            return np.zeros((0, len(self.labels)), np.float32)
        # Padded (repeating the last window) to a size class: one compilation serves
        # recordings and datasets of many lengths.
        rows = np.minimum(np.arange(pad_rows(n)), n - 1)
        p = _batch_proba(self._structure, *self._args, windows[rows], speeds[rows])
        return np.asarray(p)[:n]

    def predict_windows(self, windows, speeds=None) -> tuple[np.ndarray, np.ndarray]:
        """Class index and confidence (its probability) per window."""
        p = self.predict_proba(windows, speeds)
        idx = np.argmax(p, axis=1)
        return idx, p[np.arange(len(idx)), idx]

    def predict_window(self, samples, speed: float | None = None) -> tuple[str, float]:
        """Label and confidence of one window of ``window`` samples at ``rate_hz``, on its
        own (no context; the online stream fuses :meth:`window_proba` itself).

        This is the stable entry point for online use: jitted (compiled on the first call),
        well under a millisecond per call afterwards.
        """
        p = self.window_proba(samples, speed)
        k = int(np.argmax(p))
        return self.labels[k], float(p[k])

    def window_proba(self, samples, speed: float | None = None) -> np.ndarray:
        """Class probabilities of one window, shape ``(classes,)`` (see :meth:`predict_window`)."""
        x = np.asarray(samples, dtype=np.float64)
        if x.shape != self.spec.window_shape:
            raise ValueError(
                f"a window has {self.window} samples (shape {self.spec.window_shape}), "
                f"got shape {x.shape}"
            )
        if speed is None and self.needs_speed:
            raise ValueError("this model needs the robot speed (m/s) of each window")
        if self.needs_speed:
            check_speed(speed)
        v = np.float64(np.nan if speed is None else speed)
        return np.asarray(_window_proba(self._structure, *self._args, x, v))

    def classify_recording(self, rec: Recording, *, speed: float | None = None) -> dict:
        """Labels of every window of a recording, and one for the whole (mean probability).

        Each window's ``label`` and ``confidence`` fuse its context (``context_s``);
        ``window_label`` and ``window_confidence`` are the window's own. ``channel`` is the
        column classified: the model's, or a recording's only signal column whatever its
        name (an NPY recording's is ``signal``).
        """
        if self.spec.channels != 1:
            raise ValueError("classify_recording reads one channel; this model takes several")
        if self.channel is not None and self.channel not in rec.columns and len(rec.columns) > 1:
            raise RecordingError(
                f"{rec.source or 'recording'}: no column {self.channel!r}, the one the model "
                f"was trained on (columns: {list(rec.columns)}): rename the column, or "
                "train a model on one of these"
            )
        used = signal_column(rec, self.channel, only_column_ok=True)
        x = recording_signal(rec, used)
        check_rate(rec, self.rate_hz)
        w, starts = windows_of(rec.t, x, rate_hz=self.rate_hz, window=self.window, hop=self.hop)
        if len(w) == 0:
            raise RecordingError(
                f"{rec.source}: shorter than one window ({self.window / self.rate_hz:g} s)"
            )
        if speed is None and self.needs_speed:
            speed = _speed(rec)
            if not np.isfinite(speed):
                raise RecordingError(
                    f"{rec.source}: the model needs the robot speed; add '# speed_mps: V' "
                    "to the recording or pass --speed"
                )
        p = self.predict_proba(w, None if speed is None else np.full(len(w), speed))
        fused = self.fuse(p, np.zeros(len(w), int), starts)
        own, idx = np.argmax(p, axis=1), np.argmax(fused, axis=1)
        mean = p.mean(axis=0)
        return {
            "label": self.labels[int(np.argmax(mean))],
            "confidence": float(mean.max()),
            "channel": used,
            "context_s": self.context_s,
            "windows": [
                {"start_s": round(float(starts[i]), 6), "label": self.labels[k],
                 "confidence": round(float(fused[i, k]), 4),
                 "window_label": self.labels[own[i]],
                 "window_confidence": round(float(p[i, own[i]]), 4)}
                for i, k in enumerate(idx)
            ],
        }  # fmt: skip

    # ----------------------------------------------------------------------- files
    def header(self) -> dict:
        """The JSON header of a model file."""
        return {
            "format": MODEL_FORMAT,
            "whiskerid_version": __version__,
            "features": self.spec.to_dict(),
            "rate_hz": self.rate_hz,
            "window": self.window,
            "window_s": self.window / self.rate_hz,
            "hop": self.hop,
            "context_s": self.context_s,
            "context": "a label fuses the windows that started up to context_s - window_s "
                       "before it (mean log-probability, renormalised)",
            "channel": self.channel,
            "labels": list(self.labels),
            "normalisation": {"mean": self.mean.tolist(), "std": self.std.tolist()},
            "network": {"sizes": self.net.sizes, "hidden_activation": "relu",
                        "output": "softmax", "members": len(self.nets),
                        "combine": "mean of the members' probabilities"},
            "training": self.info,
        }  # fmt: skip

    def save(self, path: str | Path) -> Path:
        """Write ``path/model.json`` and ``path/weights.npz``."""
        path = Path(path)
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} is a file; a model is a folder: give a folder name")
        path.mkdir(parents=True, exist_ok=True)
        arrays = {f"m{j}_{k}": a for j, n in enumerate(self.nets) for k, a in to_arrays(n).items()}
        np.savez(path / MODEL_WEIGHTS, **arrays)
        (path / MODEL_JSON).write_text(json.dumps(self.header(), indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ClassifierModel":
        """Read a model folder; refuses corrupt or incompatible files with a clear message."""
        path = Path(path)
        head_file = path / MODEL_JSON if path.is_dir() else path
        if not head_file.is_file():
            raise ModelError(
                f"{path}: no classifier model here (expected a folder with {MODEL_JSON})"
            )
        try:
            head = json.loads(head_file.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise ModelError(f"{head_file}: corrupt model header (not JSON: {err})") from None
        if not isinstance(head, dict) or head.get("format") != MODEL_FORMAT:
            got = head.get("format") if isinstance(head, dict) else None
            raise ModelError(
                f"{head_file}: incompatible model format {got!r}; this whiskerid "
                f"({__version__}) reads {MODEL_FORMAT!r}: retrain with 'whiskerid train'"
            )
        try:
            spec = FeatureSpec.from_dict(head["features"])
            labels = [str(s) for s in head["labels"]]
            mean = np.asarray(head["normalisation"]["mean"], dtype=float)
            std = np.asarray(head["normalisation"]["std"], dtype=float)
            sizes = [int(s) for s in head["network"]["sizes"]]
            hop = int(head["hop"])
            if hop < 1:
                raise ValueError(f"hop {hop} < 1")
            if len(set(labels)) != len(labels):
                raise ValueError(f"repeated labels {labels}")
            context_s = float(head.get("context_s", spec.window / spec.rate_hz))
            if not np.isfinite(context_s):
                raise ValueError(f"context_s {context_s}")
            members = int(head["network"].get("members", 1))
            if members < 1:
                raise ValueError(f"members {members} < 1")
        except (KeyError, TypeError, ValueError) as err:
            raise ModelError(f"{head_file}: corrupt model header ({err!r})") from None
        n = spec.n_features
        if sizes[0] != n or sizes[-1] != len(labels) or mean.shape != (n,) or std.shape != (n,):
            raise ModelError(
                f"{head_file}: inconsistent model (features {n}, network {sizes}, "
                f"{len(labels)} labels, normalisation {mean.shape})"
            )
        if not (np.isfinite(mean).all() and np.isfinite(std).all() and (std > 0).all()):
            raise ModelError(f"{head_file}: corrupt normalisation (non-finite or zero std)")
        weights = head_file.parent / MODEL_WEIGHTS
        try:
            with np.load(weights, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            nets = []
            for j in range(members):
                prefix = f"m{j}_"
                mine = {k[len(prefix) :]: a for k, a in arrays.items() if k.startswith(prefix)}
                nets.append(from_arrays(mine, sizes))
        except FileNotFoundError:
            raise ModelError(f"{weights}: missing model weights") from None
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
            raise ModelError(f"{weights}: corrupt model weights ({err})") from None
        try:
            return cls(spec, labels, mean, std, nets, hop=hop, channel=head.get("channel"),
                       info=head.get("training", {}), context_s=context_s)  # fmt: skip
        except ValueError as err:
            raise ModelError(f"{head_file}: corrupt model header ({err})") from None


# --------------------------------------------------------------------------- training
def default_spec(
    ws: WindowSet, features: str = "fitted", *, use_speed: bool | None = None
) -> FeatureSpec:
    """Feature settings for a window set: its rate and window; speed features and absolute
    octave levels when the speed is known.

    The spatial-frequency range is the one every training speed covers: bins from
    ``2 Δf`` at the slowest speed to Nyquist at the fastest.
    """
    window = ws.windows.shape[-1]
    channels = ws.windows.shape[1] if ws.windows.ndim == 3 else 1
    if features == "paper":
        return FeatureSpec(kind="paper", rate_hz=ws.rate_hz, window=window, channels=channels)
    use = ws.has_speed if use_speed is None else use_speed
    if use and not ws.has_speed:
        raise ValueError("speed features need speed_mps on every recording")
    # Absolute octave levels only with the speed: without it a level says as much about
    # how fast a run went as about the ground (BorealTC, runs held out: 1-4 points worse
    # with them; the synthetic set, where the speed is known: 1 point better).
    spec = FeatureSpec(kind="fitted", rate_hz=ws.rate_hz, window=window, octave_bands=use,
                       use_speed=use, channels=channels)  # fmt: skip
    if use:
        df, nyq = ws.rate_hz / window, ws.rate_hz / 2
        lo, hi = 2 * df / float(ws.speeds.min()), nyq / float(ws.speeds.max())
        if not lo < hi / 2:
            lo = hi / 10
        spec = replace(spec, spatial_lo=float(lo), spatial_hi=float(hi))
    return spec


def features_of(ws: WindowSet, spec: FeatureSpec) -> np.ndarray:
    """Features of every window, shape ``(n, spec.n_features)``."""
    speeds = ws.speeds if (spec.kind == "fitted" and spec.use_speed) else None
    return np.asarray(compute_features(spec, ws.windows, speeds))


def check_context(context_s: float, window_s: float) -> float:
    """``context_s`` as a float, refused (ValueError) when shorter than one window."""
    context_s = float(context_s)
    if not np.isfinite(context_s):
        raise ValueError(f"context {context_s:g} s: pass a finite number of seconds")
    if not context_s >= window_s - 1e-9:
        raise ValueError(
            f"context {context_s:g} s is shorter than one window ({window_s:g} s): pass at "
            "least the window length (one window: no fusion)"
        )
    return context_s


def default_context_s(features: str, window_s: float) -> float:
    """Default context of a model: :data:`CONTEXT_WINDOWS` windows for ``fitted``, one
    (each window on its own, as in the paper) for ``paper``."""
    return window_s * (CONTEXT_WINDOWS if features == "fitted" else 1)


def fit_on_features(
    feats: np.ndarray, ws: WindowSet, spec: FeatureSpec, config: TrainConfig,
    *, val_fraction: float = 0.2, context_s: float | None = None,
) -> ClassifierModel:  # fmt: skip
    """Train on precomputed features of ``ws`` (validation: held-out recordings).

    Early stopping on held-out recordings chooses the number of epochs; with
    ``config.refit`` (default) the network is then trained again on all of ``ws`` for that
    many epochs. With ``config.ensemble = K > 1``, K networks are trained, each with its
    own seed and its own validation recordings, and their probabilities are averaged.
    ``context_s`` goes into the model (see :class:`ClassifierModel`); None: each window on
    its own (:func:`train_classifier` applies :func:`default_context_s`).
    """
    if context_s is not None:  # refused before training, not after
        check_context(context_s, spec.window / spec.rate_hz)
    mean = feats.mean(axis=0)
    std = np.maximum(feats.std(axis=0), 1e-6 * (np.abs(mean) + 1.0))
    z = (feats - mean) / std
    nets, runs, refit_epochs = [], [], 0
    for j in range(max(config.ensemble, 1)):
        cfg = replace(config, seed=config.seed + 1000 * j)
        val = grouped_split(ws, val_fraction, cfg.seed + 1)
        n_cls = len(ws.label_names)
        res = train_mlp(z[~val], ws.labels[~val], z[val], ws.labels[val], n_cls, cfg)
        runs.append(res)
        if cfg.refit:  # same padded shape: no new compilation
            res = train_mlp(z, ws.labels, z[:0], ws.labels[:0], n_cls, cfg, epochs=res.best_epoch)
            refit_epochs += res.epochs
        nets.append(res.model)
    info = {"epochs": sum(r.epochs for r in runs), "best_epoch": runs[0].best_epoch,
            "refit_on_all": config.refit, "refit_epochs": refit_epochs,
            "val_loss": round(float(np.mean([r.best_val_loss for r in runs])), 5),
            "val_accuracy": round(float(np.mean([r.val_accuracy for r in runs])), 4),
            "members": len(nets), "train_windows": len(ws) if config.refit else int((~val).sum()),
            "val_windows": int(val.sum()),
            "seed": config.seed, "hidden": list(config.hidden),
            "weight_decay": config.weight_decay, "input_noise": config.input_noise}  # fmt: skip
    return ClassifierModel(spec, ws.label_names, mean, std, nets, hop=ws.windows.shape[-1],
                           info=info, context_s=context_s)  # fmt: skip


def check_classes(ws: WindowSet) -> None:
    """Refuse training data with fewer than two classes or a class without windows (its
    recordings all shorter than one window): a model would learn nothing of it, yet name
    it as a class."""
    counts = np.bincount(ws.labels, minlength=len(ws.label_names))
    if len(ws.label_names) < 2:
        raise ValueError(
            f"a classifier needs at least two terrains; the data have only {list(ws.label_names)}"
        )
    empty = [lab for lab, c in zip(ws.label_names, counts, strict=True) if c == 0]
    if empty:
        window_s = ws.windows.shape[-1] / ws.rate_hz
        raise ValueError(
            f"no windows of {empty}: their recordings are shorter than one window "
            f"({window_s:g} s); record longer or pass a shorter window"
        )


def train_classifier(
    ws: WindowSet,
    *,
    features: str = "fitted",
    config: TrainConfig | None = None,
    use_speed: bool | None = None,
    channel: str | None = None,
    hop: int | None = None,
    context_s: float | None = None,
) -> ClassifierModel:
    """Train a classifier on labelled windows.

    Args:
        ws: Training windows (all of them; a validation part of whole recordings is held
            out inside for early stopping).
        features: ``fitted`` (ours) or ``paper`` (standardise + |FFT|, the paper's network).
        config: Network and training settings; the paper's preset sizes for ``paper``.
        use_speed: Speed-normalised features; by default when every recording has a speed.
        channel: Recorded column the model classifies (kept in the model file); the
            window set's own by default.
        hop: Window step for whole recordings (samples); the window length by default.
        context_s: Signal each label rests on (s), fused over consecutive windows
            (:func:`fuse_context`); :func:`default_context_s` by default.
    """
    if config is None:
        config = default_config(features)
    check_classes(ws)
    spec = default_spec(ws, features, use_speed=use_speed)
    if context_s is None:
        context_s = default_context_s(features, spec.window / spec.rate_hz)
    model = fit_on_features(features_of(ws, spec), ws, spec, config, context_s=context_s)
    model.channel = ws.channel if channel is None else channel
    if hop is not None:
        model.hop = int(hop)
    return model


# --------------------------------------------------------------------------- evaluation
def confusion_matrix(y_true, y_pred, n_classes: int) -> np.ndarray:
    """Counts ``C[i, j]`` of windows of class ``i`` predicted as ``j``."""
    c = np.zeros((n_classes, n_classes), dtype=int)
    np.add.at(c, (np.asarray(y_true), np.asarray(y_pred)), 1)
    return c


def scores(conf: np.ndarray, labels) -> dict:
    """Accuracy, per-class accuracy (recall; None for a class without windows) and the
    confusion matrix as a JSON-able dict."""
    total, rows = conf.sum(), conf.sum(axis=1)
    per = conf.diagonal() / np.maximum(rows, 1)
    return {
        "accuracy": float(conf.trace() / max(total, 1)),
        "per_class": {
            lab: round(float(a), 4) if n else None  # None: no windows of it
            for lab, a, n in zip(labels, per, rows, strict=True)
        },
        "confusion": conf.tolist(),
        "labels": list(labels),
        "n_windows": int(total),
    }


def evaluate(model: ClassifierModel, ws: WindowSet) -> dict:
    """Scores of ``model`` on labelled windows (labels must be among the model's).

    Labels fuse each window's context as the model says (``context_s``); the accuracy of
    every window on its own is reported next to them (``accuracy_per_window``), and that of
    whole-recording labels (:func:`recording_scores`).
    """
    missing = sorted(set(ws.label_names) - set(model.labels))
    if missing:
        raise ValueError(
            f"dataset labels {missing} are not classes of the model {list(model.labels)}"
        )
    y = np.array([model.labels.index(ws.label_names[k]) for k in ws.labels], dtype=int)
    p = model.predict_proba(ws.windows, ws.speeds if model.needs_speed else None)
    return _scores_with_context(model, p, y, ws)


def _scores_with_context(model: ClassifierModel, p: np.ndarray, y: np.ndarray, ws) -> dict:
    fused = model.fuse(p, ws.recording, ws.starts())
    out = scores(confusion_matrix(y, np.argmax(fused, axis=1), len(model.labels)), model.labels)
    out["context_s"] = model.context_s
    out["accuracy_per_window"] = float(np.mean(np.argmax(p, axis=1) == y))
    out.update(recording_scores(p, y, ws, model.labels))
    return out


def recording_scores(proba: np.ndarray, labels: np.ndarray, ws: WindowSet,
                     label_names=None) -> dict:  # fmt: skip
    """Whole-recording labels: the mean of each recording's window probabilities, as
    ``classify`` labels a recording.

    A different task from a label per window: it waits for the end of the recording, and
    there are far fewer recordings than windows to count.

    Args:
        proba: Class probabilities per window of ``ws``.
        labels: True class per window (indices into ``label_names``).
        ws: The windows (their recordings and sources).
        label_names: Class names; ``ws.label_names`` by default.

    Returns:
        ``accuracy_per_recording`` (share of recordings labelled right), ``n_recordings``
        and ``wrong_recordings``: each recording labelled wrong, as ``label/file``, with
        its predicted label and that label's mean probability.
    """
    names = ws.label_names if label_names is None else label_names
    right, wrong = [], []
    for r in np.unique(ws.recording).tolist():
        mean = proba[ws.recording == r].mean(axis=0)
        pred, true = int(np.argmax(mean)), int(labels[ws.recording == r][0])
        right.append(pred == true)
        if pred != true:
            wrong.append({"recording": f"{names[true]}/{Path(ws.sources[r]).name}",
                          "predicted": names[pred],
                          "confidence": round(float(mean[pred]), 4)})  # fmt: skip
    return {"accuracy_per_recording": float(np.mean(right)), "n_recordings": len(right),
            "wrong_recordings": wrong}  # fmt: skip


def format_confusion(conf, labels) -> str:
    """The confusion matrix as a text table (rows: true class; columns: predicted)."""
    conf = np.asarray(conf)
    short = [lab[:9] for lab in labels]
    width = max(9, max(len(s) for s in short))
    lines = ["true \\ pred".ljust(width + 2) + " ".join(s.rjust(width) for s in short) + "  acc"]
    for i, lab in enumerate(short):
        acc = f"{conf[i, i] / conf[i].sum():.3f}" if conf[i].sum() else "    -"  # none seen
        cells = " ".join(str(v).rjust(width) for v in conf[i])
        lines.append(lab.ljust(width + 2) + cells + f"  {acc}")
    return "\n".join(lines)


def plot_confusion(path: str | Path, conf, labels, *, title: str = "") -> Path:
    """Save the row-normalised confusion matrix as a PNG (matplotlib, Agg)."""
    from ..plot._plot import _pyplot, _save

    plt = _pyplot()
    conf = np.asarray(conf, dtype=float)
    frac = conf / np.maximum(conf.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(1.0 + 0.8 * len(labels), 0.6 + 0.7 * len(labels)))
    im = ax.imshow(frac, vmin=0, vmax=1, cmap="Blues")
    for i in range(len(labels)):
        for j in range(len(labels)):
            ax.text(j, i, f"{frac[i, j]:.2f}", ha="center", va="center", fontsize=8,
                    color="white" if frac[i, j] > 0.6 else "black")  # fmt: skip
    ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right")
    ax.set_yticks(range(len(labels)), labels)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(title or f"accuracy {np.trace(conf) / max(conf.sum(), 1):.3f}")
    fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    return _save(fig, path, dpi=120)


def paper_protocol(
    ws: WindowSet,
    *,
    features: str = "paper",
    repeats: int = 20,
    test_fraction: float = 0.25,
    seed: int = 0,
    config: TrainConfig | None = None,
) -> dict:
    """The paper's protocol: random 75/25 *window* split, ``repeats`` times.

    Windows of one recording land on both sides, so this flatters every method; it is
    reported for comparability with the paper's 85.6 %, next to the split by recording.

    Returns:
        Mean and standard deviation of the accuracy, per-class mean accuracy and the
        summed confusion matrix.
    """
    if config is None:
        config = default_config(features)
    spec = default_spec(ws, features)
    feats = features_of(ws, spec)
    rng = np.random.default_rng(seed)
    accs, total = [], np.zeros((len(ws.label_names),) * 2, int)
    for r in range(repeats):
        test = np.zeros(len(ws), bool)
        test[rng.permutation(len(ws))[: round(test_fraction * len(ws))]] = True
        # Random-window validation too, as the paper had no notion of recordings.
        train_ws = replace(ws.subset(~test), recording=np.arange(int((~test).sum())))
        model = fit_on_features(feats[~test], train_ws, spec, replace(config, seed=config.seed + r))
        pred = np.argmax(_proba_from_features(model, feats[test]), axis=1)
        conf = confusion_matrix(ws.labels[test], pred, len(ws.label_names))
        accs.append(conf.trace() / conf.sum())
        total += conf
    out = scores(total, ws.label_names)
    out.update(accuracy_mean=float(np.mean(accs)), accuracy_std=float(np.std(accs)),
               repeats=repeats)  # fmt: skip
    return out


def cross_validate(
    ws: WindowSet,
    *,
    features: str = "fitted",
    folds: int = 5,
    seed: int = 0,
    config: TrainConfig | None = None,
    context_s: float | None = None,
    use_speed: bool | None = None,
    progress: bool = False,
) -> dict:
    """Cross-validation by recording: every recording is tested once, by a model that
    never saw it (:func:`recording_folds`).

    The estimate of how well a classifier trained on all of ``ws`` does on a *new*
    recording, with more of the data in each training set than one 75/25 split and
    without the luck of which recordings were held out. ``folds`` equal to the number of
    recordings is leave-one-recording-out.

    Args:
        ws: Labelled windows.
        features: ``fitted`` or ``paper``.
        folds: Number of folds (2 to the number of recordings).
        seed: Seeds the folds and the networks (fold ``k`` trains with ``seed + k``).
        config: Training settings; :func:`default_config` of ``features`` by default.
        context_s: Signal each label rests on (s); :func:`default_context_s` by default.
        use_speed: Speed-normalised features; by default when every recording has a speed.
        progress: Show a progress bar over the folds (on stderr).

    Returns:
        :func:`scores` of the fused labels pooled over all windows, plus
        ``accuracy_per_window``, :func:`recording_scores` (whole-recording labels),
        ``context_s``, ``folds``, ``accuracy_by_fold`` (fused
        labels) and ``per_recording`` (source and label → fused accuracy).
    """
    check_classes(ws)
    fold = recording_folds(ws, folds, seed)
    config = default_config(features) if config is None else config
    spec = default_spec(ws, features, use_speed=use_speed)
    window_s = spec.window / spec.rate_hz
    context_s = default_context_s(features, window_s) if context_s is None else context_s
    check_context(context_s, window_s)
    feats = features_of(ws, spec)
    proba = np.zeros((len(ws), len(ws.label_names)))
    for k in _progress(range(folds), progress, desc="folds"):
        test = fold == k
        model = fit_on_features(feats[~test], ws.subset(~test), spec,
                                replace(config, seed=config.seed + seed + k))  # fmt: skip
        proba[test] = _proba_from_features(model, feats[test])
    lookback = max(context_s - window_s, 0.0)
    fused = fuse_context(proba, ws.recording, ws.starts(), lookback_s=lookback)
    pred, y = np.argmax(fused, axis=1), ws.labels
    out = scores(confusion_matrix(y, pred, len(ws.label_names)), ws.label_names)
    out.update(
        accuracy_per_window=float(np.mean(np.argmax(proba, axis=1) == y)),
        **recording_scores(proba, y, ws),
        context_s=context_s,
        folds=folds,
        accuracy_by_fold=[round(float(np.mean(pred[fold == k] == y[fold == k])), 4)
                          for k in range(folds)],
        per_recording={
            f"{ws.label_names[y[ws.recording == r][0]]}/{Path(ws.sources[r]).name}":
                round(float(np.mean(pred[ws.recording == r] == y[ws.recording == r])), 4)
            for r in np.unique(ws.recording).tolist()
        },
    )  # fmt: skip
    return out


def _progress(items, show: bool, desc: str):
    return tqdm(items, desc=desc, disable=not show, file=sys.stderr, leave=False)


def _proba_from_features(model: ClassifierModel, feats: np.ndarray) -> np.ndarray:
    from ._mlp import predict_proba

    z = (np.asarray(feats, np.float32) - model.mean) / model.std
    return np.mean([np.asarray(predict_proba(n, z)) for n in model.nets], axis=0)


def evaluate_features(model: ClassifierModel, feats: np.ndarray, ws: WindowSet) -> dict:
    """:func:`evaluate` from precomputed features of ``ws`` (same spec and labels as the
    model)."""
    return _scores_with_context(model, _proba_from_features(model, feats), ws.labels, ws)


#: The public name of :func:`evaluate` (``whiskerid.evaluate_classifier``).
evaluate_classifier = evaluate
