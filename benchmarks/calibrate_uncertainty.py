"""Are calibration uncertainties right? Reported 1σ against the spread of repeated fits.

For each excitation (a held pluck's free decay, a sine base excitation with unknown amplitude,
a measured random base motion), the same whisker is simulated ``--repeats`` times with
different noise seeds (ADS1115 codes, white noise), calibrated each time, and the median
reported 1σ of f_1 and ζ is compared with the standard deviation of the fitted values over
the repeats. A ratio (reported / spread) within 0.8–1.25 means the reported 1σ can be
trusted; each repeat has the same shape, so the fit compiles once per excitation. With
``--posterior`` the first repeat of each excitation is also sampled with emcee and its
posterior standard deviations are printed beside them.

Run: ``python benchmarks/calibrate_uncertainty.py [--repeats 100] [--posterior]`` (JSON).
"""

import argparse
import json
import platform
import sys
import time
from dataclasses import replace

import numpy as np

from whiskerid.fit import Observation, calibrate
from whiskerid.model import BaseMotion, paper_record, simulate, simulate_pluck


def _record():
    rec = paper_record()
    return rec.replace(zeta=0.03, adc=replace(rec.adc, data_rate_sps=860))


def _observation(kind: str, seed: int) -> Observation:
    rec = _record()
    if kind == "decay":
        r, truth = simulate_pluck(rec, kind="held", rate_hz=860.0, duration_s=1.5,
                                  noise_db=30.0, seed=seed, drift=0.0, tremor=0.0)  # fmt: skip
        keep = r.t >= truth.releases_s[0]
        return Observation(r.t[keep], r.signal()[keep], excitation="decay", observable="adc",
                           gain=None)  # fmt: skip
    if kind == "sine":
        r = simulate(rec, excitation="sine", fb_hz=40.0, hb_m=1e-4, observable="adc",
                     rate_hz=200.0, duration_s=5.0, noise_db=30.0, seed=seed)  # fmt: skip
        return Observation(r.t, r.signal(), excitation="sine", fb_hz=40.0, observable="adc",
                           gain=None)  # fmt: skip
    # base: random base acceleration, known (measured) exactly, band-limited (a 20 ms Hann
    # kernel: nothing above ~100 Hz) so that the samples at 860 Hz describe the input the
    # fit integrates: under-sampled input would be a model error, not noise
    rng = np.random.default_rng(1000)  # the same base motion every repeat
    tb = np.arange(0, 3.0, 1 / 4000)
    acc = np.convolve(rng.standard_normal(tb.size), np.hanning(80), mode="same") * 20.0
    r = simulate(rec, excitation="base", base=BaseMotion(tb, acc), observable="acceleration",
                 rate_hz=860.0, duration_s=2.5, noise_db=30.0, seed=seed)  # fmt: skip
    return Observation(r.t, r.signal(), excitation="base", observable="acceleration",
                       base_acc=np.interp(r.t, tb, acc))  # fmt: skip


def run(kind: str, repeats: int, posterior: bool) -> dict:
    rec = _record()
    f1, z, f1_sd, z_sd, status = [], [], [], [], []
    t0 = time.perf_counter()
    for seed in range(repeats):
        cal = calibrate(rec, _observation(kind, seed))
        p = cal.params
        f1.append(p["f1_hz"]["value"])
        z.append(p["zeta"]["value"])
        f1_sd.append(p["f1_hz"]["std"])
        z_sd.append(p["zeta"]["std"])
        status.append(cal.status)
        print(f"{kind} {seed}: {cal.status} f1 {f1[-1]:.5g} ± {f1_sd[-1]:.2g}, zeta "
              f"{z[-1]:.4g} ± {z_sd[-1]:.2g}", file=sys.stderr)  # fmt: skip
    out = {
        "excitation": kind,
        "repeats": repeats,
        "f1_true_hz": float(rec.whisker().natural_frequencies_hz[0]),
        "zeta_true": 0.03,
        "f1_mean": float(np.mean(f1)),
        "zeta_mean": float(np.mean(z)),
        "f1_spread": float(np.std(f1, ddof=1)),
        "f1_reported_median": float(np.median(f1_sd)),
        "f1_ratio": float(np.median(f1_sd) / np.std(f1, ddof=1)),
        "zeta_spread": float(np.std(z, ddof=1)),
        "zeta_reported_median": float(np.median(z_sd)),
        "zeta_ratio": float(np.median(z_sd) / np.std(z, ddof=1)),
        "ok_fraction": status.count("ok") / repeats,
        "seconds_per_fit": (time.perf_counter() - t0) / repeats,
    }
    if posterior:
        from whiskerid.posterior import sample_posterior

        post = sample_posterior(rec, [_observation(kind, 0)], progress=False)
        out["posterior_f1_sd"] = float(post.params["f1_hz"]["std"])
        out["posterior_zeta_sd"] = float(post.params["zeta"]["std"])
        out["first_fit_f1_sd"] = f1_sd[0]
        out["first_fit_zeta_sd"] = z_sd[0]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=100, help="seeded repeats per excitation")
    ap.add_argument("--kinds", default="decay,sine,base", help="excitations, comma-separated")
    ap.add_argument("--posterior", action="store_true", help="also sample the first repeat")
    args = ap.parse_args(argv)
    results = [run(k, args.repeats, args.posterior) for k in args.kinds.split(",")]
    print(json.dumps({"machine": platform.machine(), "results": results}, indent=1))


if __name__ == "__main__":
    main()
