"""The paper's spectral analysis of a dataset: dominant frequency components per terrain and
speed, and whether they tell terrains and speeds apart.

The paper reports that the whisker's vibration has a dominant frequency "sandwiched by two
other less dominant but distinct frequency components", and that the dominant components are
unique to the terrain and the robot's speed. :func:`analyze_dataset` measures both on a
dataset: per recording, the averaged amplitude spectrum (Welch: Hann segments, half
overlapping) and its largest peaks; per terrain and speed, the peaks of the mean spectrum of
its recordings and the spread of the recordings' dominant frequency. Two groups are told apart
by their dominant frequency when the two means differ by more than twice the combined spread
(about 2σ: the recordings of one would seldom be taken for the other's).
"""

from itertools import combinations
from pathlib import Path

import numpy as np

from ..io import RecordingError, read_recording
from ._dataset import list_dataset, recording_rate, recording_signal, recording_speed, windows_of


def _spectrum(rec, channel, rate_hz, segment_s):
    """Welch amplitude spectrum of a recording's channel: ``(freqs, amps)``."""
    x = recording_signal(rec, channel, only_column_ok=True)
    n = round(segment_s * rate_hz)
    segs, _ = windows_of(rec.t, x, rate_hz=rate_hz, window=n, hop=max(n // 2, 1))
    if len(segs) == 0:
        raise RecordingError(
            f"{rec.source}: shorter than one analysis segment ({segment_s:g} s): pass a "
            "shorter --segment"
        )
    w = np.hanning(n)
    segs = segs - segs.mean(axis=1, keepdims=True)
    amps = np.sqrt(np.mean(np.abs(np.fft.rfft(segs * w, axis=1)) ** 2, axis=0)) * 2 / w.sum()
    return np.fft.rfftfreq(n, 1.0 / rate_hz), amps


#: Components closer than this are one peak with ripples on it, not two components.
MIN_SEPARATION_HZ = 2.0


def _peaks(freqs, amps, n):
    keep = freqs >= 2 * freqs[1]  # below two bins: the slow drift of a recording
    from ..fit import find_peaks  # here: importing classify (the stream) skips the fit package

    return find_peaks(freqs[keep], amps[keep], n=n,
                      min_separation_hz=max(MIN_SEPARATION_HZ, 2 * freqs[1]),
                      min_relative=1e-3)  # fmt: skip


def analyze_dataset(
    root: str | Path,
    *,
    channel: str | None = None,
    segment_s: float = 4.0,
    rate_hz: float | None = None,
    n_components: int = 3,
    time_col: str = "t",
) -> dict:
    """Dominant frequency components per terrain and speed, and the paper's claim checked.

    Args:
        root: A dataset folder ``ROOT/<label>/<recording>``; recordings without
            ``speed_mps`` metadata form one group per label (speed ``None``).
        channel: Column to analyse (each recording's first signal column by default).
        segment_s: Length of the Welch segments (s): the frequency resolution is its
            reciprocal.
        rate_hz: Rate to resample to; the first recording's by default.
        n_components: Spectral peaks reported per group (the dominant one first).
        time_col: Name of the recordings' time column.

    Returns:
        A JSON-able dict: ``groups`` (per terrain, per speed: ``components`` as
        ``[frequency_hz, amplitude]`` of the mean spectrum's largest peaks, its dominant one
        ``dominant_hz``, each recording's own (``recording_dominant_hz``) and their standard
        deviation ``dominant_spread_hz``, ``sandwiched``: whether the
        dominant component lies between the next two, and ``recordings``), ``claim``
        (``terrains_told_apart``: the share of terrain pairs at one speed whose dominant
        frequencies differ by more than twice the combined spread, ``speeds_told_apart``:
        the same for speed pairs of one terrain, ``sandwiched``: the share of groups whose
        dominant component is sandwiched, and ``verdict`` in words), and the settings.
    """
    files = list_dataset(root)
    per_group: dict[tuple[str, float | None], list] = {}
    rate = rate_hz
    for label, paths in files.items():
        for path in paths:
            rec = read_recording(path, time_col=time_col)
            rate = recording_rate(rec) if rate is None else rate
            speed = recording_speed(rec)
            key = (label, round(speed, 4) if np.isfinite(speed) else None)
            per_group.setdefault(key, []).append(_spectrum(rec, channel, rate, segment_s))
    groups: dict[str, dict] = {}
    summary = {}

    def order(item):
        (label, speed), _ = item
        return label, speed or 0.0

    for (label, speed), spectra in sorted(per_group.items(), key=order):
        freqs = spectra[0][0]
        mean = np.mean([a for _, a in spectra], axis=0)
        comps = _peaks(freqs, mean, n_components)
        dominant = [_peaks(f, a, 1)[0].frequency_hz for f, a in spectra if _peaks(f, a, 1)]
        spread = float(np.std(dominant, ddof=1)) if len(dominant) > 1 else float(freqs[1])
        lo_hi = sorted(c.frequency_hz for c in comps[1:3])
        sandwiched = len(lo_hi) == 2 and lo_hi[0] < comps[0].frequency_hz < lo_hi[1]
        entry = {
            "components": [[round(c.frequency_hz, 3), float(f"{c.amplitude:.4g}")]
                           for c in comps],
            "dominant_hz": round(comps[0].frequency_hz if comps else float("nan"), 3),
            "recording_dominant_hz": [round(f, 3) for f in dominant],
            "dominant_spread_hz": round(max(spread, float(freqs[1]) / 2), 3),
            "sandwiched": bool(sandwiched),
            "recordings": len(spectra),
        }  # fmt: skip
        groups.setdefault(label, {})[str(speed)] = entry
        summary[(label, speed)] = entry
    claim = _claim(summary)
    return {"groups": groups, "claim": claim, "segment_s": segment_s, "rate_hz": rate,
            "resolution_hz": round(1.0 / segment_s, 4), "channel": channel}  # fmt: skip


def _apart(a: dict, b: dict) -> bool:
    gap = abs(a["dominant_hz"] - b["dominant_hz"])
    return gap > 2 * float(np.hypot(a["dominant_spread_hz"], b["dominant_spread_hz"]))


def _claim(summary: dict) -> dict:
    speeds = sorted({s for _, s in summary if s is not None})
    labels = sorted({lab for lab, _ in summary})
    same_speed = [_apart(summary[(a, s)], summary[(b, s)])
                  for s in speeds or [None] for a, b in combinations(labels, 2)
                  if (a, s) in summary and (b, s) in summary]  # fmt: skip
    same_label = [_apart(summary[(lab, s)], summary[(lab, u)])
                  for lab in labels for s, u in combinations(speeds, 2)
                  if (lab, s) in summary and (lab, u) in summary]  # fmt: skip
    sandwiched = [e["sandwiched"] for e in summary.values()]
    share = {"terrains_told_apart": _share(same_speed), "speeds_told_apart": _share(same_label),
             "sandwiched": _share(sandwiched)}  # fmt: skip
    words = []
    for key, what in (("terrains_told_apart", "terrain pairs at one speed"),
                      ("speeds_told_apart", "speed pairs on one terrain")):  # fmt: skip
        if share[key] is not None:
            words.append(f"{100 * share[key]:.0f} % of {what} have distinct dominant frequencies")
    if share["sandwiched"] is not None:
        words.append(f"the dominant component is sandwiched by the next two in "
                     f"{100 * share['sandwiched']:.0f} % of the groups")  # fmt: skip
    holds = all(v is not None and v >= 0.9 for k, v in share.items() if k != "sandwiched")
    share["verdict"] = ("the claim holds: " if holds else "the claim does not hold in full: ") + (
        "; ".join(words) or "no groups to compare"
    )
    return share


def _share(flags) -> float | None:
    return round(float(np.mean(flags)), 3) if flags else None
