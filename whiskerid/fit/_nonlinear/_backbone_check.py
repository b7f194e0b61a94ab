"""Is the fitted backbone what the decay itself says? A check without the model's law.

Short windows of a few periods along each decay get their own ``f`` and ``ζ`` (damped-sine
fits, :func:`whiskerid.fit.fit_windows`): a model-free backbone. The same windows of the
fit's own curve go through the same estimator, so that what a short window does to ``f`` and
``ζ`` (the amplitude falling within it, harmonics, the window's length) is the same on both
sides and only the misfit and the noise remain in their difference. The windows, sorted by
amplitude, are pooled into up to :data:`BANDS` bands of at least :data:`MIN_PER_BAND`; in
each band the mean difference of ``f`` and of ``ζ`` is divided by its own 1σ, the scatter of
the windows within the band over ``√n`` (Student's t with ``n − 1`` degrees of freedom, so a
band of few windows is not overconfident). A band whose smallest two-sided p-value is below
the Šidák level ``1 − (1 − α)^(1/m)`` (``m`` tests: two per band) gives ``backbone-misfit``:
a correct model passes at the false-alarm rate ``α`` (:data:`P_FALSE`), for independent
windows.

What it cannot see: a law that describes the recorded amplitudes as well as the true one but
extrapolates differently below them. Cubic damping (``ζ ∝ a²``) fitted by ζ₀ plus friction
(``∝ 1/a``) is such a case: over the recorded range the two backbones agree within the
windows' scatter at 40 dB, while ζ₀ (an ``a → 0`` value) comes out 2–3 % low.
"""

import numpy as np

from .._linear import bucket, fit_windows
from .._numerics import f_sf

#: Periods of the first mode per window (short: many windows per band).
CHECK_PERIODS = 3
#: Fewest samples per window.
CHECK_MIN_SAMPLES = 12
#: Most amplitude bands.
BANDS = 4
#: Fewest windows per band (a band of 4 has 3 degrees of freedom: too weak a test).
MIN_PER_BAND = 8
#: False-alarm rate of the check for a correct model (all bands together).
P_FALSE = 0.01


def window_estimates(y, t, samples: int) -> dict:
    """Damped-sine fits of consecutive windows of ``samples`` samples: ``amplitude`` (at the
    window's first sample, units of ``y``), ``f_hz`` (undamped), ``zeta``, ``ok`` (arrays,
    one entry per whole window)."""
    n = t.size // samples
    if n < 1:
        return {k: np.zeros(0) for k in ("amplitude", "f_hz", "zeta", "ok")}
    yw = np.asarray(y)[: n * samples].reshape(n, samples)
    tw = np.asarray(t)[: n * samples].reshape(n, samples)
    # padded to a shape bucket with copies of the last window, so that recordings of other
    # lengths share the compiled window fit
    rows = np.minimum(np.arange(bucket(n)), n - 1)
    fits = fit_windows(yw[rows], t=tw[rows])
    z = np.asarray(fits.zeta)[:n]
    fd = np.asarray(fits.damped_frequency_hz)[:n]
    with np.errstate(invalid="ignore"):
        f = fd / np.sqrt(1 - z**2)
    ok = np.asarray(fits.ok)[:n] & np.isfinite(f) & np.isfinite(z)
    return {"amplitude": np.asarray(fits.amplitude)[:n], "f_hz": f, "zeta": z, "ok": ok}


def backbone_check(obs, curves, per_rec: list[dict], f1_hz: float, *, alpha=P_FALSE) -> dict:
    """The fit's curves against the data, window by window, in amplitude bands.

    Args:
        obs: The recordings (free decays).
        curves: The fit's ``(t, y, model)`` per recording.
        per_rec: Per recording ``noise_amplitude_m`` and ``rms_residual`` (to convert an
            observed amplitude to metres at the tip, as the backbone's amplitudes).
        f1_hz: The fitted f₁ (sets the window length).
        alpha: False-alarm rate for a correct model.

    Returns:
        ``bands`` (each: ``amplitude_m`` [lowest, highest], ``n`` windows, the mean
        differences data − model ``df_hz``, ``dzeta`` with their ``t`` and ``p``), ``level``
        (the Šidák per-test level), ``alpha``, ``window_samples``, and ``misfit``: the bands
        below the level (empty when the check passes or could not run; ``reason`` then
        says why).
    """
    diffs = []
    samples = CHECK_MIN_SAMPLES
    for o, (_, _, model), r in zip(obs, curves, per_rec, strict=True):
        dt = float(np.median(np.diff(o.t)))
        samples = max(CHECK_MIN_SAMPLES, round(CHECK_PERIODS / (f1_hz * dt)))
        d, m = window_estimates(o.y, o.t, samples), window_estimates(model, o.t, samples)
        to_m = r["noise_amplitude_m"] / max(r["rms_residual"] * np.sqrt(2), 1e-300)
        a_m = m["amplitude"] * to_m
        good = d["ok"] & m["ok"] & (a_m > 3 * r["noise_amplitude_m"])
        diffs.append(np.stack([a_m, d["f_hz"] - m["f_hz"], d["zeta"] - m["zeta"]])[:, good])
    a, df, dz = np.concatenate(diffs, axis=1) if diffs else np.zeros((3, 0))
    out = {"alpha": alpha, "window_samples": int(samples), "bands": [], "misfit": []}
    n_bands = min(BANDS, a.size // MIN_PER_BAND)
    if n_bands < 1:
        out["reason"] = f"{a.size} windows above 3x the noise: too few for a band"
        return out
    level = 1 - (1 - alpha) ** (1 / (2 * n_bands))
    out["level"] = level
    for idx in np.array_split(np.argsort(-a), n_bands):
        n = idx.size
        band = {"amplitude_m": [float(a[idx].min()), float(a[idx].max())], "n": int(n)}
        for name, d in (("df_hz", df[idx]), ("dzeta", dz[idx])):
            se = float(np.std(d, ddof=1) / np.sqrt(n))
            tv = float(np.mean(d) / se) if se > 0 else 0.0
            band[name] = float(np.mean(d))
            band[f"t_{name}"] = tv
            # two-sided Student t: t² is F(1, n − 1) (no SciPy on the calibration's path)
            band[f"p_{name}"] = float(f_sf(tv**2, 1, n - 1))
        out["bands"].append(band)
        if min(band["p_df_hz"], band["p_dzeta"]) < level:
            out["misfit"].append(band)
    return out


def misfit_reason(check: dict) -> str | None:
    """The ``backbone-misfit`` check's text, or None when the check passed."""
    if not check["misfit"]:
        return None
    where = "; ".join(
        f"a {b['amplitude_m'][0]:.3g}..{b['amplitude_m'][1]:.3g} m: "
        f"df {b['df_hz']:+.3g} Hz (t {b['t_df_hz']:+.1f}), "
        f"dzeta {b['dzeta']:+.3g} (t {b['t_dzeta']:+.1f})"
        for b in check["misfit"]
    )
    return (
        f"short-window f and zeta of the data differ from the fitted curve's beyond their "
        f"scatter ({where}; Sidak level {check['level']:.2g} per test, false-alarm rate "
        f"{check['alpha']:g}): the nonlinear law does not describe these amplitudes; try "
        "other --nl-terms or the log-polynomial backbone"
    )
