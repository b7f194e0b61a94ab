"""The added-mass calibration's figure: the plain and loaded decays with their fits, and the
spectra with the fitted first-mode frequencies, whose shift measures ρa (matplotlib, Agg)."""

from pathlib import Path

import numpy as np

from .._choices import UNITS
from ..fit import amplitude_spectrum, resample_uniform
from ._plot import _pyplot, _save

#: Periods of the plain whisker's f_1 shown in the decay panel.
DECAY_PERIODS = 12


def plot_added_mass(path: str | Path, cal) -> Path:
    """Save two panels: each configuration's first recording (data and fit, offset removed,
    normalised) over its first periods, and their amplitude spectra with the fitted f_1 of each
    configuration marked (the frequency shift, μ and the C or ρa it gives in the title).

    Args:
        path: PNG to write.
        cal: A :class:`whiskerid.fit.Calibration` of the added-mass method.
    """
    plt = _pyplot()
    fig, (ax_t, ax_f) = plt.subplots(1, 2, figsize=(12, 4.0), constrained_layout=True)
    p = cal.params
    f1 = {0: p["f1_hz"]["value"]}
    for k in range(1, 10):
        if f"f1_hz_mass{k}" in p:
            f1[k] = p[f"f1_hz_mass{k}"]["value"]
    shown = set()
    end = DECAY_PERIODS / max(f1[0], 1e-9)
    for (t, y, model), info in zip(cal.curves, cal.per_recording, strict=True):
        k = info.get("configuration", 0)
        if k in shown:
            continue
        shown.add(k)
        mass_g = 1e3 * info.get("added_mass_kg", 0.0)
        label = "plain" if mass_g == 0 else f"+{mass_g:.3g} g"
        scale = max(np.max(np.abs(y - np.median(y))), 1e-300)
        keep = t - t[0] <= end
        tt = t[keep] - t[0]
        ax_t.plot(
            tt, (y[keep] - np.median(y)) / scale, ".", ms=3, color=f"C{k}", label=f"{label}: data"
        )
        ax_t.plot(tt, (model[keep] - np.median(y)) / scale, lw=0.9, color=f"C{k}", alpha=0.8,
                  label=f"{label}: fit")  # fmt: skip
        _, yu, rate = resample_uniform(t, y - model.mean())
        freqs, amps = amplitude_spectrum(yu, rate, window="none")
        pos = freqs > 0  # the mean is removed: its bin is rounding noise
        ax_f.semilogy(freqs[pos], amps[pos] / amps[pos].max(), lw=0.8, color=f"C{k}", label=label)
        alias = abs(f1[k] - rate * round(f1[k] / rate))
        ax_f.axvline(alias, color=f"C{k}", ls="--", lw=0.8)
        ax_f.annotate(f"f1 {f1[k]:.4g} Hz", (alias, 1.0), xytext=(3, -12 - 12 * k),
                      textcoords="offset points", fontsize=8, color=f"C{k}")  # fmt: skip
    unit = UNITS.get(cal.per_recording[0]["observable"], "")
    ax_t.set_xlabel("t from the decay's start (s)")
    ax_t.set_ylabel(f"signal, normalised ({unit})")
    ax_t.set_title("plucks without and with the added mass", fontsize=9)
    ax_t.legend(fontsize=7, ncol=2)
    ax_f.set_xlabel("frequency (Hz; as sampled)")
    ax_f.set_ylabel("amplitude (relative)")
    ax_f.set_ylim(bottom=max(ax_f.get_ylim()[0], 1e-4))
    ax_f.set_title("spectra and fitted first-mode frequencies", fontsize=9)
    ax_f.legend(fontsize=7)
    shift = 100 * (f1.get(1, f1[0]) / f1[0] - 1)
    name = "C" if "C" in p else "rho_a"
    mu = p.get("mu_mass1", {}).get("value", float("nan"))
    fig.suptitle(
        f"{cal.record.name}: f1 {f1[0]:.4g} -> {f1.get(1, f1[0]):.4g} Hz ({shift:+.3g} %), "
        f"mu = {mu:.3g}: {name} = {p[name]['value']:.4g} ± {p[name]['std']:.2g}, "
        f"EI = {p['EI']['value']:.4g} ± {p['EI']['std']:.2g} N m^2  (status {cal.status})",
        fontsize=10,
    )
    return _save(fig, path)
