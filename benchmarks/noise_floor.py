"""The noise-floor check: how often does it mark a fit ``check`` on linear plucks (false
alarms, must be ~0), and how often on nonlinear plucks fitted linearly (detections)?

Linear plucks: the cases of ``benchmarks/calibrate_plucks.py`` (the project's simulator: all
modes, ADS1115 codes with conversion averaging, held/flicked/tapped/late/multi/clipped, hand
drift and tremor during the hold, 30–45 dB), calibrated exactly as ``whiskerid calibrate`` does.

Nonlinear plucks: the SciPy integrator of ``benchmarks/calibrate_nonlinear.py`` (one mode with
cubic, velocity-squared or Coulomb terms; independent of the project's model), in volts at
40 dB, now with a held stretch before the release (the tip held at its release deflection
with the same noise, ``--hold-s``), read from a recording as the command line reads it (so
the release detector and the quiet stretch are the project's).

Usage::

    python benchmarks/noise_floor.py [--cases 24] [--seeds 2] [--rates 200 860]

Prints one JSON object: per set the number of fits, the statuses, the ``above-noise-floor``
checks and the residual-to-floor ratios.
"""

import argparse
import json
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from calibrate_nonlinear import KINDS, nonlinear_case
from calibrate_plucks import KINDS as PLUCK_KINDS
from calibrate_plucks import make_case

from whiskerid.fit import calibrate, observations_from_recording
from whiskerid.io import Recording


def floor_rows(cal) -> list[dict]:
    return [r for r in cal.diagnostics.get("noise_floor", {}).get("recordings", []) if r["tested"]]


def linear_cases(n, seed):
    rng = np.random.default_rng(seed)  # the draw of calibrate_plucks.py
    grid = [(str(rng.choice(PLUCK_KINDS)), float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))),
             float(np.exp(rng.uniform(np.log(0.005), np.log(0.15)))),
             float(rng.choice([200.0, 475.0, 860.0]))) for _ in range(n)]  # fmt: skip
    rows = []
    for k, (kind, ff, z, rate) in enumerate(grid):
        nominal, rec, _, _ = make_case(kind, ff, z, rate, k)
        try:
            obs = observations_from_recording(rec, nominal, observable="adc")
            cal = calibrate(nominal, obs)
        except Exception as e:  # a refusal is not a noise-floor check
            rows.append({"kind": kind, "status": f"error: {e}", "floor_check": False})
            continue
        fr = floor_rows(cal)
        rows.append({"kind": kind, "rate_hz": rate, "zeta": z, "status": cal.status,
                     "checks": sorted(cal.checks), "floor_check": "above-noise-floor" in cal.checks,
                     "ratios": [round(r["ratio"], 3) for r in fr],
                     "tested": len(fr), "recordings": len(obs)})  # fmt: skip
        print(f"linear {kind:8s} {rate:4.0f} Hz zeta {z:.3g}: {cal.status} {sorted(cal.checks)} "
              f"ratios {rows[-1]['ratios']}", file=sys.stderr)  # fmt: skip
        jax.clear_caches()
    return rows


def held_recording(kind, rate, seed, hold_s):
    """A SciPy nonlinear pluck with a held stretch before the release, as a Recording."""
    record, obs, truth = nonlinear_case(kind, rate, seed)
    rng = np.random.default_rng([seed, 77])
    noise = float(np.std(obs.y)) / 100  # 40 dB, as the decay's
    # the decay's first sample is the deflection at release (less its small first step)
    t_hold = obs.t[0] - np.arange(1, int(hold_s * rate) + 1)[::-1] / rate
    y_hold = obs.y[0] + rng.normal(0, noise, t_hold.size)
    t = np.concatenate([t_hold, obs.t]) - t_hold[0]
    y = np.concatenate([y_hold, obs.y])
    rec = Recording(t=t, columns={"voltage": y}, meta={"units": "V"})
    return record, rec, truth


def nonlinear_cases(seeds, rates, hold_s):
    rows = []
    for rate in rates:
        for kind in KINDS:
            for s in range(seeds):
                record, rec, _ = held_recording(kind, rate, s, hold_s)
                obs = observations_from_recording(rec, record, observable="voltage")
                lin = calibrate(record, obs, n_modes=1)
                nl = calibrate(record, obs, n_modes=1, model="nonlinear")
                fr, fn = floor_rows(lin), floor_rows(nl)
                rows.append({"kind": kind, "rate_hz": rate, "seed": s,
                             "linear_status": lin.status, "linear_checks": sorted(lin.checks),
                             "linear_floor_check": "above-noise-floor" in lin.checks,
                             "linear_ratio": [round(r["ratio"], 3) for r in fr],
                             "nonlinear_status": nl.status,
                             "nonlinear_floor_check": "above-noise-floor" in nl.checks,
                             "nonlinear_ratio": [round(r["ratio"], 3) for r in fn]})  # fmt: skip
                r = rows[-1]
                print(f"{kind}@{rate:g} seed {s}: linear {lin.status} {r['linear_checks']} "
                      f"ratio {r['linear_ratio']}; nonlinear {nl.status} ratio "
                      f"{r['nonlinear_ratio']}", file=sys.stderr)  # fmt: skip
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=24, help="linear plucks (calibrate_plucks draw)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=1, help="seeds per nonlinear kind and rate")
    ap.add_argument("--rates", type=float, nargs="+", default=[200.0, 860.0])
    ap.add_argument("--hold-s", type=float, default=0.5, help="held stretch before the release")
    ap.add_argument("--out", help="also write the per-case rows here (JSON)")
    args = ap.parse_args(argv)
    lin = linear_cases(args.cases, args.seed)
    nl = nonlinear_cases(args.seeds, args.rates, args.hold_s)
    by_kind = {}
    for kind in KINDS:
        rs = [r for r in nl if r["kind"] == kind]
        by_kind[kind] = {
            "n": len(rs),
            "linear_floor_check": sum(r["linear_floor_check"] for r in rs),
            "linear_statuses": [r["linear_status"] for r in rs],
            "linear_ratios": [r["linear_ratio"] for r in rs],
            "nonlinear_floor_check": sum(r["nonlinear_floor_check"] for r in rs),
            "nonlinear_ratios": [r["nonlinear_ratio"] for r in rs],
        }
    result = {
        "benchmark": "noise_floor",
        "note": "timings not reported; shared machine",
        "linear_plucks": {
            "n": len(lin),
            "tested": sum(r.get("tested", 0) > 0 for r in lin),
            "floor_check": sum(r["floor_check"] for r in lin),
            "statuses": [r["status"] for r in lin],
            "max_ratio": max((x for r in lin for x in r.get("ratios", [])), default=None),
        },
        "scipy_plucks_with_hold": by_kind,
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"linear": lin, "nonlinear": nl}, f, indent=1, default=str)
    print(json.dumps(result, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
