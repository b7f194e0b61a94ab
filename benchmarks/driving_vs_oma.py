"""Benchmark: ``fleet drive``'s f1 and ζ against an output-only peer, SSI-cov, on the same drives.

The peer is covariance-driven stochastic subspace identification (Peeters & De Roeck 1999,
"Reference-based stochastic subspace identification for output-only modal analysis", MSSP
13(6)), written here from the paper: the output's covariances ``R_i`` (averaged over the
drive's recordings), their block Toeplitz matrix of ``ROWS`` × ``ROWS`` lags, its SVD
truncated to order ``n``, the state matrix ``A`` from the shifted observability matrix, and
the poles ``λ`` → ``s = f_s ln λ``, ``f = |s|/2π``, ζ ``= −Re s/|s|``. Orders 2 … 40 make the
stabilization diagram; a pole is stable where an order two lower has one within 1 % in
frequency and 5 % in ζ; the peer's f1 and ζ are the medians of the stable poles within
0.8–1.25 of the record's f1 (the same prior as ``fleet drive``'s), in their densest cluster
(poles within 1 % in frequency: a physical mode is stable over many orders). pyOMA2 (the package the
issue names) could not be installed on the machine this was written on (the package index
has no release of it), so the peer is this independent implementation, not pyOMA2.

Drives: ``tests/generators/driving.py`` (SciPy ``lsim`` of one mode, optionally a second,
driven by coloured noise; not the project's terrain simulator). Printed (JSON): per drive the
truth, both estimates, errors and times; a summary per method. ``--png FILE`` draws the first
drive's stabilization diagram beside its spectrum and both estimates.

Run: ``python benchmarks/driving_vs_oma.py [--drives 6 --minutes 5 --png stab.png]``.
"""

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from generators.driving import RATE, drive  # noqa: E402

from whiskerid.fleet import identify_driving  # noqa: E402

ROWS = 100  # block rows: lags up to 2·ROWS samples (1 s at 200 Hz)
ORDERS = tuple(range(2, 42, 2))


def covariances(signals, lags: int) -> np.ndarray:
    """``R_i = E[y_{k+i} y_k]``, i = 0 … lags, averaged over the recordings (by FFT)."""
    acc = np.zeros(lags + 1)
    total = 0
    for _, y in signals:
        y = np.asarray(y, float) - np.mean(y)
        n = y.size
        spec = np.fft.rfft(y, 2 * n)
        r = np.fft.irfft(spec * np.conj(spec))[: lags + 1]
        acc += r
        total += n - np.arange(lags + 1)
    return acc / total


def ssi_cov(signals, rate_hz: float, rows: int = ROWS, orders=ORDERS):
    """Poles per order: ``{order: (f_hz, zeta)}`` (arrays, each pole once)."""
    r = covariances(signals, 2 * rows)
    # block Toeplitz of one output: T[i, j] = R_{rows + i - j}
    idx = rows + np.arange(rows)[:, None] - np.arange(rows)[None, :]
    t = r[idx]
    u, sv, _ = np.linalg.svd(t)
    poles = {}
    for n in orders:
        o = u[:, :n] * np.sqrt(sv[:n])
        a = np.linalg.pinv(o[:-1]) @ o[1:]
        lam = np.linalg.eigvals(a)
        lam = lam[np.imag(lam) > 0]
        s = np.log(lam) * rate_hz
        f = np.abs(s) / (2 * np.pi)
        z = -np.real(s) / np.abs(s)
        keep = (z > 0) & (z < 0.5)
        poles[n] = (f[keep], z[keep])
    return poles


def stable_poles(poles, df: float = 0.01, dz: float = 0.05):
    """``(order, f, zeta)`` of the poles with a match at the order two lower."""
    out = []
    orders = sorted(poles)
    for lo, hi in itertools.pairwise(orders):
        f0, z0 = poles[lo]
        for f, z in zip(*poles[hi], strict=True):
            if f0.size == 0:
                continue
            k = int(np.argmin(np.abs(f0 - f)))
            if abs(f0[k] / f - 1) < df and abs(z0[k] / z - 1) < dz:
                out.append((hi, float(f), float(z)))
    return out


def ssi_estimate(signals, rate_hz: float, f1_prior: float):
    poles = ssi_cov(signals, rate_hz)
    st = [(n, f, z) for n, f, z in stable_poles(poles) if 0.8 < f / f1_prior < 1.25]
    if not st:
        return float("nan"), float("nan"), poles
    # the physical mode is stable over many orders: the densest cluster (within 1 % in f)
    f = np.array([q[1] for q in st])
    z = np.array([q[2] for q in st])
    count = (np.abs(f[:, None] / f[None, :] - 1) < 0.01).sum(axis=1)
    near = np.abs(f / f[np.argmax(count)] - 1) < 0.01
    return float(np.median(f[near])), float(np.median(z[near])), poles


def _png(path, signals, rate_hz, poles, truth, ours, peer):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.signal import welch

    from whiskerid.fleet import SEGMENT_S

    fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    y = np.concatenate([s for _, s in signals])
    f, p = welch(y, fs=rate_hz, nperseg=int(SEGMENT_S * rate_hz))
    ax2 = ax.twinx()
    ax2.semilogy(f, p, color="0.6", lw=0.8)
    ax2.set_ylabel("output PSD")
    st = stable_poles(poles)
    for n, (fs, _) in poles.items():
        ax.plot(fs, np.full(fs.size, n), "x", color="tab:red", ms=3)
    if st:
        ax.plot([q[1] for q in st], [q[0] for q in st], "o", mfc="none", color="tab:green", ms=5)
    for x, c, lab in ((truth[0], "k", "truth"), (ours[0], "tab:blue", "fleet drive"),
                      (peer[0], "tab:green", "SSI-cov")):  # fmt: skip
        ax.axvline(x, color=c, ls="--", lw=1, label=f"{lab}: f1 {x:.2f} Hz")
    ax.set_xlim(0, rate_hz / 2)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order (x: pole, o: stable)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("SSI-cov stabilization diagram and the drive's spectrum")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=6)
    ap.add_argument("--minutes", type=int, default=5)
    ap.add_argument("--png", type=Path, help="the first drive's stabilization diagram")
    args = ap.parse_args()
    rows = []
    for k in range(args.drives):
        rng = np.random.default_rng(500 + k)
        f1, zeta = rng.uniform(20, 75), rng.uniform(0.02, 0.08)
        # every other drive has a second mode (a whisker's second bending mode) far above
        modes = ((min(6.3 * f1, 95.0), 0.02, 0.05),) if k % 2 else ()
        signals = drive(rng, f1, zeta, minutes=args.minutes, modes=modes)
        prior = f1 * rng.uniform(0.97, 1.03)
        t0 = time.perf_counter()
        fit = identify_driving(signals, RATE, prior, 0.04)
        t1 = time.perf_counter()
        f_s, z_s, poles = ssi_estimate(signals, RATE, prior)
        t2 = time.perf_counter()
        rows.append({
            "f1_true": f1, "zeta_true": zeta, "modes": 1 + len(modes),
            "ours_status": fit.status, "ours_f1_err_pct": 100 * (fit.f1_hz / f1 - 1),
            "ours_zeta_err_pct": 100 * (fit.zeta / zeta - 1), "ours_s": round(t1 - t0, 2),
            "ssi_f1_err_pct": 100 * (f_s / f1 - 1), "ssi_zeta_err_pct": 100 * (z_s / zeta - 1),
            "ssi_s": round(t2 - t1, 2),
        })  # fmt: skip
        if k == 0 and args.png:
            _png(args.png, signals, RATE, poles, (f1, zeta), (fit.f1_hz, fit.zeta), (f_s, z_s))

    def summ(key):
        v = np.array([r[key] for r in rows], float)
        return {"mean": float(np.nanmean(v)), "rms": float(np.sqrt(np.nanmean(v**2))),
                "max_abs": float(np.nanmax(np.abs(v)))}  # fmt: skip

    print(json.dumps({
        "peer": "SSI-cov written in this benchmark (pyOMA2 not installable here)",
        "drives": rows,
        "summary": {k: summ(k) for k in ("ours_f1_err_pct", "ours_zeta_err_pct",
                                          "ssi_f1_err_pct", "ssi_zeta_err_pct", "ours_s",
                                          "ssi_s")},
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
