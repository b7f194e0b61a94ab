"""A recording's sample rate, from its timestamps or its ``rate_hz`` metadata.

Timestamps that carry no rate (all equal, going backwards, or rounded more coarsely than the
sampling, such as 0.1 s steps at 200 Hz) are refused with a message saying what to do,
rather than turned into a division by zero or a rate that is wrong by orders of magnitude.
"""

import numpy as np

from ._recording import Recording, RecordingError

#: Largest relative disagreement between ``rate_hz`` metadata and the timestamps.
RATE_METADATA_TOLERANCE = 0.15
#: How far apart the rates of one dataset's recordings, or of a recording and the rate
#: asked for, may be (one ADS1115's oscillator is good to a few per cent).
RATE_TOLERANCE = 0.05

#: Largest share of zero steps a time column may hold: more means it was rounded more
#: coarsely than the samples were taken.
MAX_ZERO_STEPS = 0.25


def timestamp_rate(t: np.ndarray, *, where: str = "recording") -> float:
    """Sample rate from timestamps (Hz): one over the median step.

    Args:
        t: Timestamps (s).
        where: What the timestamps belong to, for the message (a file name).

    Raises:
        RecordingError: Fewer than two timestamps, non-finite ones, all of them equal,
            any step backwards, or too many equal neighbours (timestamps rounded more
            coarsely than the sampling).
    """
    t = np.asarray(t, dtype=float).ravel()
    if t.size < 2:
        raise RecordingError(f"{where}: {t.size} timestamp(s); a rate needs at least two")
    if not np.all(np.isfinite(t)):
        row = int(np.flatnonzero(~np.isfinite(t))[0])
        raise RecordingError(
            f"{where}: timestamp at row {row} is {float(t[row])!r}; remove that row"
        )
    steps = np.diff(t)
    if np.all(steps == 0):
        raise RecordingError(
            f"{where}: every timestamp is {float(t[0])!r}, so the time column holds no time: write "
            "each sample's time in seconds"
        )
    back = np.flatnonzero(steps < 0)
    if back.size:
        row = int(back[0]) + 1
        raise RecordingError(
            f"{where}: decreasing timestamp at row {row} (t = {float(t[row - 1])!r} then "
            f"{float(t[row])!r}); timestamps must increase: sort the rows by time or remove "
            "the repeated part"
        )
    zero = float(np.mean(steps == 0))
    if zero > MAX_ZERO_STEPS:
        res = float(np.min(steps[steps > 0]))
        raise RecordingError(
            f"{where}: {zero:.0%} of the timestamps equal the one before: they are rounded to "
            f"about {res:.3g} s, more coarsely than the samples were taken; write them with "
            "more digits (1e-6 s), or give rate_hz metadata and evenly spaced times"
        )
    return 1.0 / float(np.median(steps))


def recording_rate(rec: Recording) -> float:
    """A recording's sample rate: its ``rate_hz`` metadata, else the median timestamp step.

    Raises:
        RecordingError: Timestamps that carry no rate (:func:`timestamp_rate`), ``rate_hz``
            that is not a positive number, or one that disagrees with the timestamps by more
            than :data:`RATE_METADATA_TOLERANCE` (time in ms or ns, or the wrong rate written
            down: either would silently shift every spectrum).
    """
    src = str(rec.source or "recording")
    stamped = timestamp_rate(rec.t, where=src)
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
