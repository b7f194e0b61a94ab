"""A whisker's history across sessions: f_1 and ζ per session with the baseline's band."""

from pathlib import Path

import numpy as np

from ._plot import _pyplot, _save

_LABELS = {"f1_hz": "f1 (Hz)", "zeta": "zeta"}


def plot_fleet_history(
    path: str | Path,
    whisker: str,
    sessions: list[str],
    values: dict[str, np.ndarray],
    errors: dict[str, np.ndarray],
    plucks: dict[str, list[list[float]]],
    *,
    baseline: int,
    centre: dict[str, float],
    band: dict[str, float],
    flagged: list[str] | dict[str, list[str]],
    began: dict[str, int] | None = None,
) -> Path:
    """Save one panel per parameter: each session's value with its 1σ, the single plucks,
    the first reference sessions shaded, the band around the reference's centre within
    which no single session's change is flagged, and where a change began; flagged sessions
    in red.

    Args:
        path: PNG to write.
        whisker: The whisker's id (title).
        sessions: Session names, in order.
        values: Parameter (``f1_hz``, ``zeta``) → value per session (NaN: no usable fit).
        errors: Parameter → 1σ per session.
        plucks: Parameter → per session, the single plucks' values.
        baseline: Number of baseline sessions (the first ones).
        centre: Parameter → the baseline's centre.
        band: Parameter → half-width of the no-flag band.
        flagged: Flagged sessions, or parameter → the sessions flagged for it (each panel
            marks only its own parameter's: a change of ζ alone leaves f1's points blue).
        began: Parameter → index of the session where its change began (a dashed line).
    """
    plt = _pyplot()
    names = [p for p in ("f1_hz", "zeta") if p in values]
    fig, axes = plt.subplots(len(names), 1, figsize=(max(6, 0.45 * len(sessions) + 3), 5.5),
                             sharex=True, constrained_layout=True, squeeze=False)  # fmt: skip
    x = np.arange(len(sessions))
    for ax, p in zip(axes[:, 0], names, strict=True):
        own = flagged.get(p, []) if isinstance(flagged, dict) else flagged
        bad = np.array([s in own for s in sessions], dtype=bool)
        v, e = np.asarray(values[p], float), np.asarray(errors[p], float)
        for i, pk in enumerate(plucks.get(p, [])):
            ax.plot([i] * len(pk), pk, ".", ms=3, color="0.6", zorder=1)
        ax.errorbar(x[~bad], v[~bad], e[~bad], fmt="o", ms=4, color="C0", label="session")
        if bad.any():
            ax.errorbar(x[bad], v[bad], e[bad], fmt="o", ms=5, color="C3", label="flagged")
        if baseline:
            ax.axvspan(-0.5, baseline - 0.5, color="0.92", zorder=0, label="first reference")
        if began and p in began:
            ax.axvline(began[p] - 0.5, color="C3", ls="--", lw=1, label="change began")
        if p in centre:
            m, h = centre[p], band[p]
            ax.axhline(m, color="C2", lw=0.8)
            ax.axhspan(m - h, m + h, color="C2", alpha=0.15, zorder=0, label="no-flag band")
        ax.set_ylabel(_LABELS.get(p, p))
        ax.legend(fontsize=7, loc="best")
    axes[-1, 0].set_xticks(x, sessions, rotation=45, ha="right", fontsize=7)
    fig.suptitle(f"{whisker}: f1 and zeta over sessions", fontsize=10)
    return _save(fig, path)
