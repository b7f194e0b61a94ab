"""Calibration plots: data and fit over the whole window and zoomed on the decay's start,
residuals, and the spectra (matplotlib, Agg)."""

import textwrap
from pathlib import Path

import numpy as np

from .._choices import UNITS
from ..fit import amplitude_spectrum, resample_uniform
from ._plot import _pyplot, _save

#: Periods of f_1 shown in the zoom on the start of each fitted window.
ZOOM_PERIODS = 8


def plot_calibration(path: str | Path, cal) -> Path:
    """Save one row per recording: the fitted window (data and fit), a zoom on its first
    periods, the residuals, and the spectra of data, fit and residuals (the fitted modes
    marked where the sampling puts them)."""
    plt = _pyplot()
    n = len(cal.curves)
    backbone = getattr(cal, "backbone", None)  # a nonlinear fit: one more row
    rows = n + (1 if backbone else 0)
    fig, axes = plt.subplots(
        rows, 4, figsize=(16, 3.0 * rows), constrained_layout=True, squeeze=False,
        gridspec_kw={"width_ratios": [1.3, 1.0, 1.0, 1.2]},
    )  # fmt: skip
    f1 = cal.params["f1_hz"]["value"]
    modes = [cal.params[k]["value"] for k in cal.params if k[0] == "f" and k.endswith("_hz")]
    for row, (t, y, model), info in zip(axes[:n], cal.curves, cal.per_recording, strict=True):
        unit = UNITS.get(info["observable"], "")
        _time_panels(row[0], row[1], t, y, model, f1, info, unit)
        row[2].plot(t, y - model, lw=0.5, color="C3")
        row[2].set_xlabel("t (s)")
        row[2].set_ylabel(f"residual ({unit})")
        row[2].set_title(
            f"residuals: RMS {info['rms_residual']:.3g} {unit}, lag-1 {info['lag1_autocorr']:.2f}",
            fontsize=9,
        )
        # The spectra in two panels sharing the frequency axis: data and fit above (the fit
        # drawn over the data in a contrasting dashed line), the residuals below beside the
        # data's faint outline, so neither hides the other.
        spec = row[3].get_subplotspec().subgridspec(2, 1, hspace=0.05, height_ratios=[3, 2])
        row[3].remove()
        top = fig.add_subplot(spec[0])
        _spectra(top, fig.add_subplot(spec[1], sharex=top), t, y, model, modes, unit)
    if backbone:
        from ._backbone import backbone_panels

        backbone_panels(axes[n][0], axes[n][1], backbone)
        for ax in axes[n][2:]:
            ax.axis("off")
    p = cal.params
    fig.suptitle(
        f"{cal.record.name}: f1 = {p['f1_hz']['value']:.5g} ± {p['f1_hz']['std']:.2g} Hz, "
        f"zeta = {p['zeta']['value']:.4g} ± {p['zeta']['std']:.2g}  (status {cal.status})"
    )
    return _save(fig, path)


def _time_panels(ax_all, ax_zoom, t, y, model, f1, info, unit):
    end = min(t[-1], t[0] + ZOOM_PERIODS / max(f1, 1e-9))
    ax_all.plot(t, y, ".", ms=1.2, color="C0", label="data")
    ax_all.plot(t, model, lw=0.6, color="C1", label="fit")
    ax_all.axvspan(t[0], end, color="0.9", zorder=-1, label="zoom →")
    ax_all.set_xlabel("t (s)")
    ax_all.set_ylabel(f"{info['observable']} ({unit})")
    where = info.get("selection") or f"from {info['t_start_s']:.4g} s"
    # The file's name and its window on lines of their own, wrapped to the panel's width: a
    # long name or selection would otherwise run past the figure's edge.
    title = textwrap.fill(f"{info['name']}: {where}", 60)
    ax_all.set_title(title, fontsize=8)
    ax_all.legend(fontsize=7, loc="upper right")
    keep = t <= end
    ax_zoom.plot(t[keep], y[keep], ".-", ms=2.5, lw=0.3, color="C0", label="data")
    ax_zoom.plot(t[keep], model[keep], lw=0.9, color="C1", label="fit")
    ax_zoom.set_xlabel("t (s)")
    ax_zoom.set_title(f"first {ZOOM_PERIODS} periods of f1", fontsize=9)


def _spectra(ax, ax_res, t, y, model, modes, unit):
    """Data and fit on ``ax``, the residuals on ``ax_res`` (on the same scale, the data's
    spectrum a faint outline behind them), the fitted modes marked on both."""
    rate = 1.0
    spectra = {}
    for name, sig in (("data", y), ("fit", model), ("residuals", y - model)):
        _, su, rate = resample_uniform(t, sig)
        f, a = amplitude_spectrum(su, rate)
        spectra[name] = (f, np.maximum(a, 1e-30))
    ax.semilogy(*spectra["data"], lw=0.7, color="C0", alpha=0.8, label="data")
    ax.semilogy(*spectra["fit"], lw=1.3, color="k", ls="--", label="fit", zorder=3)
    ax_res.semilogy(*spectra["data"], lw=0.6, color="0.75", label="data")
    ax_res.semilogy(*spectra["residuals"], lw=0.8, color="C3", label="residuals", zorder=3)
    ax_res.set_ylim(ax.get_ylim())
    nyquist = rate / 2
    for k, fm in enumerate(modes):
        seen = abs(fm - rate * round(fm / rate))  # where the sampling puts it
        if seen <= nyquist:
            tag = f"f{k + 1}" + ("" if abs(seen - fm) < 1e-9 * fm else " (aliased)")
            for a in (ax, ax_res):
                a.axvline(seen, ls=":", lw=0.6, color="0.4")
            ax.text(seen, 1.0, tag, transform=ax.get_xaxis_transform(), fontsize=7,
                    ha="center", va="bottom")  # fmt: skip
    ax.set_xlim(0, min(nyquist, max(6 * modes[0], 1.3 * max(m for m in modes if m < nyquist)
                                    if any(m < nyquist for m in modes) else nyquist)))  # fmt: skip
    ax.tick_params(labelbottom=False)
    ax_res.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude ({unit})")
    ax_res.set_ylabel("residuals")
    ax.legend(fontsize=7, loc="upper right")
    ax_res.legend(fontsize=7, loc="upper right")
