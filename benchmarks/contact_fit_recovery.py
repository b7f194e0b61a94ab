"""Fitted contact parameters on simulated recordings of known parameters: pulls, what the
data determine (Fisher information against the prior's) and what is degenerate (the
correlation of the estimate). Prints one JSON object.

Each case is a 20 s recording of the statistical twin (a ground profile drawn with random
numbers the fit never sees), fitted as ``benchmarks/contact_features.py`` fits a recording.

    .venv/bin/python benchmarks/contact_fit_recovery.py [--draws 1 --duration 3 --max-steps 12]
"""

import argparse
import json
import time

import numpy as np

#: (speed m/s, k N/m, preload m, friction, roughness m, slope): soft to stiff grounds,
#: light to heavy preloads, smooth to rough profiles
CASES = [
    (0.2, 200.0, 1.2e-3, 0.5, 2e-4, 2.3),
    (0.1, 60.0, 0.8e-3, 0.4, 1e-4, 2.0),
    (0.3, 1500.0, 1.0e-3, 0.8, 3e-4, 2.6),
    (0.15, 400.0, 2.0e-3, 0.6, 5e-4, 1.8),
    (0.25, 3000.0, 0.6e-3, 0.7, 8e-5, 2.2),
    (0.2, 100.0, 0.5e-3, 0.5, 4e-4, 2.8),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=1)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--max-steps", type=int, default=12)
    ap.add_argument(
        "--stiffness-starts",
        type=float,
        nargs="*",
        default=[],
        help="further starting stiffnesses (N/m)",
    )
    args = ap.parse_args()

    import equinox as eqx

    from whiskerid.terrain import PARAM_NAMES, contact_twin, fit_contact

    volts_of = eqx.filter_jit(lambda tw, p: tw.volts(p))
    twin = contact_twin(0.2, draws=args.draws, duration_s=args.duration, seed=0)
    rows = []
    for i, (v, k, d0, mu, rho, w) in enumerate(CASES):
        truth = np.array([np.log(k), np.log(d0), np.log(mu), np.log(rho), w])
        case_twin = contact_twin(v, draws=1, duration_s=20.0, seed=11 + i)
        volts = np.asarray(volts_of(case_twin, truth))
        t0 = time.perf_counter()
        fit = fit_contact(
            volts,
            v,
            twin=twin.at_speed(v),
            max_steps=args.max_steps,
            stiffness_starts=tuple(args.stiffness_starts),
        )
        rows.append({
            "speed": v, "truth": truth.round(3).tolist(), "estimate": fit.params.round(3).tolist(),
            "sd": fit.sd.round(3).tolist(),
            "pull": ((fit.params - truth) / fit.sd).round(2).tolist(),
            "data_information": fit.data_information.round(2).tolist(),
            "corr_stiffness_preload": round(float(fit.correlation[0, 1]), 3),
            "chi2": round(fit.chi2, 2), "steps": fit.steps, "converged": fit.converged,
            "seconds": round(time.perf_counter() - t0, 2),
        })  # fmt: skip
    pulls = np.array([r["pull"] for r in rows])
    info = np.array([r["data_information"] for r in rows])
    est = np.array([r["estimate"] for r in rows])
    tru = np.array([r["truth"] for r in rows])
    from whiskerid.terrain._contact_fit import PRIOR_SD

    summary = {
        name: {"rms_pull": round(float(np.sqrt(np.mean(pulls[:, j] ** 2))), 2),
               "max_abs_pull": round(float(np.abs(pulls[:, j]).max()), 2),
               "abs_error_per_case": np.abs(est[:, j] - tru[:, j]).round(2).tolist(),
               "median_data_over_prior_information":
                   round(float(np.median(info[:, j]) * PRIOR_SD[j] ** 2), 2)}
        for j, name in enumerate(PARAM_NAMES)
    }  # fmt: skip
    print(json.dumps({"benchmark": "contact_fit_recovery", "draws": args.draws,
                      "duration_s": args.duration, "max_steps": args.max_steps,
                      "stiffness_starts": args.stiffness_starts,
                      "summary": summary, "cases": rows,
                      "note": "shared, loaded 2-core machine"}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
