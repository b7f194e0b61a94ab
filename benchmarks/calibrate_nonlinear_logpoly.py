"""The log-polynomial backbone on independent SciPy plucks: pulls of f(a) and ζ(a) at the smallest
informed amplitude and in the middle of the range, beside the parametric fit's.

The plucks are ``benchmarks/calibrate_nonlinear.py``'s (SciPy ``solve_ivp``, one mode with
cubic stiffening and velocity-squared damping, volts, 40 dB). The log-polynomial backbone
(:func:`whiskerid.fit._nonlinear._select.calibrate_logpoly_backbone`, knots chosen by its criterion)
identifies ``f(a)`` and ``ζ(a)`` over the recorded amplitudes, so its truth is the true
backbone at the same amplitude: the harmonic-balance ``f(a) = f₀(1 + 3γa²/8)`` and, because
its flow is ``ȧ = −ζ(a)ω(a)a`` where the parametric one's is ``ȧ = −ζ_p(a)ω₀a``,
``ζ(a) = ζ_p(a)·f₀/f(a)`` with ``ζ_p = ζ₀ + 4c·a·ω/(3πω₀)`` (first order, as the generator's
strengths are small). The parametric fit's pulls (f₀, ζ₀) are printed beside it.

    python benchmarks/calibrate_nonlinear_logpoly.py [--seeds 2] [--kinds linear cubic+quadratic]

Prints one JSON object: per pluck the chosen knots and pulls, then the largest |pull|.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibrate_nonlinear import KINDS, nonlinear_case, pull

from whiskerid.fit import calibrate
from whiskerid.fit._nonlinear import backbone_at, calibrate_logpoly_backbone, calibrate_nonlinear
from whiskerid.model import NonlinearMode


def true_backbone(truth: dict, a: float) -> tuple[float, float]:
    """``f(a)`` (Hz) and the flexible flow's ``ζ(a)`` of the generator's mode (tip amplitude)."""
    m = NonlinearMode(truth["f1_hz"], truth["zeta"], gamma_per_m2=truth["gamma_per_m2"],
                      quadratic_per_m=truth["quadratic_per_m"])  # fmt: skip
    f = float(m.frequency_hz(a))
    return f, float(m.zeta(a)) * truth["f1_hz"] / f


def run(kind: str, rate: float, seed: int, knots) -> dict:
    record, obs, truth = nonlinear_case(kind, rate, seed)
    lin = calibrate(record, obs, n_modes=1)
    par = calibrate_nonlinear(lin, [obs])
    t0 = time.perf_counter()
    spl = calibrate_logpoly_backbone(lin, [obs], knots=knots)
    row = {"kind": kind, "rate_hz": rate, "seed": seed, "status": spl.status,
           "knots": spl.diagnostics["knot_selection"]["chosen"],
           "seconds_logpoly": time.perf_counter() - t0,
           "parametric_status": par.status,
           "parametric_pull_f0": pull(par, "f1_hz", truth["f1_hz"]),
           "parametric_pull_zeta0": pull(par, "zeta", truth["zeta"])}  # fmt: skip
    a_lo, a_hi = spl.diagnostics["a_lo_m"], spl.diagnostics["a_ref_m"]
    for name, a in (("lo", a_lo), ("mid", float(np.sqrt(a_lo * a_hi)))):
        b = backbone_at(spl, a)
        f, z = true_backbone(truth, a)
        row[f"pull_f_{name}"] = (b["f_hz"] - f) / b["f_std"]
        row[f"pull_zeta_{name}"] = (b["zeta"] - z) / b["zeta_std"]
    print(json.dumps(row), file=sys.stderr)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--rates", type=float, nargs="+", default=[200.0, 860.0])
    kinds = ["linear", "cubic-0.4%", "quadratic-1.25x", "cubic+quadratic"]
    ap.add_argument("--kinds", nargs="+", default=kinds, choices=list(KINDS))
    ap.add_argument("--knots", type=int, nargs="+", default=[2, 3])
    args = ap.parse_args(argv)
    rows = [run(k, r, s, tuple(args.knots)) for k in args.kinds for r in args.rates
            for s in range(args.seeds)]  # fmt: skip
    keys = [k for k in rows[0] if k.startswith("pull_")]
    worst = {k: float(np.nanmax(np.abs([r[k] for r in rows]))) for k in keys}
    worst_par = {k: float(np.nanmax(np.abs([r[k] for r in rows])))
                 for k in ("parametric_pull_f0", "parametric_pull_zeta0")}  # fmt: skip
    statuses = {s: sum(r["status"] == s for r in rows) for s in {r["status"] for r in rows}}
    print(json.dumps({"rows": rows, "max_abs_pull": worst, "parametric_max_abs_pull": worst_par,
                      "statuses": statuses}, indent=1))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
