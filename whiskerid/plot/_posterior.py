"""Posterior plots: a small corner plot and trace plots (matplotlib, Agg; no ``corner``).

Tick labels carry their own digits (no offset text such as ``+4.6e1`` beside an axis,
where it collides with the labels), every axis names its quantity and unit, and the noise
σ of each recording is labelled as such rather than shown as if it were the interval.
"""

import math
from pathlib import Path

import numpy as np

from ._plot import _pyplot, _save

#: The physical quantities drawn, in order (those the posterior has).
_PHYSICAL = ("f1_hz", "zeta", "kappa", "EI", "C")
#: Axis labels with units.
_LABELS = {
    "f1_hz": "f₁ (Hz)",
    "zeta": "ζ",
    "kappa": "κ = EI/(ρa) (m⁴/s²)",
    "EI": "EI (N m²)",
    "C": "C",
}
#: Noise σ panels drawn in the trace plot at most (one per recording).
_MAX_SIGMAS = 6
#: Correlation above which a quantity is a function of one already drawn (κ and EI of f₁).
_SAME = 0.9999


def _label(name: str) -> str:
    if name.startswith("sigma_"):
        return f"noise σ, recording {name.split('_', 1)[1]}"
    return _LABELS.get(name, name)


def _digits(lo: float, hi: float) -> int:
    """Significant digits that tell ``lo`` and ``hi`` apart (tick labels, titles)."""
    span, scale = abs(hi - lo), max(abs(lo), abs(hi))
    if span <= 0 or scale <= 0 or not math.isfinite(span / scale):
        return 4
    return int(min(max(math.ceil(math.log10(scale / span)) + 2, 2), 12))


def _plain_ticks(axis, x: np.ndarray) -> None:
    """At most three ticks, written in full (no offset text, no ×10ⁿ)."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    lo, hi = np.percentile(x, [0.5, 99.5]) if x.size else (0.0, 1.0)
    d = _digits(float(lo), float(hi))
    axis.set_major_locator(MaxNLocator(3))
    axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:.{d}g}"))


def _interval_title(name: str, p: dict) -> str:
    d = _digits(p["q16"], p["q84"])
    return f"{_label(name)}\n{p['median']:.{d}g}  (68 %: {p['q16']:.{d}g} … {p['q84']:.{d}g})"


def _drawn(post, names) -> tuple[list[str], list[str]]:
    """The quantities to draw, and those left out as functions of one drawn (κ, EI of f₁)."""
    keep, same = [], []
    for n in names:
        col = post.samples[:, post.names.index(n)]
        twin = False
        for k in keep:
            other = post.samples[:, post.names.index(k)]
            if np.std(col) > 0 and np.std(other) > 0:
                twin = abs(float(np.corrcoef(col, other)[0, 1])) > _SAME
            if twin:
                same.append(f"{_label(n)} follows {_label(k)}")
                break
        if not twin:
            keep.append(n)
    return keep, same


def plot_corner(path: str | Path, post, names: tuple[str, ...] | None = None) -> Path:
    """Histograms on the diagonal, 2-D sample clouds below, 16/50/84 % lines; PNG.

    Draws the physical quantities (``names`` to choose others); a quantity that is a
    function of one already drawn (κ and EI of f₁, the geometry fixing C) is named in the
    caption instead of drawn as a line. The noise σ of each recording is listed in the
    caption, labelled per recording.
    """
    plt = _pyplot()
    wanted = [n for n in (names or _PHYSICAL) if n in post.names]
    names, same = _drawn(post, wanted)
    x = post.samples[:, [post.names.index(n) for n in names]]
    k = len(names)
    width = max(2.6 * k, 6.5)
    caption = _caption(post, same, chars=int(width * 15))
    foot = 0.14 * (caption.count("\n") + 1) + 0.15  # inches under the panels
    fig, axes = plt.subplots(k, k, figsize=(width, 2.6 * k + 0.5 + foot), squeeze=False)
    for i in range(k):
        for j in range(k):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                ax.hist(x[:, i], bins=40, histtype="step", color="k")
                for q in np.percentile(x[:, i], [16, 50, 84]):
                    ax.axvline(q, color="C0", lw=0.8, ls="--")
                ax.set_title(_interval_title(names[i], post.params[names[i]]), fontsize=8)
                ax.set_yticks([])
            else:
                ax.plot(x[:, j], x[:, i], ",", color="k", alpha=0.3)
                _plain_ticks(ax.yaxis, x[:, i])
            _plain_ticks(ax.xaxis, x[:, j])
            if i == k - 1:
                ax.set_xlabel(_label(names[j]), fontsize=8)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(_label(names[i]), fontsize=8)
            elif i != j:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=6)
            plt.setp(ax.get_xticklabels(), rotation=30, ha="right")
    fig.text(0.01, 0.01, caption, fontsize=7, va="bottom")
    d = post.diagnostics
    fig.suptitle(
        f"posterior: {d['walkers']} walkers × {d['steps']} steps, first {d['burn']} discarded, "
        f"{d['n_samples']} samples" + ("" if d["converged"] else " (not converged)"),
        fontsize=9,
    )
    fig.tight_layout(rect=(0, foot / fig.get_figheight(), 1, 1))
    return _save(fig, path)


def _caption(post, same: list[str], *, chars: int = 100) -> str:
    """What the corner plot shows, in words: lines, titles, left-out quantities, noise σ
    (wrapped to ``chars`` characters a line)."""
    import textwrap

    parts = ["Dashed lines: 16, 50 and 84 % quantiles; titles: median and 68 % interval."]
    if same:
        parts.append("Not drawn, being functions of a drawn quantity: " + "; ".join(same) + ".")
    sigmas = [n for n in post.names if n.startswith("sigma_")]
    if sigmas:
        text = ", ".join(
            f"recording {n.split('_', 1)[1]}: {post.params[n]['median']:#.3g}"
            for n in sigmas[:_MAX_SIGMAS]
        )
        more = f" (and {len(sigmas) - _MAX_SIGMAS} more)" if len(sigmas) > _MAX_SIGMAS else ""
        parts.append(
            f"Noise σ per recording (median, signal units; one per recording, not an "
            f"interval): {text}{more}."
        )
    return "\n".join(textwrap.fill(p, chars) for p in parts)


def plot_trace(path: str | Path, post) -> Path:
    """Every walker's trace per reported quantity, with the discarded burn-in shaded; PNG."""
    plt = _pyplot()
    sigmas = [n for n in post.names if n.startswith("sigma_")][:_MAX_SIGMAS]
    names = [n for n in _PHYSICAL if n in post.names] + sigmas
    chain = post.derived_chain
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 1.6 * len(names) + 0.8), sharex=True)
    axes = np.atleast_1d(axes)
    d = post.diagnostics
    burn = d["burn"]
    for ax, name in zip(axes, names, strict=True):
        x = chain[:, :, post.names.index(name)]
        ax.plot(x, lw=0.3, alpha=0.4, color="k")
        ax.axvspan(0, burn, color="C1", alpha=0.15, label=f"burn-in ({burn} steps, discarded)")
        _plain_ticks(ax.yaxis, x[burn:].ravel())
        ax.set_ylabel(_label(name), fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("step")
    fig.suptitle(_trace_title(d), fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def _trace_title(d: dict) -> str:
    """Two lines: what is drawn, and whether the run is long enough (and what to do)."""
    head = (
        f"emcee traces: {d['walkers']} walkers over {d['steps']} steps; mean acceptance "
        f"{d['acceptance']:.2f}"
    )
    if d.get("steps_needed") is None:
        verdict = "not converged: too few steps to estimate the autocorrelation time τ"
    elif d["converged"]:
        verdict = (
            f"converged: {d['steps']} steps ≥ 50 × the longest autocorrelation time "
            f"(τ = {d['max_tau']:.3g} steps) = {d['steps_needed']}"
        )
    else:
        verdict = (
            f"not converged: 50 × the longest autocorrelation time (τ = {d['max_tau']:.3g} "
            f"steps) = {d['steps_needed']} steps needed; resume with "
            f"{d['steps_needed'] - d['steps']} more"
        )
    return f"{head}\n{verdict}"


#: Recordings drawn in the posterior-predictive figure at most (one panel each).
_MAX_PREDICTIVE = 4


def plot_predictive(path: str | Path, post, *, window_s: float | None = None) -> Path:
    """Posterior-predictive check: each recording against the 5–95 % band of recordings
    simulated at posterior draws (noise included), and the band's median; PNG.

    Args:
        path: The PNG to write.
        post: A :class:`whiskerid.posterior.Posterior` (its
            :meth:`~whiskerid.posterior.Posterior.predictive_draws`).
        window_s: Draw the first ``window_s`` seconds of each recording. By default the span
            where the simulated signal stands out of its noise (and half as long again), at
            least 20 samples: a free decay is over long before most recordings end, and drawn
            whole its cycles would be a smear.
    """
    pred = post.predictive_draws()
    plt = _pyplot()
    n = min(len(pred["t"]), _MAX_PREDICTIVE)
    fig, axes = plt.subplots(2 * n, 1, figsize=(9, 4.2 * n + 0.8), squeeze=False)
    for j in range(n):
        ax, res = axes[2 * j, 0], axes[2 * j + 1, 0]
        t, y = np.asarray(pred["t"][j]), np.asarray(pred["observed"][j])
        draws = np.asarray(pred["draws"][j])
        lo, mid, hi = np.percentile(draws, [5, 50, 95], axis=0)
        inside = (y >= lo) & (y <= hi)
        end = _signal_end(t, lo, mid, hi) if window_s is None else t[0] + window_s
        keep = t <= end
        tk = t[keep]
        ax.fill_between(tk, lo[keep], hi[keep], color="C0", alpha=0.3, lw=0,
                        label=f"5–95 % of {draws.shape[0]} simulated recordings")  # fmt: skip
        ax.plot(tk, mid[keep], color="C0", lw=0.8, label="their median")
        ax.plot(tk, y[keep], ".", color="k", ms=3, label="data")
        ax.set_ylabel(f"recording {j + 1}", fontsize=8)
        ax.set_title(
            f"inside the 90 % band: {100 * np.mean(inside[keep]):.0f} % of the samples drawn, "
            f"{100 * np.mean(inside):.0f} % of all {t.size}",
            fontsize=8,
        )
        # the band is a few noise σ wide, invisible beside the signal: again, less the median
        res.fill_between(tk, (lo - mid)[keep], (hi - mid)[keep], color="C0", alpha=0.3, lw=0)
        res.axhline(0.0, color="C0", lw=0.8)
        res.plot(tk, (y - mid)[keep], ".", color="k", ms=3)
        res.set_ylabel("less the median", fontsize=8)
        for a in (ax, res):
            a.tick_params(labelsize=7)
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle("posterior-predictive check: data against simulated recordings", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def _signal_end(t, lo, mid, hi) -> float:
    """Where the simulated median last stands out of the band's noise (twice its half-width
    from its level at the end), half as long again; at least 20 samples."""
    level = np.median(mid[-max(len(mid) // 10, 1) :])
    noise = np.median(0.5 * (hi - lo))
    above = np.flatnonzero(np.abs(mid - level) > 2 * noise)
    last = int(above[-1]) if above.size else len(t) - 1
    end = t[0] + 1.5 * (t[last] - t[0])
    return float(max(end, t[min(19, len(t) - 1)]))
