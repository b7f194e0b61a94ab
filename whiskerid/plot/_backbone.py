"""Backbone panels of a nonlinear calibration: frequency and damping against amplitude, the
fitted curves with their 1σ bands over the short-window fits of the data."""

import numpy as np


def backbone_panels(ax_f, ax_z, backbone: dict) -> None:
    """Draw ``f(a)`` on ``ax_f`` and ``ζ(a)`` on ``ax_z`` (amplitude in mm, log axis).

    Args:
        ax_f: Axes for the frequency.
        ax_z: Axes for the damping ratio.
        backbone: :attr:`whiskerid.fit.NonlinearCalibration.backbone`.
    """
    a = np.asarray(backbone["amplitude_m"]) * 1e3
    win = backbone.get("windows", {})
    wa = np.asarray(win.get("amplitude_m", [])) * 1e3
    for ax, key, std, label in (
        (ax_f, "f_hz", "f_std", "f (Hz)"),
        (ax_z, "zeta", "zeta_std", "zeta"),
    ):
        v, s = np.asarray(backbone[key]), np.asarray(backbone[std])
        if wa.size:
            ax.plot(wa, win[key], ".", ms=3, color="0.5", label="short windows")
        ax.plot(a, v, color="C0", label="fitted backbone")
        ax.fill_between(a, v - s, v + s, color="C0", alpha=0.3, label="1 sigma")
        ax.set_xscale("log")
        ax.set_xlabel("mode-1 tip amplitude a (mm)")
        ax.set_ylabel(label)
        if wa.size:  # the window fits scatter where the signal is weak: show the curve's range
            lo, hi = float(np.min(v - 3 * s)), float(np.max(v + 3 * s))
            pad = 0.5 * (hi - lo) + 1e-12
            ax.set_ylim(lo - pad, hi + pad)
        ax.legend(fontsize=7)
    ax_f.set_title("backbone: frequency against amplitude", fontsize=9)
    ax_z.set_title("damping against amplitude", fontsize=9)
