"""Benchmark: a bit-level fingerprint of the fits, to show that a refactoring changed no result.

Runs a fixed, quick set of calibrations through the public API on the benchmarks' own
recordings: the first whiskers of ``calibrate_many.py`` (seed 0), the first pluck cases of
``calibrate_plucks.py``'s draw (seed 0, 24 cases), nonlinear fits of
``calibrate_nonlinear.py``'s decays (the linear fit, the nonlinear one and the term selection),
and one added-mass fit of ``calibrate_added_mass.py``. Every value, 1σ, correlation,
covariance, optimum, status, check, warning, diagnostic, per-recording entry, report and the
fitted record's TOML go into a JSON file, each float written with ``float.hex`` (curves
sampled every 25th point, with a hash of the whole array), so that two runs compare to the
last bit.

Run::

    python benchmarks/fit_fingerprint.py --out before.json      # about three minutes
    python benchmarks/fit_fingerprint.py --compare before.json after.json

The comparison prints JSON: the number of values compared, those that differ, the largest
absolute and relative difference and where they are, and the differing strings.
"""

import argparse
import dataclasses
import hashlib
import json
import re
import sys
import time
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

#: The date a record's ``[fit]`` table was written, left out of the comparison.
DATE = re.compile(r'^date = ".*"$', re.M)
#: Every ``CURVE_STEP``-th sample of a curve is kept (the hash covers all of them).
CURVE_STEP = 25


def encode(value, *, curve=False):
    """A JSON tree of ``value`` with every float as ``float.hex`` (tagged ``{"f": ...}``)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {}
        for f in dataclasses.fields(value):
            if f.name == "problem":
                continue  # the problem is the input; the optimum and covariance are its output
            v = getattr(value, f.name)
            if f.name == "curves":
                out[f.name] = [[encode(a, curve=True) for a in c] for c in v]
            elif f.name == "record":
                out[f.name] = v.to_toml()
            else:
                out[f.name] = encode(v)
        out["report"] = value.report()
        out["json"] = encode(value.to_json())
        return out
    if isinstance(value, dict):
        return {str(k): encode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [encode(v) for v in value]
    if isinstance(value, bool | str | None):
        return value
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return {"f": float(value).hex()}
    if isinstance(value, np.ndarray | jax.Array):
        a = np.asarray(value)
        if a.dtype.kind in "fc":
            a = a.astype(np.float64)
            digest = hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()
            flat = a.ravel()[:: CURVE_STEP if curve else 1]
            return {"shape": list(a.shape), "sha256": digest, "a": [x.hex() for x in flat.tolist()]}
        return {"shape": list(a.shape), "ints": a.ravel().tolist()}
    if hasattr(value, "to_toml"):
        return value.to_toml()
    leaves = jax.tree_util.tree_leaves(value)
    if leaves and all(isinstance(x, np.ndarray | jax.Array | float) for x in leaves):
        return {"leaves": [encode(np.asarray(x)) for x in leaves]}
    return repr(value)


def run(args) -> dict:
    import calibrate_added_mass as am
    import calibrate_many as many
    import calibrate_nonlinear as cn
    import calibrate_plucks as plucks

    import whiskerid as wi
    from whiskerid.fit import calibrate, calibrate_nonlinear, calibrate_nonlinear_selected

    out: dict = {}
    t0 = time.perf_counter()

    # calibrate_many: the first whiskers of its seed-0 draw (the --whiskers 21 run's first ones)
    records = many._whiskers(21, 0)[: args.whiskers]
    for k, rec in enumerate(records):
        sim = wi.simulate(rec, excitation="decay", observable="adc", rate_hz=200,
                          duration_s=10.0, noise_db=30, seed=k,
                          tip_deflection_m=2e-3)  # fmt: skip
        obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
        out[f"many/{k}"] = encode(wi.calibrate(many._nominal(rec), obs))
    print(f"many: {time.perf_counter() - t0:.1f} s", file=sys.stderr)

    # calibrate_plucks: the seed-0 draw of 24 cases, the first --plucks of them
    rng = np.random.default_rng(0)
    grid = [
        (
            str(rng.choice(plucks.KINDS)),
            float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))),
            float(np.exp(rng.uniform(np.log(0.005), np.log(0.15)))),
            float(rng.choice([200.0, 475.0, 860.0])),
        )
        for _ in range(24)
    ]
    for k, (kind, ff, z, rate) in enumerate(grid[: args.plucks]):
        nominal, rec, _, _ = plucks.make_case(kind, ff, z, rate, k)
        try:
            obs = wi.observations_from_recording(rec, nominal, observable="adc")
            out[f"plucks/{k}/{kind}"] = encode(calibrate(nominal, obs))
        except Exception as e:  # a refusal is a result too
            out[f"plucks/{k}/{kind}"] = f"error: {type(e).__name__}: {e}"
        jax.clear_caches()
    print(f"plucks: {time.perf_counter() - t0:.1f} s", file=sys.stderr)

    # calibrate_nonlinear: a cubic+quadratic decay, the linear fit, the nonlinear one and the
    # term selection (--coulomb: a Coulomb decay too, another three minutes)
    for kind in ("cubic+quadratic", "coulomb-1.25x")[: 1 + args.coulomb]:
        record, obs, _ = cn.nonlinear_case(kind, 200.0, 0)
        lin = calibrate(record, obs, n_modes=1)
        out[f"nonlinear/{kind}/linear"] = encode(lin)
        out[f"nonlinear/{kind}/nonlinear"] = encode(calibrate_nonlinear(lin, [obs]))
        if kind == "cubic+quadratic":
            out[f"nonlinear/{kind}/selected"] = encode(calibrate_nonlinear_selected(lin, [obs]))
    print(f"nonlinear: {time.perf_counter() - t0:.1f} s", file=sys.stderr)

    # calibrate_added_mass: one plain and one loaded pluck at 200 Hz, mass ratio 0.5
    m = 0.5 * am.BEAM_KG
    obs = [am.observation(0.0, 0.02, 200.0, 11), am.observation(m, 0.018, 200.0, 12)]
    masses = [None, wi.fit.AddedMass(m, 1e-6)]
    out["added_mass"] = encode(calibrate(am.REC, obs, added_mass=masses, n_modes=am.N_MODES))
    print(f"added mass: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return out


def compare(a, b, path="", acc=None):
    """Walk two fingerprints side by side; collect the float differences and other changes."""
    if acc is None:
        acc = {"floats": 0, "differ": 0, "max_abs": (0.0, ""), "max_rel": (0.0, ""), "other": []}
    if isinstance(a, dict) and "f" in a and isinstance(b, dict) and "f" in b and len(a) == 1:
        pairs = [(a["f"], b["f"], path)]
    elif isinstance(a, dict) and "a" in a and isinstance(b, dict) and "a" in b:
        if a["shape"] != b["shape"] or len(a["a"]) != len(b["a"]):
            acc["other"].append(f"{path}: shape {a['shape']} -> {b['shape']}")
            return acc
        both = zip(a["a"], b["a"], strict=True)
        pairs = [(x, y, f"{path}[{i}]") for i, (x, y) in enumerate(both)]
        if a["sha256"] != b["sha256"] and all(x == y for x, y, _ in pairs):
            acc["other"].append(f"{path}: unsampled points differ (hash)")
    elif isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                acc["other"].append(f"{path}/{k}: only in {'A' if k in a else 'B'}")
            else:
                compare(a[k], b[k], f"{path}/{k}", acc)
        return acc
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            acc["other"].append(f"{path}: length {len(a)} -> {len(b)}")
            return acc
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            compare(x, y, f"{path}[{i}]", acc)
        return acc
    else:
        if isinstance(a, str) and isinstance(b, str):  # a fitted record's date is not a result
            a, b = (DATE.sub("", x) for x in (a, b))
        if a != b:
            acc["other"].append(f"{path}: {str(a)[:80]!r} -> {str(b)[:80]!r}")
        return acc
    for x, y, where in pairs:
        acc["floats"] += 1
        if x == y:
            continue
        fx, fy = float.fromhex(x), float.fromhex(y)
        if np.isnan(fx) and np.isnan(fy):
            continue
        acc["differ"] += 1
        d = abs(fx - fy)
        r = d / max(abs(fx), abs(fy)) if d else 0.0
        if d > acc["max_abs"][0] or np.isnan(d):
            acc["max_abs"] = (d, where)
        if r > acc["max_rel"][0] or np.isnan(r):
            acc["max_rel"] = (r, where)
    return acc


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="write the fingerprint here (JSON)")
    ap.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two fingerprints")
    ap.add_argument("--whiskers", type=int, default=3, help="calibrate_many whiskers")
    ap.add_argument("--plucks", type=int, default=4, help="calibrate_plucks cases")
    ap.add_argument("--coulomb", action="store_true", help="a Coulomb nonlinear decay too")
    args = ap.parse_args(argv)
    if args.compare:
        a, b = (json.loads(Path(p).read_text()) for p in args.compare)
        acc = compare(a, b)
        acc["other_count"] = len(acc["other"])
        acc["other"] = acc["other"][:40]
        acc["bit_equal"] = acc["differ"] == 0 and acc["other_count"] == 0
        print(json.dumps(acc, indent=1))
        return
    if not args.out:
        ap.error("--out or --compare is needed")
    t0 = time.perf_counter()
    data = run(args)
    Path(args.out).write_text(json.dumps(data))
    print(json.dumps({"out": args.out, "fits": len(data), "seconds": time.perf_counter() - t0}))


if __name__ == "__main__":
    main()
