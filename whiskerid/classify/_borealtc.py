"""Loader for the BorealTC IMU recordings (a real terrain-classification benchmark).

``ROOT/<TERRAIN>/imu_XX.csv``: a Husky A200 robot on ASPHALT, FLOORING, ICE, SANDY_LOAM and
SNOW, one file per run, columns ``time, wx, wy, wz, ax, ay, az`` at 100 Hz (``az``
vertical, m/s²; ``w*`` rad/s). By default runs become windows of the vertical acceleration,
like a whisker's single signal; ``channels="all"`` keeps all six IMU axes as a
multi-channel window ``(6, window)`` (closer to the inputs of the published results). The
speed is unknown, so speed-normalised features are not used.
"""

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io import RecordingError
from ._dataset import WindowSet, cut_windows

DEFAULT_ROOT = Path(__file__).resolve().parents[3] / "shared" / "data" / "borealtc"
IMU_CHANNELS = ("wx", "wy", "wz", "ax", "ay", "az")


def load_borealtc(
    root: str | Path = DEFAULT_ROOT,
    *,
    channel: str | Sequence[str] = "az",
    window_s: float = 1.0,
    hop_s: float | None = None,
    rate_hz: float = 100.0,
    max_runs: int | None = None,
) -> WindowSet:
    """Windows of IMU channels of every BorealTC run, labelled by terrain folder.

    Args:
        root: The ``borealtc`` folder.
        channel: A column (``az``: vertical acceleration, the default), a list of columns,
            or ``"all"`` for the six IMU axes; several give windows ``(n, channels,
            window)``.
        window_s: Window length (s).
        hop_s: Step between windows (s); ``window_s`` (no overlap) by default.
        rate_hz: Rate to resample the timestamps onto (the IMU's 100 Hz).
        max_runs: Read at most this many runs per terrain (quick checks).
    """
    root = Path(root)
    terrains = sorted(d.name for d in root.iterdir() if d.is_dir()) if root.is_dir() else []
    if not terrains:
        raise RecordingError(f"{root}: no BorealTC terrain folders")
    cols = (
        IMU_CHANNELS
        if channel == "all"
        else (channel,)
        if isinstance(channel, str)
        else tuple(channel)
    )
    window = round(window_s * rate_hz)
    hop = window if hop_s is None else max(round(hop_s * rate_hz), 1)
    wins, labels, recs, sources, starts = [], [], [], [], []
    for k, terrain in enumerate(terrains):
        files = sorted((root / terrain).glob("imu_*.csv"))[:max_runs]
        for f in files:
            data = np.genfromtxt(f, delimiter=",", names=True)
            missing = [c for c in cols if c not in data.dtype.names]
            if missing:
                raise RecordingError(f"{f}: no column(s) {missing}")
            t = data["time"]
            xs = np.stack([data[c] for c in cols])
            ok = np.isfinite(t) & np.isfinite(xs).all(axis=0)
            t, xs = t[ok], xs[:, ok]
            keep = np.concatenate([[True], np.diff(t) > 0])  # drop repeated timestamps
            w = np.stack(
                [
                    cut_windows(t[keep], x[keep], rate_hz=rate_hz, window=window, hop=hop)
                    for x in xs
                ],
                axis=1,
            )  # (n, channels, window)
            wins.append(w[:, 0] if len(cols) == 1 else w)
            labels.append(np.full(len(w), k))
            recs.append(np.full(len(w), len(sources)))
            sources.append(str(f))
            starts.append(np.arange(len(w)) * hop / rate_hz)
    n = sum(len(w) for w in wins)
    return WindowSet(
        np.concatenate(wins),
        np.concatenate(labels).astype(int),
        tuple(terrains),
        np.concatenate(recs).astype(int),
        np.full(n, np.nan),
        sources,
        rate_hz,
        np.concatenate(starts),
    )
