"""Plots saved as PNG (matplotlib, headless). Install with ``pip install "whiskerid[plot]"``."""

from pathlib import Path

import numpy as np

from ..fit import amplitude_spectrum, find_peaks, resample_uniform
from ..io import atomic_path


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise RuntimeError('plotting needs matplotlib: pip install "whiskerid[plot]"') from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: A labelled peak stands this many times above the spectrum's local median (12 dB) ...
PEAK_OVER_FLOOR = 4.0
#: ... and at least this fraction of the largest peak (−30 dB): smaller ones are noise bumps.
PEAK_MIN_RELATIVE = 0.03


def real_peaks(freqs: np.ndarray, amps: np.ndarray, n: int = 3, *,
               min_separation_hz: float = 8.0) -> list:  # fmt: skip
    """The ``n`` largest peaks that stand out of the noise: at least
    :data:`PEAK_OVER_FLOOR` times the running median of the spectrum around them (over a
    twentieth of the band) and :data:`PEAK_MIN_RELATIVE` of the largest. A spectrum of
    white noise has none."""
    amps = np.asarray(amps, dtype=float)
    half = max(amps.size // 40, 3)
    pad = np.pad(amps, half, mode="edge")
    floor = np.median(np.lib.stride_tricks.sliding_window_view(pad, 2 * half + 1), axis=1)
    cands = find_peaks(freqs, amps, n=4 * n, min_separation_hz=min_separation_hz,
                       min_relative=PEAK_MIN_RELATIVE)  # fmt: skip
    df = freqs[1] - freqs[0] if freqs.size > 1 else 1.0
    idx = np.clip(np.round((np.array([p.frequency_hz for p in cands]) - freqs[0]) / df)
                  .astype(int), 0, amps.size - 1) if cands else []  # fmt: skip
    keep = [p for p, i in zip(cands, idx, strict=True) if p.amplitude > PEAK_OVER_FLOOR * floor[i]]
    return keep[:n]


def _spectrum_axes(ax, t, x, *, label: str, n_peaks: int = 3) -> None:
    _, xu, rate = resample_uniform(t, x)
    freqs, amps = amplitude_spectrum(xu, rate)
    ax.semilogy(freqs, np.maximum(amps, 1e-30), lw=0.8)
    for p in real_peaks(freqs, amps, n_peaks):
        ax.annotate(
            f"{p.frequency_hz:.1f} Hz",
            (p.frequency_hz, p.amplitude),
            fontsize=7,
            xytext=(3, 3),
            textcoords="offset points",
        )
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude spectrum, {label}" if label else "amplitude spectrum")
    ax.set_xlim(0, freqs[-1])
    top = amps.max() if amps.size else 1.0
    ax.set_ylim(top * 1e-5, top * 3)


def _activity_end(t: np.ndarray, x: np.ndarray) -> float | None:
    """Where a signal that dies out (a pluck) is worth showing to: half as long again as it
    stays above 2 % of its largest swing about its final level; None when it lasts more
    than half the record (a sine, a terrain), which is then shown whole."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    if t.size < 10 or not np.all(np.isfinite(x)):
        return None
    dev = np.abs(x - np.median(x[-max(t.size // 10, 1) :]))
    if dev.max() == 0:
        return None
    last = t[np.flatnonzero(dev > 0.02 * dev.max())[-1]]
    if last - t[0] > 0.5 * (t[-1] - t[0]):
        return None
    return float(t[0] + 1.5 * (last - t[0]))


def plot_signal_and_spectrum(
    path: str | Path, t: np.ndarray, x: np.ndarray, *, title: str = "", label: str = ""
) -> Path:
    """Save a two-panel PNG: the signal over time and its amplitude spectrum."""
    plt = _pyplot()
    fig, (ax_t, ax_f) = plt.subplots(2, 1, figsize=(8, 6), constrained_layout=True)
    ax_t.plot(t, x, lw=0.7)
    ax_t.set_xlabel("t (s)")
    ax_t.set_ylabel(label)
    if (end := _activity_end(t, x)) is not None:  # a pluck dies out: show its decay
        ax_t.set_xlim(t[0], end)
    _spectrum_axes(ax_f, t, x, label=label)
    fig.suptitle(title)
    return _save(fig, path)


def plot_modal_analysis(path: str | Path, cases: list[dict]) -> Path:
    """The paper's modal-analysis figure: one row per (h_b, f_b), signal and spectrum.

    Args:
        path: PNG file to write.
        cases: Dicts with ``t``, ``y``, ``hb_m``, ``fb_hz`` (and optional ``model``).
    """
    plt = _pyplot()
    fig, axes = plt.subplots(
        len(cases), 2, figsize=(10, 2.3 * len(cases)), constrained_layout=True, squeeze=False
    )
    for (ax_t, ax_f), case in zip(axes, cases, strict=True):
        t, y = np.asarray(case["t"]), np.asarray(case["y"])
        shown = t <= t[0] + 0.1
        ax_t.plot(t[shown] * 1e3, y[shown] * 1e6, lw=0.8)
        ax_t.set_xlabel("t (ms)")
        ax_t.set_ylabel("y_s (µm)")
        ax_t.set_title(
            f"{case.get('model', '')} h_b = {case['hb_m'] * 1e3:g} mm, f_b = {case['fb_hz']:g} Hz",
            fontsize=9,
        )
        _spectrum_axes(ax_f, t, y, label="y_s (m)")
        ax_f.set_xlim(0, min(1000.0, ax_f.get_xlim()[1]))
    return _save(fig, path)


def plot_recording_labels(path: str | Path, t: np.ndarray, x: np.ndarray, result: dict,
                          labels, *, window_s: float, title: str = "") -> Path:  # fmt: skip
    """Save a classified recording as a PNG: the signal, shaded by each window's label, and
    the labels over time (filled: the label fused over the context, as reported; open: the
    window's own), with the label of the whole recording in the title.

    Args:
        path: PNG file to write.
        t: Sample times (s).
        x: The classified signal.
        result: :meth:`~whiskerid.ClassifierModel.classify_recording`'s result.
        labels: The model's class names (the timeline's rows).
        window_s: Window length (s).
        title: Title; by default the whole-recording label and its confidence.
    """
    plt = _pyplot()
    labels = list(labels)
    colours = plt.get_cmap("tab10")
    fig, (ax_x, ax_l) = plt.subplots(2, 1, figsize=(9, 3 + 0.3 * len(labels)), sharex=True,
                                     height_ratios=(2, 1 + 0.15 * len(labels)),
                                     constrained_layout=True)  # fmt: skip
    ax_x.plot(t, x, lw=0.5, color="0.2")
    for w in result["windows"]:
        k = labels.index(w["label"])
        ax_x.axvspan(w["start_s"], w["start_s"] + window_s, color=colours(k % 10), alpha=0.15,
                     lw=0)  # fmt: skip
    ax_x.set_ylabel(result.get("channel") or "signal")
    starts = np.array([w["start_s"] for w in result["windows"]]) + window_s / 2
    fused = [labels.index(w["label"]) for w in result["windows"]]
    own = [labels.index(w["window_label"]) - 0.2 for w in result["windows"]]  # just below
    ax_l.scatter(starts, own, marker="o", s=30, facecolors="none", edgecolors="0.4",
                 label="window on its own")  # fmt: skip
    ax_l.scatter(starts, fused, marker="s", s=14, c=[colours(k % 10) for k in fused],
                 label=f"label ({result.get('context_s', window_s):g} s of context)")  # fmt: skip
    ax_l.set_yticks(range(len(labels)), labels)
    ax_l.set_ylim(-0.5, len(labels) - 0.5)
    ax_l.set_xlabel("t (s)")
    ax_l.grid(axis="y", alpha=0.3)
    ax_l.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)  # off the points
    fig.suptitle(title or f"{result['label']} (mean probability {result['confidence']:.2f})")
    return _save(fig, path)


def terrain_panels(plt, n: int):
    """A figure of ``n`` panels sharing their frequency axis, four to a row (one per
    terrain): the figure and its axes as a 2-D array."""
    ncols = min(4, n)
    nrows = -(-n // ncols)
    return plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 2.8 * nrows), sharey=True,
                        constrained_layout=True, squeeze=False)  # fmt: skip


def plot_dominant_frequencies(path: str | Path, analysis: dict) -> Path:
    """One panel per terrain: the dominant frequency components against the robot's speed
    (:func:`whiskerid.classify.analyze_dataset`): the dominant one of the mean spectrum
    filled, with the spread of the recordings' own dominant frequencies (grey dots) as an
    error bar, the next ones open, each marker's area following its amplitude relative to
    the dominant one."""
    plt = _pyplot()
    groups = analysis["groups"]
    labels = list(groups)
    fig, axes = terrain_panels(plt, len(labels))
    for ax, label in zip(axes.flat, labels, strict=False):
        for k, (speed, g) in enumerate(sorted(groups[label].items(), key=lambda kv: kv[0])):
            v = float(speed) if speed != "None" else float(k)
            comps = g["components"]
            if not comps:
                continue
            top, first = comps[0][1], k == 0
            ax.scatter([v] * len(g["recording_dominant_hz"]), g["recording_dominant_hz"], s=8,
                       color="0.6", zorder=1, label="each recording's dominant" if first
                       else None)  # fmt: skip
            ax.errorbar(v, g["dominant_hz"], yerr=g["dominant_spread_hz"], fmt="o", color="C0",
                        ms=6, capsize=3, zorder=3, label="dominant" if first else None)  # fmt: skip
            for j, (f, a) in enumerate(comps[1:]):
                name = "next components" if first and j == 0 else None
                ax.scatter(v, f, s=60 * max(a / top, 0.05), facecolors="none",
                           edgecolors="C1", zorder=2, label=name)  # fmt: skip
        ax.set_ylim(0, analysis["rate_hz"] / 2)
        ax.set_title(label, fontsize=10)
        if "None" in groups[label]:  # recordings without speed_mps: one column, no axis
            ax.set_xticks([])
            ax.set_xlabel("speed not recorded")
        else:
            ax.set_xlabel("speed (m/s)")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("frequency (Hz)")
    for ax in list(axes.flat)[len(labels) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"dominant frequency components by terrain and speed "
                 f"({analysis['resolution_hz']:g} Hz resolution)", fontsize=11)  # fmt: skip
    return _save(fig, path)


def _save(fig, path, *, dpi: int = 110) -> Path:
    """Write ``fig`` as a PNG to exactly ``path`` (without ``format``, matplotlib would
    write ``path.png`` for a name without a suffix) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return path
