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
"""

import argparse
import json
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
            "carrier_snr_db": sb.get("carrier_snr_db"), "carrier_p": sb.get("carrier_p"),
            "delta_hz": sb.get("delta_hz"), "p_value": sb.get("p_value"),
            "sidebands": sb["present"],
        })  # fmt: skip
    return rows, res["claim"], wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, default=1e-4, help="the solver's relative tolerance")
    ap.add_argument("--speeds", type=float, nargs="+", default=list(wi.SPEEDS_MPS))
    ap.add_argument("--figure", type=Path, help="the figure of the first condition run")
    ap.add_argument("--conditions", nargs="+", choices=list(CONDITIONS), default=list(CONDITIONS))
    args = ap.parse_args()
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
