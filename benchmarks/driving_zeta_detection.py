"""Benchmark: is a lasting ζ ×1.5 found from driving data, and how often is a healthy drive
flagged? Scaled down to fit a shared machine.

``--whiskers`` whiskers (f1 25–70 Hz, ζ 0.02–0.08 drawn at random), each driven
``--sessions`` times for ``--minutes`` minutes (``tests/generators/driving.py``: SciPy alone,
not the project's terrain simulator); every other whisker's ζ is ×1.5 from session
``--first`` on, and each drive's f1 and ζ move by 0.2 % and 3 % (the mount, the temperature).
Every drive is identified by :func:`whiskerid.fleet.identify_driving` from the same record
(f1 2 % high, ζ 0.04), logged as a health-log row and read by
:func:`whiskerid.fleet.check_fleet` with its defaults. Printed (JSON): damaged whiskers
whose ζ change is found, and flags on healthy whisker-sessions (false alarms).

Run: ``python benchmarks/driving_zeta_detection.py [--whiskers 6 --sessions 4 --minutes 5]``.
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

from whiskerid.fleet import check_fleet, health_row, identify_driving  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--whiskers", type=int, default=6)
    ap.add_argument("--sessions", type=int, default=4)
    ap.add_argument("--first", type=int, default=3, help="first damaged session (1-based)")
    ap.add_argument("--minutes", type=int, default=5)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows, truth = [], {}
    for w in range(args.whiskers):
        rng = np.random.default_rng(9000 + w)
        f1, zeta = rng.uniform(25, 70), rng.uniform(0.02, 0.08)
        damaged = w % 2 == 1
        truth[f"w{w}"] = {"f1": f1, "zeta": zeta, "damaged": damaged, "zeta_read": []}
        for s in range(1, args.sessions + 1):
            z = zeta * (1.5 if damaged and s >= args.first else 1.0) * (1 + 0.03 * rng.normal())
            f = f1 * (1 + 0.002 * rng.normal())
            fit = identify_driving(drive(rng, f, z, minutes=args.minutes), RATE, 1.02 * f1, 0.04)
            truth[f"w{w}"]["zeta_read"].append(round(fit.zeta / z - 1, 3))
            rows.append({**health_row(f"w{w}", f"s{s:02d}", fit, []), "source": "drive"})
            print(f"w{w} s{s}: {fit.status} zeta {fit.zeta:.4g} (truth {z:.4g})",
                  file=sys.stderr, flush=True)  # fmt: skip
    result = check_fleet(rows)
    flagged = {(f["whisker"], f["session"], f["parameter"]) for f in result.flags}
    found = [
        w
        for w, t in truth.items()
        if t["damaged"]
        and any((w, f"s{s:02d}", "zeta") in flagged for s in range(args.first, args.sessions + 1))
    ]
    healthy = [
        (w, f"s{s:02d}")
        for w, t in truth.items()
        for s in range(3, args.sessions + 1)
        if not t["damaged"] or s < args.first
    ]
    false = [h for h in healthy if any((*h, p) in flagged for p in ("zeta", "f1_hz"))]
    print(json.dumps({
        "damaged": sum(t["damaged"] for t in truth.values()), "zeta_change_found": len(found),
        "healthy_sessions_checked": len(healthy), "false_alarms": len(false),
        "flags": sorted(map(list, flagged)), "whiskers": truth,
        "elapsed_s": round(time.perf_counter() - t0, 1),
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
