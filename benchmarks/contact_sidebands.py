"""When do the paper's sidebands appear? The contact simulator (the whisker's tip on the
ground: Hunt–Crossley contact, smoothed Coulomb friction) on every terrain at the five
speeds, under five conditions (the default preload of 1 mm, a light one of 0.5 mm and a
heavy one of 2.5 mm; a drivetrain perturbation ten times stronger with the default and
the light preload), each run
analysed by ``whiskerid analyze`` (dominant line, perturbation frequency, sideband test).
Also the contact simulator's cost per simulated second against the linear simulator's,
on the same runs. Prints one JSON object; writes the figure of the default condition
with ``--figure PNG``.

    .venv/bin/python benchmarks/contact_sidebands.py [--duration 10] [--figure PNG]
        [--conditions NAME ...]

With ``--realisations N`` it measures instead how often sidebands are found: ``N`` runs
(different run numbers: different ground, speed, contact parameters) per terrain, speed and
condition, each analysed alone at each of ``--lengths`` (the first seconds of one run of the
longest length); per cell the share found with its Wilson 95 % interval, and the median
length at which the test reaches 80 % power for the sidebands measured
(``length_80_s``)::

    .venv/bin/python benchmarks/contact_sidebands.py --realisations 20 --lengths 10 20 \
        --terrains sand --speeds 0.3 --conditions "heavy preload 2.5 mm"
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import whiskerid as wi
from whiskerid.classify import analyze_dataset
from whiskerid.io import write_csv
from whiskerid.terrain import RunSpec, iter_contact_runs

CONDITIONS = {
    "default (preload 1 mm)": {"preload_m": 1e-3, "drive_gain": 1.0},
    "light preload 0.5 mm": {"preload_m": 5e-4, "drive_gain": 1.0},
    "heavy preload 2.5 mm": {"preload_m": 2.5e-3, "drive_gain": 1.0},
    "perturbation x10": {"preload_m": 1e-3, "drive_gain": 10.0},
    "perturbation x10, light preload": {"preload_m": 5e-4, "drive_gain": 10.0},
}


def run_condition(specs, duration, options, rtol, figure=None):
    t0 = time.perf_counter()
    recs = list(iter_contact_runs(specs, duration_s=duration, batch=len(specs), rtol=rtol,
                                  **options))  # fmt: skip
    wall = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        for s, r in zip(specs, recs, strict=True):
            write_csv(Path(tmp) / s.terrain / f"{s.terrain}_v{s.speed_mps:.2f}.csv", r)
        res = analyze_dataset(tmp, segment_s=2.0)
    if figure is not None:
        from whiskerid.plot import plot_sidebands

        plot_sidebands(figure, res)
    rows = []
    for s, r in zip(specs, recs, strict=True):
        g = res["groups"][s.terrain][str(round(s.speed_mps, 4))]
        sb = g["sidebands"]
        rows.append({
            "terrain": s.terrain, "speed_mps": s.speed_mps,
            "contact_fraction": float(r.meta["contact_fraction"]),
            "stick_fraction": float(r.meta["stick_fraction"]),
            "perturbation_hz": g["perturbation_hz"], "dominant_hz": g["dominant_hz"],
            "dominant_at_perturbation": g["dominant_at_perturbation"],
            "carrier_p_value": sb.get("carrier_p_value"), "power": sb.get("power"),
            "delta_hz": sb.get("delta_hz"), "p_value": sb.get("p_value"),
            "sidebands": sb["present"],
        })  # fmt: skip
    return rows, res["claim"], wall


def wilson(k: int, n: int, z: float = 1.96) -> list[float]:
    """Wilson score interval of a binomial share ``k/n`` (95 % by default)."""
    p = k / n
    mid = (p + z**2 / (2 * n)) / (1 + z**2 / n)
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / (1 + z**2 / n)
    return [round(max(float(mid - half), 0.0), 3), round(min(float(mid + half), 1.0), 3)]


def realisations(args) -> dict:
    longest = max(args.lengths)
    cells = []
    for name in args.conditions:
        for terrain in args.terrains:
            for v in args.speeds:
                specs = [RunSpec(terrain, v, r) for r in range(args.realisations)]
                t0 = time.perf_counter()
                recs = list(iter_contact_runs(specs, duration_s=longest, batch=len(specs),
                                              rtol=args.rtol, **CONDITIONS[name]))  # fmt: skip
                wall = time.perf_counter() - t0
                for length in args.lengths:
                    with tempfile.TemporaryDirectory() as tmp:
                        for s, r in zip(specs, recs, strict=True):
                            keep = r.t - r.t[0] <= length
                            cut = wi.Recording(t=r.t[keep], meta=r.meta,
                                               columns={"adc": r.columns["adc"][keep]})  # fmt: skip
                            write_csv(Path(tmp) / f"run{s.run}" / "r.csv", cut)
                        res = analyze_dataset(tmp, segment_s=2.0)
                    sbs = [next(iter(g.values()))["sidebands"] for g in res["groups"].values()]
                    k = sum(bool(sb["present"]) for sb in sbs)
                    # runs with no side line measured need an unbounded length: infinite
                    l80 = [sb.get("length_80_s") or np.inf for sb in sbs]
                    med = float(np.median(l80))
                    cells.append({
                        "condition": name, "terrain": terrain, "speed_mps": v,
                        "length_s": length, "found": k, "of": len(sbs),
                        "share": round(k / len(sbs), 3), "wilson95": wilson(k, len(sbs)),
                        "carrier_significant": sum(sb["carrier_p_value"] < 0.01 for sb in sbs),
                        "median_length_80_s": round(med, 1) if np.isfinite(med) else None,
                        "length_80_s": [round(x, 1) if np.isfinite(x) else None for x in l80],
                        "contact_fraction_median": round(float(np.median(
                            [float(r.meta["contact_fraction"]) for r in recs])), 3),
                        "simulation_wall_s": round(wall, 1),
                    })  # fmt: skip
                    print(json.dumps(cells[-1]), file=sys.stderr, flush=True)
    return {"realisations": args.realisations, "lengths_s": args.lengths, "rtol": args.rtol,
            "cells": cells,
            "note": "each run analysed alone by whiskerid analyze (alpha 0.01); shorter "
                    "lengths are the first seconds of the same runs"}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, default=1e-4, help="the solver's relative tolerance")
    ap.add_argument("--speeds", type=float, nargs="+", default=list(wi.SPEEDS_MPS))
    ap.add_argument("--figure", type=Path, help="the figure of the first condition run")
    ap.add_argument("--conditions", nargs="+", choices=list(CONDITIONS), default=list(CONDITIONS))
    ap.add_argument("--realisations", type=int, help="runs per cell: the detection study")
    ap.add_argument("--lengths", type=float, nargs="+", default=[10.0, 20.0])
    ap.add_argument("--terrains", nargs="+", default=list(wi.TERRAINS))
    args = ap.parse_args()
    if args.realisations:
        print(json.dumps(realisations(args), indent=1))
        return
    specs = [RunSpec(t, v, 0) for t in wi.TERRAINS for v in args.speeds]
    simulated = len(specs) * (args.duration + 1.5)  # settling and tail included
    out = {"runs": len(specs), "duration_s": args.duration, "rtol": args.rtol,
           "conditions": {}}  # fmt: skip
    for k, name in enumerate(args.conditions):
        options = CONDITIONS[name]
        rows, claim, wall = run_condition(specs, args.duration, options, args.rtol,
                                          args.figure if k == 0 else None)  # fmt: skip
        share = float(np.mean([r["sidebands"] for r in rows]))
        out["conditions"][name] = {"rows": rows, "claim": claim, "sidebands_share": share,
                                   "wall_s": round(wall, 1)}  # fmt: skip
        if k == 0:
            out["contact_s_per_simulated_s"] = round(wall / simulated, 4)
        print(f"{name}: {out['conditions'][name]['sidebands_share']:.2f} with sidebands, "
              f"{wall:.0f} s", flush=True)  # fmt: skip
    t0 = time.perf_counter()
    wi.synthesize_runs(specs, duration_s=args.duration)
    out["linear_s_per_simulated_s"] = round((time.perf_counter() - t0) / simulated, 5)
    out["note"] = ("wall times include compilation, on a shared, loaded 2-core machine; "
                   "seconds of computing per simulated second of one run")  # fmt: skip
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
