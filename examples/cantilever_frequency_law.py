"""Which law does the cantilever's frequency follow at small amplitude? Short windows, model-free.

Every recording of ``examples/calibrate_cantilever.py`` (same release detection) is cut into
windows of four periods (not overlapping); each gets a damped-sine fit
(:func:`whiskerid.fit.fit_windows`): frequency ``f``, damping ``ζ`` and amplitude ``a`` (the
accelerometer's, m/s², at the window's middle). Candidate laws for ``f(a)`` are then fitted
to each recording's windows by least squares, each window's 1σ from the scatter of
neighbouring windows, and compared by the Bayesian information criterion
(``BIC = χ² + k ln n``, lower is better):

* ``kappa+cubic``: ``f₀ + k₁a + k₂a²``, the nonlinear model's backbone (κ and γ);
* ``power``: ``f₀(1 + q(a/a_max)^p)``, a joint's micro-slip (Iwan/Masing: a softening that
  grows as a power ``p`` of the amplitude, ``p = 1`` for uniformly distributed slip
  strengths, below 1 when weak contacts dominate);
* ``kappa+cubic+drift``: the backbone plus a drift linear in the recording's time
  ``f₀ + k₁a + k₂a² + d·t`` (a slow change of the clamp or the temperature);
* ``log``: ``f₀ + k ln a`` (a frequency that keeps rising as the amplitude falls, no a → 0
  limit).

Within one decay ``a`` falls exponentially with ``t``, so an amplitude law and a time drift
trade against each other; across repeats they do not: the drift from one recording to the
next (minutes apart, at the same amplitude) is printed beside the drift the fit needs
within a recording. Prints one JSON object.

    .venv/bin/python examples/cantilever_frequency_law.py [--lengths 30 50]
"""

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibrate_cantilever import ROOT, observation

from whiskerid.fit import fit_windows

F1 = {30: 16.37, 50: 6.06}
STRIDE = {30: 8, 50: 16}
PERIODS = 4


def windows(o, f1: float) -> dict:
    """Non-overlapping damped-sine window fits: t (s from the release), a, f, ζ."""
    dt = float(np.median(np.diff(o.t)))
    m = round(PERIODS / (f1 * dt))
    n = o.t.size // m
    y = o.y[: n * m].reshape(n, m)
    t = o.t[: n * m].reshape(n, m)
    w = fit_windows(y, t=t - t[:, :1])
    fd, z, a = (np.asarray(v) for v in (w.damped_frequency_hz, w.zeta, w.amplitude))
    span = t[:, -1] - t[:, 0]
    a_mid = a * np.exp(-z * 2 * np.pi * fd * span / 2)
    good = np.isfinite(fd) & np.isfinite(a_mid) & (a_mid > 0) & np.asarray(w.ok)
    return {"t": (t[:, 0] + span / 2 - o.t[0])[good], "a": a_mid[good],
            "f": (fd / np.sqrt(1 - z**2))[good], "zeta": z[good]}  # fmt: skip


LAWS = {
    "kappa+cubic": (lambda p, a, t: p[0] + p[1] * a + p[2] * a**2, [0.0, 0.0]),
    "power": (lambda p, a, t: p[0] * (1 + p[1] * np.abs(a) ** p[2]), [-1e-3, 0.5]),
    "kappa+cubic+drift": (lambda p, a, t: p[0] + p[1] * a + p[2] * a**2 + p[3] * t, [0, 0, 0]),
    "log": (lambda p, a, t: p[0] + p[1] * np.log(a), [0.0]),
}


def compare_laws(w: dict) -> dict:
    a = w["a"] / w["a"].max()
    f, t = w["f"], w["t"]
    # each window's 1σ from neighbouring windows (f(a) is smooth on that scale)
    sigma = 1.4826 * np.median(np.abs(np.diff(f, 2))) / np.sqrt(6)
    out = {"n_windows": int(f.size), "window_sigma_hz": float(sigma)}
    for name, (fun, rest) in LAWS.items():
        # the power law from several exponents (its cost has more than one valley)
        starts = [[f[-1], -1e-3, p] for p in (0.25, 0.5, 1.0, 1.5)] if name == "power" else [
            [f[-1], *rest]]  # fmt: skip
        r = min((least_squares(lambda p, fun=fun: (fun(p, a, t) - f) / sigma, x0, x_scale="jac")
                 for x0 in starts), key=lambda r: r.cost)  # fmt: skip
        chi2 = float(np.sum(r.fun**2))
        out[name] = {"chi2": chi2, "bic": chi2 + r.x.size * np.log(f.size),
                     "params": r.x.tolist()}  # fmt: skip
    ref = out["kappa+cubic"]["bic"]
    for name in LAWS:
        out[name]["delta_bic_vs_kappa_cubic"] = out[name]["bic"] - ref
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "cantilever")
    ap.add_argument("--lengths", type=int, nargs="+", default=[30, 50])
    args = ap.parse_args(argv)
    if not args.data.exists():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    summary = {}
    for length in args.lengths:
        rows, at_common = [], []
        paths = sorted((args.data / f"{length}cm").glob("*.npy"))
        for path in paths:
            o = observation(path)
            o = type(o)(o.t[:: STRIDE[length]], o.y[:: STRIDE[length]], observable=o.observable,
                        name=o.name)  # fmt: skip
            w = windows(o, F1[length])
            row = {"file": o.name, **compare_laws(w)}
            # frequency and damping at amplitude bins spanning the decay (medians)
            edges = np.geomspace(w["a"].min(), w["a"].max(), 8)
            row["binned"] = [
                {"a_m_s2": float(np.sqrt(lo * hi)), "t_s": float(np.median(w["t"][s])),
                 "f_hz": float(np.median(w["f"][s])), "zeta": float(np.median(w["zeta"][s])),
                 "n": int(s.sum())}
                for lo, hi in itertools.pairwise(edges)
                if (s := (w["a"] >= lo) & (w["a"] <= hi)).sum() >= 3
            ]  # fmt: skip
            rows.append(row)
            # the frequency at one amplitude common to all repeats (log-interpolated)
            order = np.argsort(w["a"])
            at_common.append((o.name, w, order))
            print(f"{length} cm {o.name}: dBIC power {row['power']['delta_bic_vs_kappa_cubic']:.0f}"
                  f", drift {row['kappa+cubic+drift']['delta_bic_vs_kappa_cubic']:.0f}",
                  file=sys.stderr)  # fmt: skip
        a_common = max(float(np.quantile(w["a"], 0.1)) for _, w, _ in at_common)
        f_common = []
        for _, w, _ in at_common:
            near = np.abs(np.log(w["a"] / a_common)) < 0.15
            f_common.append(float(np.median(w["f"][near])))
        stamps = [p.name[:14] for p in paths]
        minutes = [int(s[6:8]) * 60 + int(s[9:11]) + int(s[12:14]) / 60 for s in stamps]
        between = np.polyfit(minutes, f_common, 1)[0] / 60.0  # Hz/s between recordings
        within = [r["kappa+cubic+drift"]["params"][3] for r in rows]
        summary[f"{length}cm"] = {
            "recordings": rows,
            "drift": {
                "amplitude_m_s2": a_common,
                "f_hz_at_amplitude": f_common,
                "between_recordings_hz_per_s": float(between),
                "within_recording_fit_hz_per_s": within,
            },
        }
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
