"""Benchmark: a whisker's f1 and ζ from 10 minutes of simulated driving (no pluck).

Each drive is ten 60 s runs of the terrain simulator (:func:`whiskerid.terrain.synthesize_runs`:
the exact modal model driven by the base motion of the seven terrains, the Hall sensor and
the ADS1115 at 200 Hz), terrain ``k mod 7`` for run ``k`` at a speed drawn from the five
nominal ones, of the paper's whisker or of one whose f1 is ``--drop`` lower (its coil's shear
modulus times the factor squared). :func:`whiskerid.fleet.identify_driving` starts from the
paper record's f1 and ζ in every case (a whisker that changed since it was calibrated).

Printed (JSON): per drive the truth, the estimates, their 1σ, the relative errors and the
pulls; and the largest errors.

Run: ``python benchmarks/fleet_driving.py [--drives 6]``.
"""

import argparse
import json
import time
from dataclasses import replace

import numpy as np


def drive(seed: int, factor: float):
    from whiskerid.model import paper_record
    from whiskerid.terrain import SPEEDS_MPS, TERRAINS, RunSpec, synthesize_runs

    rec = paper_record()
    if factor != 1.0:
        s = rec.structure
        rec = rec.replace(structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * factor**2))
    rng = np.random.default_rng(seed)
    specs = [RunSpec(TERRAINS[i % 7], float(rng.choice(SPEEDS_MPS)), seed * 100 + i)
             for i in range(10)]  # fmt: skip
    runs = synthesize_runs(specs, record=rec, duration_s=60.0, seed=seed)
    signals = [(f"{s.terrain}@{s.speed_mps:g}", r.columns["adc"].astype(float))
               for s, r in zip(specs, runs, strict=True)]  # fmt: skip
    return rec, signals


def main() -> None:
    from whiskerid.fleet import identify_driving
    from whiskerid.model import paper_record

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=6)
    ap.add_argument("--drop", type=float, default=0.03, help="f1 drop of every second drive")
    args = ap.parse_args()
    paper = paper_record()
    f1_start = float(paper.whisker().natural_frequencies_hz[0])
    zeta = float(paper.zeta)
    out = []
    for k in range(args.drives):
        factor = 1.0 - args.drop if k % 2 else 1.0
        rec, signals = drive(k + 1, factor)
        t0 = time.perf_counter()
        fit = identify_driving(signals, 200.0, f1_start, zeta)
        f1 = float(rec.whisker().natural_frequencies_hz[0])
        out.append({
            "seed": k + 1, "f1_factor": factor, "f1_true": f1, "zeta_true": zeta,
            "status": fit.status, "f1_hz": fit.f1_hz, "f1_std": fit.f1_std, "zeta": fit.zeta,
            "zeta_std": fit.zeta_std,
            "f1_error_pct": 100 * (fit.f1_hz / f1 - 1),
            "zeta_error_pct": 100 * (fit.zeta / zeta - 1),
            "f1_pull": (fit.f1_hz - f1) / fit.f1_std,
            "zeta_pull": (fit.zeta - zeta) / fit.zeta_std,
            "blocks_used": sum(b["status"] == "ok" for b in fit.blocks),
            "identify_s": round(time.perf_counter() - t0, 1),
        })  # fmt: skip
        print(json.dumps(out[-1]), flush=True)
    print(json.dumps({
        "max_abs_f1_error_pct": max(abs(d["f1_error_pct"]) for d in out),
        "max_abs_zeta_error_pct": max(abs(d["zeta_error_pct"]) for d in out),
        "drives": len(out),
    }))  # fmt: skip


if __name__ == "__main__":
    main()
