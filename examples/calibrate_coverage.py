"""Synthetic recovery and 1σ coverage of ``whiskerid.calibrate`` over seeded trials.

Each trial: the paper whisker plucked (2 mm at the tip), exact modal model, Hall sensor and
ADS1115 (475 SPS conversions averaged, 16-bit codes) polled at 200 Hz for 10 s, white noise
at SNR 30 dB, a new seed per trial; calibrated from a nominal record 30 % off (f_1 30 % high,
ζ 30 % high) with start values from the data. Reports the worst and median errors of f_1
and ζ and the fraction of trials whose reported 1σ interval covers the truth (about 68 %
for honest uncertainties).

Three modes are fitted (``--modes``; calibrate's default is two). The Hall sensor sits near
the clamp (x_s/l = 0.083), where the third mode (807 Hz, gone within ~5 samples) is strong
enough that a two-mode fit is biased: without noise it puts f_1 2.0e-3 Hz low (−4.4e-5,
about 0.7 of the reported σ at SNR 30 dB), and over 200 trials its 1σ then covers f_1 in
only 62 % (pull mean −0.7, pull std 0.8–1.0: the σ is the right size, the centre is off).
With three modes the noise-free error is 1e-4 Hz, and over 200 trials (seeds 1000–1199)
the 1σ covers f_1 in 67 % and ζ in 72.5 % (pulls: f_1 mean −0.02, std 1.00; ζ −0.11,
0.91). One of those trials (seed 1123) ends on an aliased solution, f_1 = 88.4 Hz with
ζ = 0.0033, whose residuals are as good as the right one's (reduced χ² equal to six
digits): at 200 Hz the data alone cannot tell them apart, only the nominal record can, and
the start's tie-break towards the nominal (costs within 2 %) did not reach it.

    .venv/bin/python examples/calibrate_coverage.py [--trials 200] [--seed0 1000]

A progress bar goes to stderr, the JSON result to stdout. About 2–3 s per trial on a 2-core
CPU: most of it is ``wi.simulate`` (which compiles its signal function anew for every call);
a calibration itself takes about 0.5 s once its compiled pieces are warm.
"""

import argparse
import json
import sys
import time
from dataclasses import replace

import numpy as np
from tqdm import tqdm

import whiskerid as wi


def trials(n: int, seed0: int = 1000, n_modes: int = 3) -> dict:
    rec = wi.paper_record()
    truth = rec.whisker()
    f1, zeta = float(truth.natural_frequencies_hz[0]), float(truth.zeta[0])
    s = rec.structure
    start = rec.replace(
        structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * 1.3**2), zeta=zeta * 1.3
    )
    rows, lag1, chi2 = [], [], []
    t0 = time.perf_counter()
    for k in tqdm(range(n), desc="trials", unit="trial", file=sys.stderr):
        sim = wi.simulate(
            rec,
            excitation="decay",
            observable="adc",
            rate_hz=200.0,
            duration_s=10.0,
            noise_db=30.0,
            seed=seed0 + k,
            tip_deflection_m=2e-3,
        )
        obs = wi.Observation(sim.t, sim.signal(), observable="adc", gain=None)
        cal = wi.calibrate(start, obs, n_modes=n_modes)
        p = cal.params
        rows.append(
            (cal.ok, p["f1_hz"]["value"], p["f1_hz"]["std"], p["zeta"]["value"], p["zeta"]["std"])
        )
        lag1.append(cal.diagnostics["lag1_autocorr"][0])
        chi2.append(cal.diagnostics["reduced_chi2"])
    ok, fv, fs, zv, zs = (np.array(c) for c in zip(*rows, strict=True))
    ef, ez = np.abs(fv / f1 - 1), np.abs(zv / zeta - 1)
    pf, pz, good = (fv - f1) / fs, (zv - zeta) / zs, ef <= 0.01
    return {
        "seeds_f1_off_by_over_1pct": [int(seed0 + k) for k in np.flatnonzero(ef > 0.01)],
        "trials": n,
        "fitted_modes": n_modes,
        "converged": int(ok.sum()),
        "truth": {"f1_hz": f1, "zeta": zeta},
        "f1_rel_error_max": float(ef.max()),
        "f1_rel_error_median": float(np.median(ef)),
        "f1_within_0.1pct": float(np.mean(ef < 1e-3)),
        "zeta_rel_error_max": float(ez.max()),
        "zeta_rel_error_median": float(np.median(ez)),
        "zeta_within_3pct": float(np.mean(ez < 0.03)),
        "coverage_1sigma_f1": float(np.mean(np.abs(fv - f1) <= fs)),
        "coverage_1sigma_zeta": float(np.mean(np.abs(zv - zeta) <= zs)),
        "coverage_2sigma_f1": float(np.mean(np.abs(fv - f1) <= 2 * fs)),
        "coverage_2sigma_zeta": float(np.mean(np.abs(zv - zeta) <= 2 * zs)),
        # pulls (fit − truth)/σ over the trials that found the right mode: mean ≈ 0 and
        # std ≈ 1 for unbiased fits with honest σ
        "pull_mean": {"f1": float(np.mean(pf[good])), "zeta": float(np.mean(pz[good]))},
        "pull_std": {"f1": float(np.std(pf[good])), "zeta": float(np.std(pz[good]))},
        "mean_reported_std": {"f1_hz": float(fs.mean()), "zeta": float(zs.mean())},
        "empirical_std": {
            "f1_hz": float(fv[good].std(ddof=1)),
            "zeta": float(zv[good].std(ddof=1)),
        },
        "median_lag1_residual_autocorr": float(np.median(lag1)),
        "median_reduced_chi2": float(np.median(chi2)),
        "seconds": time.perf_counter() - t0,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--modes", type=int, default=3, help="modes in the fitted model")
    a = ap.parse_args(argv)
    print(json.dumps(trials(a.trials, a.seed0, a.modes), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
