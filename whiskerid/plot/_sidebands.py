"""The paper's figure, tested: dominant line, perturbation frequency and sidebands against
speed, one panel per terrain (:func:`whiskerid.classify.analyze_dataset`)."""

from pathlib import Path

from ._plot import _pyplot, _save, terrain_panels


def plot_sidebands(path: str | Path, analysis: dict) -> Path:
    """One panel per terrain, frequency against speed: the dominant line (filled circle),
    the perturbation frequency ``f_b`` (black bar), and the best sideband pair
    ``f_c ± Δ`` (triangles: filled when the test finds them present, open otherwise), the
    next components of the mean spectrum (small grey circles)."""
    plt = _pyplot()
    groups = analysis["groups"]
    labels = list(groups)
    fig, axes = terrain_panels(plt, len(labels))
    seen: set[str] = set()

    def tag(name):
        if name in seen:
            return None
        seen.add(name)
        return name

    for ax, label in zip(axes.flat, labels, strict=False):
        for k, (speed, g) in enumerate(sorted(groups[label].items(), key=lambda kv: kv[0])):
            v = float(speed) if speed != "None" else float(k)
            for f, _ in g["components"][1:]:
                ax.scatter(v, f, s=10, color="0.65", zorder=1, label=tag("next components"))
            if g.get("perturbation_hz") is not None:
                ax.scatter(v, g["perturbation_hz"], marker="_", s=300, color="k", zorder=2,
                           label=tag("perturbation f_b"))  # fmt: skip
            ax.scatter(v, g["dominant_hz"], s=36, color="C0", zorder=3, label=tag("dominant"))
            sb = g.get("sidebands", {})
            if sb.get("delta_hz") is not None:
                fc, d = sb["carrier_hz"], sb["delta_hz"]
                present = sb["present"]
                ax.scatter([v, v], [fc - d, fc + d], marker="^", s=40, zorder=4,
                           facecolors="C3" if present else "none", edgecolors="C3",
                           label=tag("sidebands (present)" if present
                                     else "best pair (not significant)"))  # fmt: skip
        ax.set_ylim(0, analysis["rate_hz"] / 2)
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("speed (m/s)" if "None" not in groups[label] else "speed not recorded")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("frequency (Hz)")
    for ax in list(axes.flat)[len(labels) :]:
        ax.axis("off")
    handles, names = [], []
    for ax in axes.flat:  # a pair present may be drawn first in any panel
        for h, n in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.append(h)
            names.append(n)
    axes.flat[0].legend(handles, names, fontsize=6, loc="upper left")
    fig.suptitle("dominant line, perturbation and sidebands by terrain and speed "
                 f"({analysis['resolution_hz']:g} Hz resolution)", fontsize=11)  # fmt: skip
    return _save(fig, path)
