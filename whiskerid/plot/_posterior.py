"""Posterior plots: a small corner plot and trace plots (matplotlib, Agg; no ``corner``)."""

from pathlib import Path

import numpy as np

from ._plot import _pyplot, _save

_CORNER = ("f1_hz", "zeta", "kappa", "EI", "C", "sigma_1")


def plot_corner(path: str | Path, post, names: tuple[str, ...] | None = None) -> Path:
    """Histograms on the diagonal, 2-D sample clouds below, 16/50/84 % lines; PNG."""
    plt = _pyplot()
    names = [n for n in (names or _CORNER) if n in post.names]
    idx = [post.names.index(n) for n in names]
    x = post.samples[:, idx]
    k = len(names)
    fig, axes = plt.subplots(k, k, figsize=(2.3 * k, 2.3 * k), squeeze=False)
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
                p = post.params[names[i]]
                ax.set_title(
                    f"{names[i]} = {p['median']:.4g}\n+{p['q84'] - p['median']:.2g} "
                    f"-{p['median'] - p['q16']:.2g}",
                    fontsize=8,
                )
                ax.set_yticks([])
            else:
                ax.plot(x[:, j], x[:, i], ",", color="k", alpha=0.3)
            if i == k - 1:
                ax.set_xlabel(names[j], fontsize=8)
            if j == 0 and i > 0:
                ax.set_ylabel(names[i], fontsize=8)
            ax.tick_params(labelsize=6)
    fig.tight_layout()
    return _save(fig, path)


def plot_trace(path: str | Path, post) -> Path:
    """Every walker's trace per reported quantity, with the burn-in shaded; PNG."""
    plt = _pyplot()
    names = [n for n in _CORNER if n in post.names]
    chain = post.derived_chain
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 1.8 * len(names)), sharex=True)
    axes = np.atleast_1d(axes)
    burn = post.diagnostics["burn"]
    for ax, name in zip(axes, names, strict=True):
        ax.plot(chain[:, :, post.names.index(name)], lw=0.3, alpha=0.4, color="k")
        ax.axvspan(0, burn, color="C1", alpha=0.15)
        ax.set_ylabel(name, fontsize=8)
    axes[-1].set_xlabel("step")
    d = post.diagnostics
    axes[0].set_title(f"{d['message']}; acceptance {d['acceptance']:.2f}", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)
