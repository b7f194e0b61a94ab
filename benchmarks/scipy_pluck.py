"""The peer of ``whiskerid calibrate`` on a pluck: the same fit in NumPy and SciPy alone.

Model (what calibrate fits to a free decay, two modes): an offset, a linear drift and two
damped modes ``e^{−σ_i t}(a_i cos ω_di t + b_i sin ω_di t)`` with ``f_2 = r f_1`` (``r`` the
cantilever's eigenvalue ratio ``(β_2/β_1)²`` for the record's tip mass, given) and one ζ,
each column averaged over the ADS1115's conversion (``--conversion-s``, 16 points, as the
converter averages its input). Start: f_1 at the largest spectral peak below the Nyquist
frequency (no window: a pluck rings at the start; bin-interpolated), ζ = 0.04; the linear
coefficients by least squares. Fit: ``scipy.optimize.least_squares(method="lm")`` on
(log f_1, logit ζ, the six coefficients); 1σ from ``s²(JᵀJ)⁻¹`` at the optimum. Prints one
JSON line.

Run: ``python benchmarks/scipy_pluck.py pluck.csv --ratio 6.27 [--conversion-s 0.0021]``.
"""

import argparse
import json
import time

import numpy as np
from scipy.optimize import least_squares

ZETA_MAX = 0.95


def columns(t, f1, zeta, ratio, offsets):
    """The six design columns at (f_1, ζ), averaged over the conversion ``offsets``."""
    span = max(t[-1] - t[0], 1e-12)
    cols = [np.ones_like(t), (t - 0.5 * (t[0] + t[-1])) / span]
    for f in (f1, ratio * f1):
        w = 2 * np.pi * f
        sigma, wd = zeta * w, w * np.sqrt(1 - zeta**2)
        e = np.exp(-sigma * t)
        c, s = e * np.cos(wd * t), e * np.sin(wd * t)
        if offsets is not None:  # the mean of e^{λ(t+o)} over o is e^{λt} times a constant
            eo = np.exp(-sigma * offsets)
            a_re, a_im = np.mean(eo * np.cos(wd * offsets)), np.mean(eo * np.sin(wd * offsets))
            c, s = c * a_re - s * a_im, s * a_re + c * a_im
        cols += [c, s]
    return np.stack(cols, axis=1)


def fit(t, y, *, ratio, conversion_s=None, points=16):
    """f_1, ζ and their 1σ fitted to a pluck ``(t, y)`` (see the module docstring)."""
    t = t - t[0]
    y = (y - y.mean()) / y.std()
    offsets = None
    if conversion_s:
        offsets = -(np.arange(points) + 0.5) / points * conversion_s
    rate = 1 / np.median(np.diff(t))
    spec = np.abs(np.fft.rfft(y - y.mean()))  # no window: a pluck rings at the start
    k = int(np.argmax(spec[2:-1])) + 2
    a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
    f1 = (k + 0.5 * (a - c) / (a - 2 * b + c)) * rate / y.size
    zeta = 0.04
    coef = np.linalg.lstsq(columns(t, f1, zeta, ratio, offsets), y, rcond=None)[0]
    u0 = np.concatenate([[np.log(f1), np.log(zeta / (ZETA_MAX - zeta))], coef])

    def resid(u):
        z = ZETA_MAX / (1 + np.exp(-u[1]))
        return columns(t, np.exp(u[0]), z, ratio, offsets) @ u[2:] - y

    res = least_squares(resid, u0, method="lm", xtol=1e-10, ftol=1e-10)
    u = res.x
    s2 = np.sum(res.fun**2) / (y.size - u.size)
    cov = s2 * np.linalg.pinv(res.jac.T @ res.jac)
    z = ZETA_MAX / (1 + np.exp(-u[1]))
    dz = z * (1 - z / ZETA_MAX)  # dζ/du of the logistic
    return {
        "f1_hz": float(np.exp(u[0])),
        "f1_std": float(np.exp(u[0]) * np.sqrt(cov[0, 0])),
        "zeta": float(z),
        "zeta_std": float(dz * np.sqrt(cov[1, 1])),
        "ok": bool(res.success),
        "nfev": int(res.nfev),
    }


def main() -> None:
    t0 = time.perf_counter()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", help="a recording: a time column (s) and a signal column")
    ap.add_argument("--ratio", type=float, required=True, help="f_2 / f_1")
    ap.add_argument("--conversion-s", type=float, help="the ADS1115's conversion time (s)")
    a = ap.parse_args()
    with open(a.csv) as f:  # metadata lines (#), a header, then rows
        rows = [line for line in f if not line.startswith("#")][1:]
    data = np.loadtxt(rows, delimiter=",")
    out = fit(data[:, 0], data[:, 1], ratio=a.ratio, conversion_s=a.conversion_s)
    print(json.dumps({**out, "elapsed_s": round(time.perf_counter() - t0, 4)}))


if __name__ == "__main__":
    main()
