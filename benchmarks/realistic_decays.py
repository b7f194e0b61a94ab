"""The independent generator's realistic recordings: decays counted, and f_1's pulls of the
fits reported ``ok``.

``tests/generators/realistic_decays.py`` (NumPy/SciPy, not whiskerid's model) makes
recordings as a bench gives them: three modes (1 : 6.27 : 17.55, each its own damping), pink
and white noise, drift, 50 Hz hum, a hand's hold with tremor, 1–4 taps at random phases, a
200 Hz ADS1115 Hall sensor or a jittered 4 kHz accelerometer; a fifth start mid-decay.

For seeds ``0..N-1`` (Hall on even seeds, accelerometer on odd) it counts the decays
:func:`whiskerid.fit.find_decays` finds against those made. With ``--fit K`` the first ``K``
accelerometer recordings are also calibrated (linear model, one mode, all decays jointly)
with a beam record whose nominal f_1 is within 10 % of the truth (a user knows roughly what
beam they hold), and the pull of f_1, ``(fit − truth)/σ``, is reported by status.

    .venv/bin/python benchmarks/realistic_decays.py [--n 200] [--fit 0]
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from whiskerid.fit import find_decays

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "examples"))
from calibrate_cantilever import beam_record  # noqa: E402
from generators.realistic_decays import recording  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="recordings to count on")
    ap.add_argument("--fit", type=int, default=0, help="accelerometer recordings to calibrate")
    args = ap.parse_args(argv)
    if args.n < 1 or args.fit < 0:
        print("--n must be ≥ 1 and --fit ≥ 0", file=sys.stderr)
        return 2
    import whiskerid as wi

    exact, wrong, pulls = 0, [], []
    t_start = time.perf_counter()
    fitted = 0
    for seed in range(args.n):
        sensor = "hall" if seed % 2 == 0 else "accelerometer"
        t, y, truth = recording(np.random.default_rng(seed), sensor)
        decays = find_decays(t, y)
        if len(decays) == truth.n_decays:
            exact += 1
        else:
            wrong.append({"seed": seed, "sensor": sensor, "made": truth.n_decays,
                          "found": len(decays)})  # fmt: skip
        if sensor == "accelerometer" and fitted < args.fit and decays:
            fitted += 1
            rng = np.random.default_rng(10_000 + seed)
            # f_1 ∝ 1/L² (about; the 5 g tip mass bends it): 16.36 Hz at 30 cm
            length = 0.30 * np.sqrt(16.36 / (truth.f1_hz * rng.uniform(0.9, 1.1)))
            base = beam_record(30)
            record = base.replace(
                structure=wi.UniformBeam(
                    length_m=float(length), youngs_modulus_pa=70e9, density_kg_m3=2700.0,
                    section="rectangular", width_m=0.05, thickness_m=0.002,
                ),
                sensor_position_m=float(length) - 0.06,
            )  # fmt: skip
            obs = wi.Observation(t, y, observable="acceleration", name=f"seed-{seed}")
            obs = [obs.window(d.start_s, d.end_s) for d in decays]
            try:
                cal = wi.calibrate(record, obs if len(obs) > 1 else obs[0])
                p = cal.params["f1_hz"]
                pull = (p["value"] - truth.f1_hz) / p["std"]
                pulls.append({"seed": seed, "status": cal.status, "checks": sorted(cal.checks),
                              "pull_f1": round(pull, 2), "f1_hz": p["value"],
                              "truth_hz": truth.f1_hz})  # fmt: skip
            except Exception as e:  # a benchmark reports every failure
                pulls.append({"seed": seed, "status": "error", "error": str(e)[:200]})
            print(json.dumps(pulls[-1]), file=sys.stderr)
    ok = [p for p in pulls if p["status"] == "ok"]
    out = {
        "recordings": args.n,
        "count_exact": exact,
        "count_exact_share": exact / args.n,
        "wrong": wrong,
        "seconds": round(time.perf_counter() - t_start, 1),
    }
    if args.fit:
        out["fits"] = pulls
        out["status_counts"] = {s: sum(p["status"] == s for p in pulls)
                                for s in sorted({p["status"] for p in pulls})}  # fmt: skip
        out["ok_with_abs_pull_over_3"] = sum(abs(p["pull_f1"]) > 3 for p in ok)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
