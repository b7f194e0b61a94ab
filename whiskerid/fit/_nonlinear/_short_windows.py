"""Short-window damped-sine fits along a decay: frequency and damping against amplitude.

A model-free look at a backbone (the practice of short-window and Hilbert analyses of free
decays): each window of a few periods gets its own ``f``, ``ζ`` and amplitude by
:func:`whiskerid.fit.fit_windows`; plotted against the window's amplitude they should lie on
a nonlinear fit's ``f(a)``, ``ζ(a)``, and on flat lines for a linear whisker.
"""

import numpy as np

from .._linear import bucket, fit_windows

#: Periods of the first mode per window.
WINDOW_PERIODS = 8
#: Fewest samples per window.
WINDOW_MIN_SAMPLES = 24


def short_window_points(obs, per_rec: list[dict], f1_hz: float) -> dict:
    """Window fits of every recording, as ``amplitude_m``, ``f_hz``, ``zeta`` lists.

    Args:
        obs: The recordings (free decays).
        per_rec: Per recording ``noise_amplitude_m`` (the residual RMS as a mode-1 tip
            amplitude) and ``rms_residual`` (observed units): their ratio converts an
            observed amplitude to metres at the tip.
        f1_hz: The fitted f_1 (sets the window length).

    Returns:
        Lists (one entry per window that converged above three times the noise amplitude).
    """
    amp, freq, zeta = [], [], []
    for o, r in zip(obs, per_rec, strict=True):
        dt = float(np.median(np.diff(o.t)))
        m = max(WINDOW_MIN_SAMPLES, round(WINDOW_PERIODS / (f1_hz * dt)))
        n = o.t.size // m
        if n < 1:
            continue
        y = o.y[: n * m].reshape(n, m)
        t = o.t[: n * m].reshape(n, m)
        # the windows padded to a shape bucket with copies of the last (each window is fitted
        # on its own), so that recordings of other lengths share the compiled window fit
        rows = np.minimum(np.arange(bucket(n)), n - 1)
        fits = fit_windows(y[rows], t=t[rows])
        a_obs = np.asarray(fits.amplitude)[:n]
        # observed amplitude → metres, by the fit's own conversion of the first window
        to_m = r["noise_amplitude_m"] / max(r["rms_residual"] * np.sqrt(2), 1e-300)
        z = np.asarray(fits.zeta)[:n]
        fd = np.asarray(fits.damped_frequency_hz)[:n]
        # the window's f and ζ are averages over it: place them at its middle amplitude
        span = t[:, -1] - t[:, 0]
        a_m = a_obs * to_m * np.exp(-z * 2 * np.pi * fd / np.sqrt(1 - z**2) * span / 2)
        good = np.isfinite(a_m) & (a_m > 3 * r["noise_amplitude_m"]) & np.isfinite(fd)
        amp += [float(v) for v in a_m[good]]
        freq += [float(v) for v in (fd / np.sqrt(1 - z**2))[good]]
        zeta += [float(v) for v in z[good]]
    return {"amplitude_m": amp, "f_hz": freq, "zeta": zeta}
