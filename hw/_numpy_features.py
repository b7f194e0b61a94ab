"""The ``fitted`` and ``paper`` window features in NumPy, for the JAX-free stream.

A line-by-line NumPy transcription of :func:`whiskerid.classify._features.fitted_features`
and ``paper_features`` (float64, as there): the online stream labels with these when a
model's features are all among them (:func:`unsupported`), so that it starts without
importing JAX. ``tests/test_numpy_classifier.py`` holds the two to the same numbers, window
by window, on trained models.
"""

import numpy as np

_EPS = 1e-12

#: A model file's feature settings, as :class:`whiskerid.classify.FeatureSpec` defaults
#: them (a file written before a setting existed lacks it).
SPEC_DEFAULTS = {
    "kind": "fitted", "rate_hz": 200.0, "window": 200, "n_bands": 16, "n_peaks": 3,
    "modal_fit": False, "octave_bands": False, "use_speed": False, "n_spatial_bands": 10,
    "spatial_lo": 10.0, "spatial_hi": 330.0, "channels": 1, "deconvolve": False,
    "cross_channel": False, "window_fit": False, "floor_match": False,
    "extend_edges": False, "alias_slope": 0.0,
}  # fmt: skip

#: Settings whose features only the JAX path computes, and why.
_JAX_ONLY = {
    "modal_fit": "a resonance fitted to each window (modal_fit)",
    "window_fit": "a damped oscillation fitted to each window (window_fit)",
    "deconvolve": "whisker-aware features (the whisker's transfer function divided out)",
    "cross_channel": "cross-channel features",
}


def unsupported(spec: dict) -> str | None:
    """Why these feature settings need the JAX path, or None when NumPy computes them."""
    if set(spec) - set(SPEC_DEFAULTS):
        return f"feature settings unknown here: {sorted(set(spec) - set(SPEC_DEFAULTS))}"
    s = {**SPEC_DEFAULTS, **spec}
    if s["kind"] not in ("fitted", "paper"):
        return f"features of kind {s['kind']!r}"
    for key, what in _JAX_ONLY.items():
        if s[key]:
            return what
    if s["channels"] != 1:
        return f"{s['channels']} channels per window"
    return None


def window_features(spec: dict, x: np.ndarray, speed_mps: float) -> np.ndarray:
    """Feature vector of one window ``(window,)`` for settings :func:`unsupported` accepts."""
    s = {**SPEC_DEFAULTS, **spec}
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if s["kind"] == "paper":
            return np.abs(np.fft.fft(_standardise(x)))
        return _fitted(s, x, speed_mps)


def _standardise(x):
    x = x - np.mean(x)
    return x / np.maximum(np.std(x), _EPS)


def _power(x):
    w = np.hanning(x.shape[-1])
    return (np.abs(np.fft.rfft(_standardise(x) * w)) ** 2 / np.sum(w**2))[1:]


def _bands(freqs, power, edges):
    inside = (freqs[None, :] >= edges[:-1, None]) & (freqs[None, :] < edges[1:, None])
    inside[-1] |= freqs == edges[-1]
    total = np.sum(np.where(inside.any(axis=0), power, 0.0))
    return (inside @ power) / np.maximum(total, _EPS)


def _peaks(amps, df, n):
    y = np.log(np.maximum(amps, _EPS))
    inner = np.arange(1, amps.shape[0] - 1)
    is_max = (y[inner] > y[inner - 1]) & (y[inner] >= y[inner + 1])
    score = np.where(is_max, y[inner], -np.inf)
    idx = np.argsort(-score, kind="stable")[:n]  # lax.top_k: ties to the lower index
    top, k = score[idx], inner[idx]
    y0, y1, y2 = y[k - 1], y[k], y[k + 1]
    curv = y0 - 2 * y1 + y2
    safe = np.where(curv < 0, curv, -_EPS)
    shift = np.clip(0.5 * (y0 - y2) / safe, -0.5, 0.5)
    peak_y = y1 - 0.25 * (y0 - y2) * shift
    width = 2 * np.sqrt(np.log(2.0) / np.maximum(-safe, _EPS)) * df
    valid = np.isfinite(top)
    return (np.where(valid, (k + shift) * df, 0.0), np.where(valid, np.exp(peak_y), 0.0),
            np.where(valid, width, 0.0))  # fmt: skip


def _envelope(z):
    n = z.shape[-1]
    h = np.zeros(n)
    h[0], h[1 : (n + 1) // 2] = 1.0, 2.0
    if n % 2 == 0:
        h[n // 2] = 1.0
    return np.abs(np.fft.ifft(np.fft.fft(z) * h))


def _autocorr(x):
    n = x.shape[-1]
    ac = np.fft.irfft(np.abs(np.fft.rfft(x, 2 * n)) ** 2, 2 * n)[:n]
    return ac / np.maximum(ac[0], _EPS)


def _crossings(z):
    # JAX takes the mean of booleans in float32, times the reciprocal of the count: the
    # same rounding here.
    flips = np.count_nonzero(np.signbit(z[1:]) != np.signbit(z[:-1]))
    return np.float64(np.float32(flips) * (np.float32(1) / np.float32(z.size - 1)))


def _octave_edges(window: int, rate_hz: float, df: float) -> np.ndarray:
    # How many edges depends on the window only (FeatureSpec.octave_edges at 200 Hz).
    e, nyq = [200.0 / window], 100.0
    while 2 * e[-1] < nyq * (1 - 1e-9):
        e.append(2 * e[-1])
    return np.concatenate([df * 2.0 ** np.arange(len(e)), [rate_hz / 2]])


def _fitted(s: dict, x: np.ndarray, speed_mps: float) -> np.ndarray:
    rate_hz, n = float(s["rate_hz"]), x.shape[-1]
    nyq, per_nyq = rate_hz / 2, 2.0 / rate_hz
    freqs = (np.arange(n // 2 + 1, dtype=np.float64) / np.float64(1.0 / rate_hz * n))[1:]
    df = rate_hz / n
    x0 = x - np.mean(x)
    rms = np.maximum(np.std(x0), _EPS)
    z = x0 / rms
    log_rms = np.log(rms)
    time_feats = [log_rms, np.mean(z**3), np.log(np.mean(z**4) + _EPS),
                  np.log(np.max(np.abs(z)) + _EPS),
                  _crossings(z), np.std(np.diff(z))]  # fmt: skip
    power = _power(x)
    edges = np.linspace(0.0, nyq, s["n_bands"] + 1)
    edges[-1] = nyq
    bands = np.log(_bands(freqs, power, edges) + 1e-4)
    total = np.maximum(np.sum(power), _EPS)
    pn = power / total
    centroid = np.sum(freqs * pn)
    flatness = np.mean(np.log(power + _EPS)) - np.log(np.mean(power) + _EPS)
    spread = np.sqrt(np.sum((freqs - centroid) ** 2 * pn))
    entropy = -np.sum(pn * np.log(pn + _EPS)) / np.log(pn.shape[0])
    rolloff = freqs[np.argmax(np.cumsum(pn) >= 0.85)]
    lf, lp = np.log(freqs), np.log(power + 1e-6)
    lfc = lf - np.mean(lf)
    slope = np.sum(lfc * (lp - np.mean(lp))) / np.sum(lfc**2)
    resid = np.std(lp - np.mean(lp) - slope * lfc)
    peak_floor = np.log(np.max(power) + _EPS) - np.log(np.median(power) + _EPS)
    shape_feats = [spread * per_nyq, entropy, rolloff * per_nyq, slope, resid, peak_floor]
    m = power.shape[0]
    padded = np.pad(power, 2, mode="edge")
    broad = np.median(np.stack([padded[i : i + m] for i in range(5)]), axis=0)
    b_total = np.maximum(np.sum(broad), _EPS)
    b_edges = np.linspace(0.0, nyq, s["n_bands"] // 2 + 1)
    b_edges[-1] = nyq
    b_bands = np.log(_bands(freqs, broad, b_edges) + 1e-4)
    b_level = log_rms + 0.5 * (np.log(b_total) - np.log(total))
    env = _envelope(z)
    env_mean = np.maximum(np.mean(env), _EPS)
    e0 = env - env_mean
    env_ac, sig_ac = _autocorr(e0), _autocorr(z)
    lags = np.arange(n)
    usable = (lags >= max(np.round(0.05 * rate_hz), 2)) & (lags <= n // 2)
    env_ac_u = np.where(usable, env_ac, -np.inf)
    env_lag = int(np.argmax(env_ac_u))
    env_feats = [np.std(env) / env_mean,
                 np.log(np.mean(e0**4) / np.maximum(np.mean(e0**2) ** 2, _EPS) + _EPS),
                 env_ac_u[env_lag], env_lag / n,
                 np.max(np.where(usable, np.abs(sig_ac), -np.inf)), env_ac[1]]  # fmt: skip
    pf, pa, pw = _peaks(np.concatenate([np.zeros(1), np.sqrt(power)]), df, s["n_peaks"])
    k = np.argmin(np.abs(freqs - pf[0]))
    zeta_cf = np.clip(pw[0] / (2 * np.maximum(pf[0], freqs[0])), 0.0, 1.0)
    peak_cf = np.log(power[k] + _EPS) - np.log(np.median(power) + _EPS)
    parts = [time_feats, bands, [centroid * per_nyq, flatness], shape_feats,
             [b_level, np.log(b_total / total)], b_bands, env_feats, pf * per_nyq,
             np.log(pa / np.sqrt(total) + 1e-6), pw * per_nyq, [zeta_cf, peak_cf]]  # fmt: skip
    if s["octave_bands"]:
        o_share = _bands(freqs, power, _octave_edges(n, rate_hz, df))
        parts.append(np.log(o_share + 1e-8) + np.log(total) + 2 * log_rms)
    if s["use_speed"]:
        v = float(speed_mps)
        s_edges = np.geomspace(s["spatial_lo"], s["spatial_hi"], s["n_spatial_bands"] + 1)
        parts.append(np.log(_bands(freqs / v, power, s_edges) + 1e-4))
        parts.append([np.log(np.maximum(pf[0], df) / v), np.log(np.maximum(centroid, df) / v),
                      log_rms - 2 * np.log(v), b_level - 2 * np.log(v)])  # fmt: skip
    return np.concatenate([np.asarray(p, dtype=np.float64).ravel() for p in parts])
