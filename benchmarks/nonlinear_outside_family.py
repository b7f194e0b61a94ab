"""Nonlinear fits of plucks inside and outside their family: status counts and pulls.

The plucks are made by ``tests/generators/nonlinear_plucks.py`` (SciPy ``solve_ivp``, not the
project's model): the paper whisker's first mode at 200 Hz, read by the Hall sensor through
the ADS1115's code step, 40 dB, with cubic stiffness ± and velocity-squared damping (inside
the nonlinear fit's family), cubic damping ``u²u̇`` (ζ ∝ a², outside), Coulomb friction
(inside), quadratic stiffness (inside only by its ``kappa`` term's stand-in) or none. Each
is fitted by ``calibrate(..., model="nonlinear")``; the table gives per kind the status
counts, which checks fired (``backbone-misfit`` is the model-free backbone check of
``whiskerid.fit._nonlinear._backbone_check``) and the pulls ``(estimate − truth)/1σ`` of f₀
and ζ₀ of the fits that say ``ok``.

Usage::

    python benchmarks/nonlinear_outside_family.py [--seeds 2] [--kinds linear coulomb ...]

Prints one JSON object.
"""

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from generators.nonlinear_plucks import KINDS, pluck

from whiskerid.fit import Observation, calibrate, nominal_gain
from whiskerid.fit._nonlinear import tip_per_sensor
from whiskerid.model import paper_record


def one(kind, seed):
    record = paper_record()
    w = record.whisker().with_modes(1)
    ratio = float(tip_per_sensor(w, record.sensor_position_m))
    gain = nominal_gain(record, "voltage")
    f0 = float(w.natural_frequencies_hz[0])
    t, y, truth = pluck(kind, seed, f0_hz=f0, gain_v_per_m=gain,
                        amplitude_m=(1e-3 / ratio, 3e-3 / ratio))  # fmt: skip
    obs = Observation(t, y, observable="voltage", gain=gain, x_m=record.sensor_position_m)
    start = time.perf_counter()
    nl = calibrate(record, obs, n_modes=1, model="nonlinear")
    p = nl.params
    bc = nl.diagnostics.get("backbone_check", {})
    t_max = max((max(abs(b["t_df_hz"]), abs(b["t_dzeta"])) for b in bc.get("bands", [])),
                default=float("nan"))  # fmt: skip
    return {
        "kind": kind,
        "seed": seed,
        "status": nl.status,
        "checks": sorted(nl.checks),
        "model": nl.diagnostics.get("model", "linear"),
        "pull_f0": (p["f1_hz"]["value"] - f0) / p["f1_hz"]["std"],
        "pull_zeta0": (p["zeta"]["value"] - truth["zeta0"]) / p["zeta"]["std"],
        "zeta0_rel_error": p["zeta"]["value"] / truth["zeta0"] - 1,
        "backbone_bands": len(bc.get("bands", [])),
        "backbone_max_abs_t": t_max,
        "seconds": time.perf_counter() - start,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    args = ap.parse_args(argv)
    rows = [one(k, s) for k in args.kinds for s in range(args.seeds)]
    table = {}
    for k in args.kinds:
        mine = [r for r in rows if r["kind"] == k]
        ok = [r for r in mine if r["status"] == "ok"]
        table[k] = {
            "seeds": len(mine),
            "status": dict(Counter(r["status"] for r in mine)),
            "checks": dict(Counter(c for r in mine for c in r["checks"])),
            "ok_pull_f0": [round(r["pull_f0"], 2) for r in ok],
            "ok_pull_zeta0": [round(r["pull_zeta0"], 2) for r in ok],
            "ok_with_abs_pull_over_3": sum(
                max(abs(r["pull_f0"]), abs(r["pull_zeta0"])) > 3 for r in ok
            ),
        }
    print(json.dumps({"table": table, "rows": rows}, indent=1, default=float))


if __name__ == "__main__":
    main()
