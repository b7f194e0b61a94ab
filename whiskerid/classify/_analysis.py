"""The paper's spectral analysis of a dataset, and its claim tested.

The paper reports that, at steady state, the whisker's vibration has a dominant frequency
at the robot's vertical perturbation frequency "sandwiched by two other less dominant but
distinct frequency components", and that the dominant components are unique to the
terrain and the robot's speed. :func:`analyze_dataset` measures each part per terrain and
speed:

* the **dominant line**: the largest peak of the group's mean Welch spectrum, each
  recording's own, and their spread;
* the **perturbation frequency** ``f_b``: from the recordings' ``perturbation_hz``
  metadata (the contact simulator writes it), or given, or from the speed and the wheel
  geometry (``per_rev · v/(π D)``: ``per_rev`` perturbations per wheel revolution, e.g.
  the gear ratio for a motor shaft's tone); whether the dominant line is at ``f_b``
  (within two bins);
* **sidebands** at ``f_b ± Δ`` (around the dominant line when ``f_b`` is unknown): the
  test of :func:`whiskerid.classify.line_sideband_test` on the group's recordings (a
  significant carrier line, then two lines at ``f_c ± Δ``: ``Δ`` chosen on the first
  halves, the weaker side tested on the second; multitaper F-tests, so that random
  modulation, a resonance's skirts and one-sided lines are no sidebands and a line counts
  wherever it falls between bins). A group is *sandwiched* when its sidebands are present
  by that test (not merely when the dominant peak lies between the next two largest,
  which one time in three it does by chance);
* whether terrains (at one speed) and speeds (on one terrain) are told apart by their
  dominant frequency: the two means differ by more than twice the combined spread.

The claim holds when there are terrain pairs and speed pairs to compare and at least 90 %
of each are told apart, at least 90 % of the groups are sandwiched, and, where ``f_b`` is
known, at least 90 % of the groups have their dominant line at ``f_b``.
"""

from itertools import combinations
from pathlib import Path

import numpy as np

from ..io import RecordingError, read_recording
from ._dataset import list_dataset, recording_rate, recording_signal, recording_speed, windows_of
from ._line_sidebands import TEST_NAME, line_sideband_test


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


def _series(rec, channel, rate_hz):
    """The recording's channel on a uniform grid at ``rate_hz``: its longest stretch
    without gaps."""
    x = recording_signal(rec, channel, only_column_ok=True)
    t = np.asarray(rec.t, dtype=float)
    n = int(np.floor((t[-1] - t[0]) * rate_hz * (1 + 1e-9))) + 1 if t.size > 1 else 0
    while n >= 16:
        wins, _ = windows_of(t, x, rate_hz=rate_hz, window=n, hop=n)
        if len(wins):
            return wins[0]
        n = n * 3 // 4
    return np.zeros(0)


def _perturbation(recs, speed, given_hz, per_rev, wheel_diameter_m):
    """``(f_b, source)`` of a group (see the module docstring)."""
    meta = [float(r.meta["perturbation_hz"]) for r in recs if "perturbation_hz" in r.meta]
    if meta and len(meta) == len(recs):
        return float(np.mean(meta)), "metadata"
    if given_hz is not None:
        return float(given_hz), "given"
    if per_rev is not None and speed is not None:
        return per_rev * speed / (np.pi * wheel_diameter_m), "speed and wheel geometry"
    return None, None


def analyze_dataset(
    root: str | Path,
    *,
    channel: str | None = None,
    segment_s: float = 4.0,
    rate_hz: float | None = None,
    n_components: int = 3,
    time_col: str = "t",
    perturbation_hz: float | None = None,
    per_rev: float | None = None,
    wheel_diameter_m: float = 0.070,
    alpha: float = 0.01,
) -> dict:
    """Dominant frequency components per terrain and speed, and the paper's claim tested.

    Args:
        root: A dataset folder ``ROOT/<label>/<recording>``; recordings without
            ``speed_mps`` metadata form one group per label (speed ``None``).
        channel: Column to analyse (each recording's first signal column by default).
        segment_s: Length of the Welch segments (s) of the dominant line: the frequency
            resolution is its reciprocal. The sideband test uses whole recordings.
        rate_hz: Rate to resample to; the first recording's by default.
        n_components: Spectral peaks reported per group (the dominant one first).
        time_col: Name of the recordings' time column.
        perturbation_hz: The perturbation frequency (Hz), for recordings without
            ``perturbation_hz`` metadata.
        per_rev: Perturbations per wheel revolution: ``f_b = per_rev · v/(π D)`` from each
            group's speed, when neither metadata nor ``perturbation_hz`` give it.
        wheel_diameter_m: ``D`` (m).
        alpha: Significance level of the sideband test.

    Returns:
        A JSON-able dict: ``groups`` (per terrain, per speed: ``components`` as
        ``[frequency_hz, amplitude]`` of the mean spectrum's largest peaks, its dominant one
        ``dominant_hz``, each recording's own (``recording_dominant_hz``) and their
        standard deviation ``dominant_spread_hz``, ``perturbation_hz`` and its
        ``perturbation_source``, ``dominant_at_perturbation``, ``sidebands`` (the test's
        result, :func:`sideband_test`), ``sandwiched`` (sidebands present), ``verdict``
        in words, and ``recordings``), ``claim`` (``terrains_told_apart``,
        ``speeds_told_apart``, ``sandwiched``, ``dominant_at_perturbation``: shares, and
        ``verdict`` in words), and the settings.
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
            per_group.setdefault(key, []).append(
                (rec, _spectrum(rec, channel, rate, segment_s), _series(rec, channel, rate))
            )
    groups: dict[str, dict] = {}
    summary = {}
    fb_args = (perturbation_hz, per_rev, wheel_diameter_m)

    def order(item):
        (label, speed), _ = item
        return label, speed or 0.0

    for (label, speed), items in sorted(per_group.items(), key=order):
        entry = _group(items, speed, rate, n_components, fb_args, alpha)
        groups.setdefault(label, {})[str(speed)] = entry
        summary[(label, speed)] = entry
    claim = _claim(summary, alpha)
    return {"groups": groups, "claim": claim, "segment_s": segment_s, "rate_hz": rate,
            "resolution_hz": round(1.0 / segment_s, 4), "channel": channel,
            "alpha": alpha}  # fmt: skip


def _group(items, speed, rate_hz, n_components, fb_args, alpha) -> dict:
    spectra = [s for _, s, _ in items]
    freqs = spectra[0][0]
    df = float(freqs[1])
    mean = np.mean([a for _, a in spectra], axis=0)
    comps = _peaks(freqs, mean, n_components)
    dominant = [_peaks(f, a, 1)[0].frequency_hz for f, a in spectra if _peaks(f, a, 1)]
    spread = float(np.std(dominant, ddof=1)) if len(dominant) > 1 else df
    dom = comps[0].frequency_hz if comps else float("nan")
    fb, source = _perturbation([r for r, _, _ in items], speed, *fb_args)
    recs = [r for r, _, _ in items]
    series = [x for _, _, x in items if x.size]
    carrier = fb if fb is not None else dom
    per_rec = [float(r.meta["perturbation_hz"]) for r in recs if "perturbation_hz" in r.meta]
    carriers = per_rec if source == "metadata" and len(series) == len(recs) else carrier
    if not series or not np.isfinite(carrier):
        bands = {"test": TEST_NAME, "present": False, "p_value": 1.0, "carrier_p_value": 1.0,
                 "delta_hz": None, "power": None, "recordings": len(series),
                 "reason": "no recording long enough"}  # fmt: skip
    else:
        bands = line_sideband_test(series, rate_hz, carriers, alpha=alpha)
    at_fb = None if fb is None or not np.isfinite(dom) else bool(abs(dom - fb) <= 2 * df)
    return {
        "components": [[round(c.frequency_hz, 3), float(f"{c.amplitude:.4g}")] for c in comps],
        "dominant_hz": round(dom, 3),
        "recording_dominant_hz": [round(f, 3) for f in dominant],
        "dominant_spread_hz": round(max(spread, df / 2), 3),
        "perturbation_hz": None if fb is None else round(fb, 4),
        "perturbation_source": source,
        "dominant_at_perturbation": at_fb,
        "sidebands": bands,
        "sandwiched": bool(bands["present"]),
        "verdict": _group_words(dom, fb, at_fb, bands),
        "recordings": len(items),
    }  # fmt: skip


def _group_words(dom, fb, at_fb, bands) -> str:
    words = [f"dominant {dom:.2f} Hz"]
    if fb is not None:
        words.append(f"{'at' if at_fb else 'not at'} the perturbation {fb:.2f} Hz")
    if bands.get("delta_hz") is None:
        words.append("no sideband test (" + bands.get("reason", "no windows") + ")")
    elif bands["present"]:
        words.append(f"sidebands at ±{bands['delta_hz']:.2f} Hz (p = {bands['p_value']:.2g}, "
                     f"{bands['level_db']:.1f} dB re carrier)")  # fmt: skip
    else:
        cp = bands["carrier_p_value"]
        carrier = "" if cp < bands["alpha"] else f", no significant carrier (p = {cp:.2g})"
        power = "" if bands["power"] is None else f", power {bands['power']:.2f}"
        words.append(f"no sidebands (best ±{bands['delta_hz']:.2f} Hz: p = "
                     f"{bands['p_value']:.2g}{power}{carrier})")  # fmt: skip
    return "; ".join(words)


def _apart(a: dict, b: dict) -> bool:
    gap = abs(a["dominant_hz"] - b["dominant_hz"])
    return gap > 2 * float(np.hypot(a["dominant_spread_hz"], b["dominant_spread_hz"]))


def _claim(summary: dict, alpha: float) -> dict:
    speeds = sorted({s for _, s in summary if s is not None})
    labels = sorted({lab for lab, _ in summary})
    same_speed = [_apart(summary[(a, s)], summary[(b, s)])
                  for s in speeds or [None] for a, b in combinations(labels, 2)
                  if (a, s) in summary and (b, s) in summary]  # fmt: skip
    same_label = [_apart(summary[(lab, s)], summary[(lab, u)])
                  for lab in labels for s, u in combinations(speeds, 2)
                  if (lab, s) in summary and (lab, u) in summary]  # fmt: skip
    sandwiched = [e["sandwiched"] for e in summary.values()]
    at_fb = [e["dominant_at_perturbation"] for e in summary.values()
             if e["dominant_at_perturbation"] is not None]  # fmt: skip
    share = {"terrains_told_apart": _share(same_speed), "speeds_told_apart": _share(same_label),
             "sandwiched": _share(sandwiched),
             "dominant_at_perturbation": _share(at_fb)}  # fmt: skip
    words = []
    for key, what in (("terrains_told_apart", "terrain pairs at one speed"),
                      ("speeds_told_apart", "speed pairs on one terrain")):  # fmt: skip
        if share[key] is not None:
            words.append(f"{100 * share[key]:.0f} % of {what} have distinct dominant frequencies")
    if share["dominant_at_perturbation"] is not None:
        words.append(f"the dominant line is at the perturbation frequency in "
                     f"{100 * share['dominant_at_perturbation']:.0f} % of the groups")  # fmt: skip
    if share["sandwiched"] is not None:
        words.append(f"symmetric sidebands (p < {alpha:g}) sandwich it in "
                     f"{100 * share['sandwiched']:.0f} % of the groups")  # fmt: skip
    told = ("terrains_told_apart", "speeds_told_apart")
    holds = all(share[k] is not None and share[k] >= 0.9 for k in told) and all(
        v is None or v >= 0.9 for k, v in share.items() if k not in told
    )
    share["verdict"] = ("the claim holds: " if holds else "the claim does not hold in full: ") + (
        "; ".join(words) or "no groups to compare"
    )
    return share


def _share(flags) -> float | None:
    return round(float(np.mean(flags)), 3) if flags else None
