"""Loader for the BorealTC IMU recordings (a real terrain-classification benchmark).

``ROOT/<TERRAIN>/imu_XX.csv``: a Husky A200 robot on ASPHALT, FLOORING, ICE, SANDY_LOAM and
SNOW, one file per run, columns ``time, wx, wy, wz, ax, ay, az`` at 100 Hz (``az``
vertical, m/s²). Runs become windows of the vertical acceleration, like a whisker's
recordings; the speed is unknown, so speed-normalised features are not used.
"""

from pathlib import Path

import numpy as np

from ._classify import WindowSet, cut_windows
from ._io import RecordingError

DEFAULT_ROOT = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "borealtc"


def load_borealtc(
    root: str | Path = DEFAULT_ROOT,
    *,
    channel: str = "az",
    window_s: float = 1.0,
    rate_hz: float = 100.0,
    max_runs: int | None = None,
) -> WindowSet:
    """Windows of one IMU channel of every BorealTC run, labelled by terrain folder.

    Args:
        root: The ``borealtc`` folder.
        channel: Column (``az``: vertical acceleration).
        window_s: Window length (s).
        rate_hz: Rate to resample the timestamps onto (the IMU's 100 Hz).
        max_runs: Read at most this many runs per terrain (quick checks).
    """
    root = Path(root)
    terrains = sorted(d.name for d in root.iterdir() if d.is_dir()) if root.is_dir() else []
    if not terrains:
        raise RecordingError(f"{root}: no BorealTC terrain folders")
    window = round(window_s * rate_hz)
    wins, labels, recs, sources = [], [], [], []
    for k, terrain in enumerate(terrains):
        files = sorted((root / terrain).glob("imu_*.csv"))[:max_runs]
        for f in files:
            data = np.genfromtxt(f, delimiter=",", names=True)
            if channel not in data.dtype.names:
                raise RecordingError(f"{f}: no column {channel!r}")
            t, x = data["time"], data[channel]
            ok = np.isfinite(t) & np.isfinite(x)
            t, x = t[ok], x[ok]
            keep = np.concatenate([[True], np.diff(t) > 0])
            w = cut_windows(t[keep], x[keep], rate_hz=rate_hz, window=window, hop=window)
            wins.append(w)
            labels.append(np.full(len(w), k))
            recs.append(np.full(len(w), len(sources)))
            sources.append(str(f))
    n = sum(len(w) for w in wins)
    return WindowSet(
        np.concatenate(wins),
        np.concatenate(labels).astype(int),
        tuple(terrains),
        np.concatenate(recs).astype(int),
        np.full(n, np.nan),
        sources,
        rate_hz,
    )
