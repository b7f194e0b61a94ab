"""Calibration plots: data and fit over time, residuals, and the spectra (matplotlib, Agg)."""

from pathlib import Path

import numpy as np

from ..fit import amplitude_spectrum, resample_uniform
from ._plot import _pyplot, _save


def plot_calibration(path: str | Path, cal) -> Path:
    """Save one row per recording: data and fit, residuals, and both spectra."""
    plt = _pyplot()
    n = len(cal.curves)
    fig, axes = plt.subplots(n, 3, figsize=(13, 2.8 * n), constrained_layout=True, squeeze=False)
    for (ax_y, ax_r, ax_f), (t, y, model), info in zip(
        axes, cal.curves, cal.per_recording, strict=True
    ):
        ax_y.plot(t, y, ".", ms=1.5, label="data")
        ax_y.plot(t, model, lw=0.7, label="fit")
        ax_y.set_xlabel("t (s)")
        ax_y.set_ylabel(info["observable"])
        ax_y.set_title(info["name"], fontsize=9)
        ax_y.legend(fontsize=7)
        ax_r.plot(t, y - model, lw=0.5, color="C3")
        ax_r.set_xlabel("t (s)")
        ax_r.set_title(f"residuals, RMS {info['rms_residual']:.3g}", fontsize=9)
        for sig, label in ((y, "data"), (model, "fit")):
            _, su, rate = resample_uniform(t, sig)
            f, a = amplitude_spectrum(su, rate)
            ax_f.semilogy(f, np.maximum(a, 1e-30), lw=0.7, label=label)
        ax_f.set_xlabel("frequency (Hz)")
        ax_f.legend(fontsize=7)
    p = cal.params
    fig.suptitle(
        f"f1 = {p['f1_hz']['value']:.5g} ± {p['f1_hz']['std']:.2g} Hz, "
        f"zeta = {p['zeta']['value']:.4g} ± {p['zeta']['std']:.2g} ({cal.status})"
    )
    return _save(fig, path)
