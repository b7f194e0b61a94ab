"""Figures of classifiers: the confusion matrix."""

from pathlib import Path

import numpy as np

from ._plot import _pyplot, _save


def plot_confusion(path: str | Path, conf, labels, *, title: str = "") -> Path:
    """Save the row-normalised confusion matrix as a PNG (matplotlib, Agg)."""
    plt = _pyplot()
    conf = np.asarray(conf, dtype=float)
    frac = conf / np.maximum(conf.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(1.0 + 0.8 * len(labels), 0.6 + 0.7 * len(labels)))
    im = ax.imshow(frac, vmin=0, vmax=1, cmap="Blues")
    for i in range(len(labels)):
        for j in range(len(labels)):
            ax.text(j, i, f"{frac[i, j]:.2f}", ha="center", va="center", fontsize=8,
                    color="white" if frac[i, j] > 0.6 else "black")  # fmt: skip
    ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right")
    ax.set_yticks(range(len(labels)), labels)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(title or f"accuracy {np.trace(conf) / max(conf.sum(), 1):.3f}")
    fig.colorbar(im, ax=ax, fraction=0.046).set_label("share of the true class's windows")
    fig.tight_layout()
    return _save(fig, path, dpi=120)
