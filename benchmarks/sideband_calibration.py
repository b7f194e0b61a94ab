"""Calibration of the sideband tests on recordings whose answer is known: the null library
of ``tests/generators/sideband_nulls.py`` (ringing, ringing with a tone, one-sided lines,
a line in coloured noise, random amplitude modulation in a 1 Hz band, phase jitter) and
its positives (AM, FM, asymmetric sidebands, on a 0.25 Hz bin and half-way between).

Per null kind: the false-alarm rate (``p < α``) and the Kolmogorov–Smirnov p-value of the
p-values against the uniform distribution, for the Welch test (``sideband_test``, what
``whiskerid analyze`` used before) and the multitaper line test
(``line_sideband_test``, what it uses now). Per positive: the detection rate
(``present``) against depth and SNR, on-bin and half-bin. Prints one JSON object.

    .venv/bin/python benchmarks/sideband_calibration.py [--groups 300] [--power-groups 15]
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from generators import sideband_nulls as gen  # noqa: E402

from whiskerid.classify import line_sideband_test, sideband_test, welch_dof, welch_power  # noqa: E402

FS = gen.FS
SEG = 800  # analyze's default 4 s segments


def _dominant(x):
    f = np.fft.rfftfreq(SEG, 1 / FS)
    p, _ = welch_power(x, SEG)
    p[f < 2] = 0
    return float(f[np.argmax(p)])


def welch(x, fc, alpha):
    wins = [x[s : s + 2 * SEG] for s in range(0, x.size - 2 * SEG + 1, 2 * SEG)]
    out = [welch_power(w, SEG) for w in wins]
    powers = np.stack([p for p, _ in out])
    return sideband_test(powers, FS / SEG, fc, welch_dof(out[0][1]), alpha=alpha)


def line(x, fc, alpha):
    return line_sideband_test([x], FS, fc, alpha=alpha)


def nulls(groups, alpha, duration_s):
    table = {}
    for k, kind in enumerate(gen.NULL_KINDS):
        rng = np.random.default_rng([47, k])
        ps = {"welch": [], "line": []}
        present = {"welch": 0, "line": 0}
        t0 = time.perf_counter()
        for _ in range(groups):
            x, fc = gen.null(kind, rng, duration_s)
            fc = _dominant(x) if fc is None else fc
            for name, test in (("welch", welch), ("line", line)):
                r = test(x, fc, alpha)
                ps[name].append(r["p_value"])
                present[name] += bool(r["present"])
        table[kind] = {
            name: {"false_alarm": round(float(np.mean(np.array(p) < alpha)), 4),
                   "present_rate": round(present[name] / groups, 4),
                   "ks_p": float(f"{stats.kstest(p, 'uniform').pvalue:.3g}"),
                   "share_p_eq_1": round(float(np.mean(np.array(p) >= 1.0)), 3)}
            for name, p in ps.items()
        }  # fmt: skip
        table[kind]["wall_s"] = round(time.perf_counter() - t0, 1)
        print(kind, json.dumps(table[kind]), file=sys.stderr, flush=True)
    return table


def power(groups, alpha, duration_s):
    rows = []
    cells = (("am", (0.03, 0.1, 0.3), (20.0, 30.0, 40.0)), ("fm", (0.3,), (30.0,)),
             ("asymmetric", (0.3,), (30.0,)))  # fmt: skip
    for kind, depths, snrs in cells:
        for depth in depths:
            for snr in snrs:
                row = {"kind": kind, "depth": depth, "snr_db": snr}
                for place in ("on", "half"):
                    rng = np.random.default_rng([47, 1000, round(depth * 1000), int(snr)])
                    found = {"welch": 0, "line": 0}
                    for _ in range(groups):
                        x, fc = gen.positive(kind, rng, duration_s, depth=depth, snr_db=snr,
                                             placement=place)  # fmt: skip
                        found["welch"] += bool(welch(x, fc, alpha)["present"])
                        found["line"] += bool(line(x, fc, alpha)["present"])
                    row[place] = {n: round(v / groups, 3) for n, v in found.items()}
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--groups", type=int, default=300, help="recordings per null kind")
    ap.add_argument("--power-groups", type=int, default=15, help="recordings per power cell")
    ap.add_argument("--duration", type=float, default=20.0, help="recording length (s)")
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--skip-power", action="store_true")
    args = ap.parse_args()
    out = {"alpha": args.alpha, "duration_s": args.duration, "rate_hz": FS,
           "groups_per_null": args.groups, "groups_per_power_cell": args.power_groups}  # fmt: skip
    if args.groups > 0:
        out["nulls"] = nulls(args.groups, args.alpha, args.duration)
    if not args.skip_power:
        out["power"] = power(args.power_groups, args.alpha, args.duration)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
