"""Benchmark: the bias of ζ (and f1) from driving data over a grid of (f1, ζ).

Drives from an independent generator (``tests/generators/driving.py``: one mode integrated
by SciPy's ``lsim``, base acceleration white noise through a random Butterworth low-pass
and a motor tone, 16-bit codes; not the project's terrain simulator), ``--minutes`` one-minute
recordings each, ``--seeds`` drives per cell. :func:`whiskerid.fleet.identify_driving`
starts from f1 2 % high and ζ 0.04 (a whisker that changed since its record). Printed
(JSON): per cell the mean relative error of ζ and f1 (%), their spread over seeds, and the
statuses.

Run: ``python benchmarks/driving_damping_bias.py [--seeds 2 --minutes 5]``.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from generators.driving import RATE, drive  # noqa: E402

from whiskerid.fleet import identify_driving  # noqa: E402

F1S = (20.5, 46.0, 75.0)
ZETAS = (0.02, 0.05, 0.08)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--minutes", type=int, default=5)
    args = ap.parse_args()
    cells = []
    t0 = time.perf_counter()
    for i, f1 in enumerate(F1S):
        for j, zeta in enumerate(ZETAS):
            ez, ef, status = [], [], []
            for s in range(args.seeds):
                rng = np.random.default_rng(1000 * i + 100 * j + s)
                fit = identify_driving(drive(rng, f1, zeta, minutes=args.minutes), RATE,
                                       1.02 * f1, 0.04)  # fmt: skip
                status.append(fit.status)
                ez.append(100 * (fit.zeta / zeta - 1))
                ef.append(100 * (fit.f1_hz / f1 - 1))
            cells.append({
                "f1_hz": f1, "zeta": zeta, "zeta_bias_pct": float(np.mean(ez)),
                "zeta_sd_pct": float(np.std(ez, ddof=1)) if len(ez) > 1 else None,
                "f1_bias_pct": float(np.mean(ef)), "statuses": status,
            })  # fmt: skip
    worst = max(abs(c["zeta_bias_pct"]) for c in cells)
    print(json.dumps({"minutes": args.minutes, "seeds": args.seeds, "cells": cells,
                      "worst_abs_zeta_bias_pct": worst,
                      "elapsed_s": round(time.perf_counter() - t0, 1)}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
