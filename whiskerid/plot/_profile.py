"""The profile of one calibrated parameter beside its 1σ (matplotlib, Agg)."""

from pathlib import Path

import numpy as np

from ._plot import _pyplot, _save


def plot_profile(path: str | Path, profile: dict) -> Path:
    """Save Δχ² of :func:`whiskerid.fit.profile_interval` against the parameter, with the
    Δχ² = 1 line, the profile interval and the covariance's ±1σ (its parabola dashed)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    grid, d = np.asarray(profile["grid"]), np.asarray(profile["delta_chi2"])
    v, s, name = profile["value"], profile["std"], profile["name"]
    ax.plot(grid, d, "o-", ms=3, label="profile Δχ² (others refitted)")
    ax.plot(grid, ((grid - v) / s) ** 2, "--", color="0.5", label="covariance: ((x − x̂)/1σ)²")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.axvspan(v - s, v + s, color="C1", alpha=0.15, label=f"±1σ = ±{s:.3g}")
    for end in (profile["lower"], profile["upper"]):
        if end is not None:
            ax.axvline(end, color="C0", lw=0.8)
    lo, hi = profile["lower"], profile["upper"]
    span = f"profile interval [{lo:.6g}, {hi:.6g}]" if None not in (lo, hi) else "profile open"
    ax.set_title(f"{name} = {v:.6g}: {span}", fontsize=9)
    ax.set_xlabel(name)
    ax.set_ylabel("Δχ²")
    ax.set_ylim(0, max(4.0, min(float(np.max(d)), 9.0)))
    ax.legend(fontsize=8)
    return _save(fig, path)
