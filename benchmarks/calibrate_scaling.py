"""How ``calibrate`` scales with the recording's length: time and peak memory per size.

Fits real and simulated free decays of about 10 k, 40 k, 160 k and 640 k samples, each in its
own child process (so that its peak RSS, ``resource.getrusage``, is its own), and prints one
JSON object with, per case: samples fitted, release detection time, the calibration's time
cold (compiling, into an empty compilation cache of the child's own) and warm (the same
shapes again), the HAC covariance's time, the child's peak RSS, and side by side the peer:
the Newey–West sum written lag by lag (the ``O(n L p²)`` form this project used before, with
the same lag ``L``) on the same scores, where it finishes within ``--peer-budget`` seconds
(estimated from the smaller sizes).

Recordings:

* ``real``: the 78 k-sample cantilever recording (``shared/data/cantilever/30cm``, 4 kHz
  accelerometer, ``examples/calibrate_cantilever.py``'s reading: the release found, the rest
  of the record fitted, two modes), cropped to 10 k and 40 k samples after the release and in
  full (about 77 k); tiled end to end (the decay repeated, each copy's time shifted) to 160 k
  and 640 k samples, fitted as one recording (for timing only: the copies' restarts are no
  free decay, so the fit is not ``ok``). The residuals stay correlated (the beam is
  nonlinear), so the HAC lag grows with the length, the case that made the old sum
  quadratic;
* ``simulated``: a hold then a free decay of one mode (16.3 Hz, 4 kHz, written with NumPy, 40
  dB SNR), its damping chosen so that the decay lasts the record, one mode fitted.

Usage::

    python benchmarks/calibrate_scaling.py [--sizes 10000 40000 160000 640000]
        [--sources real simulated] [--peer-budget 120] [--no-warm]
        [--data ../shared/data/cantilever/30cm]

Timings depend on the machine and its load: compare figures of one run only.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CANTILEVER = ROOT.parent / "shared" / "data" / "cantilever" / "30cm"
RATE = 4000.0


def real_observation(n: int, data: Path):
    """The cantilever decay (release found as the example does), cropped or tiled to ``n``."""
    import whiskerid as wi
    from whiskerid.fit import G0, release_time

    path = sorted(data.glob("*4000Hz.npy"))[-1]
    a = np.load(path)
    obs = wi.Observation(a[0], a[1] * G0, observable="acceleration", name=path.name)
    obs = obs.window(release_time(obs.t, obs.y), None)
    t, y = obs.t - obs.t[0], obs.y
    if n <= t.size:
        return wi.Observation(t[:n], y[:n], observable="acceleration", name=f"real-{n}")
    reps = -(-n // t.size)
    dt = float(np.median(np.diff(t)))
    span = t[-1] + dt
    tt = np.concatenate([t + k * span for k in range(reps)])[:n]
    yy = np.tile(y, reps)[:n]
    return wi.Observation(tt, yy, observable="acceleration", name=f"real-tiled-{n}")


def simulated_observation(n: int, seed: int = 0):
    """A hold, then one mode's free decay lasting the rest of the ``n`` samples."""
    import whiskerid as wi

    rng = np.random.default_rng(seed)
    f1 = 16.3
    t = np.arange(n) / RATE
    release = 0.25 + rng.uniform(0, 1 / RATE)
    w = 2 * np.pi * f1
    zeta = 3.0 / (w * (t[-1] - release))  # the envelope falls by e³ over the record
    s, wd = zeta * w, w * np.sqrt(1 - zeta**2)
    tau = np.maximum(t - release, 0.0)
    x = np.where(
        t < release, 1.0, np.exp(-s * tau) * (np.cos(wd * tau) + s / wd * np.sin(wd * tau))
    )
    y = 1.65 + 0.5 * x + 0.005 * rng.standard_normal(n)
    return wi.Observation(t, y, observable="voltage", gain=None, name=f"sim-{n}"), zeta


def _hac_by_lags(scores, lag):
    meat = scores.T @ scores
    for ell in range(1, lag + 1):
        g = scores[ell:].T @ scores[:-ell]
        meat += (1.0 - ell / (lag + 1.0)) * (g + g.T)
    return meat


def child(source: str, n: int, warm: bool, peer: bool, data: Path) -> dict:
    """One case, measured in this process (run with ``--child``)."""
    import whiskerid as wi
    from whiskerid.fit import find_decays
    from whiskerid.fit._checks._checks import bartlett_meat, hac_lag
    from whiskerid.fit._linear._problem import residuals_and_jacobian

    sys.path.insert(0, str(ROOT / "examples"))
    from calibrate_cantilever import beam_record

    out = {"source": source, "samples_requested": n}
    if source == "real":
        obs, n_modes, record = real_observation(n, data), 2, beam_record(30)
    else:
        (obs, zeta), n_modes = simulated_observation(n), 1
        record = beam_record(30).replace(zeta=zeta)
        # the release search on the whole record (hold included), then the decay fitted
    t0 = time.perf_counter()
    decays = find_decays(obs.t, obs.y)
    out["release_s"] = time.perf_counter() - t0
    if source == "simulated":
        obs = obs.window(decays[0].start_s, None)
    out["samples"] = int(obs.t.size)
    t0 = time.perf_counter()
    cal = wi.calibrate(record, obs, n_modes=n_modes)
    out["calibrate_cold_s"] = time.perf_counter() - t0
    if warm:
        t0 = time.perf_counter()
        cal = wi.calibrate(record, obs, n_modes=n_modes)
        out["calibrate_warm_s"] = time.perf_counter() - t0
    out["status"] = cal.status
    out["f1_hz"] = cal.params["f1_hz"]
    out["zeta"] = cal.params["zeta"]
    out["uncertainty"] = cal.diagnostics["uncertainty"]
    flat = cal.problem.flatten(cal.optimum)
    r, jac = (np.asarray(a) for a in residuals_and_jacobian(cal.problem, flat))
    scores = jac * r[:, None]
    lag = hac_lag(r)
    out["hac_lag"] = lag
    out["n_params"] = int(jac.shape[1])
    t0 = time.perf_counter()
    new = bartlett_meat(scores, lag)
    out["hac_s"] = time.perf_counter() - t0
    if peer:
        t0 = time.perf_counter()
        old = _hac_by_lags(scores, lag)
        out["peer_hac_by_lags_s"] = time.perf_counter() - t0
        out["peer_max_rel_diff"] = float(np.max(np.abs(new - old)) / np.max(np.abs(old)))
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 40_000, 160_000, 640_000])
    ap.add_argument("--sources", nargs="+", default=["real", "simulated"])
    ap.add_argument("--data", type=Path, default=CANTILEVER, help="the 30 cm cantilever folder")
    ap.add_argument(
        "--peer-budget",
        type=float,
        default=120.0,
        help="run the lag-by-lag HAC only where its estimated time (s) is below this",
    )
    ap.add_argument("--no-warm", action="store_true", help="skip the second (warm) calibration")
    ap.add_argument("--child", nargs=2, metavar=("SOURCE", "N"), help=argparse.SUPPRESS)
    ap.add_argument("--peer", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        res = child(args.child[0], int(args.child[1]), not args.no_warm, args.peer, args.data)
        print(json.dumps(res))
        return 0
    if "real" in args.sources and not args.data.exists():
        print(f"no cantilever data at {args.data} (give --data)", file=sys.stderr)
        return 2
    sizes = sorted(args.sizes)
    if "real" in args.sources:  # the full recording as well
        sizes_real = sorted({*sizes, 77_000})
    results = []
    for source in args.sources:
        per_unit = None  # seconds of the lag-by-lag sum per (n · L)
        for n in sizes_real if source == "real" else sizes:
            # the lag-by-lag sum costs about n · L (L ≤ n/4): run it where it fits the budget
            peer = per_unit is None or per_unit * n * n / 4 < args.peer_budget
            cmd = [sys.executable, __file__, "--child", source, str(n), "--data", str(args.data)]
            cmd += ["--peer"] * peer + ["--no-warm"] * args.no_warm
            print(f"{source} {n}: ...", file=sys.stderr, flush=True)
            # an empty compilation cache of its own: "cold" compiles, whatever the user's
            # cache folder already holds from an earlier run
            with tempfile.TemporaryDirectory(prefix="whiskerid-scaling-") as cache:
                env = {**os.environ, "WHISKERID_COMPILE_CACHE": cache}
                t0 = time.perf_counter()
                proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
                wall = time.perf_counter() - t0
            if proc.returncode != 0:
                results.append({"source": source, "samples_requested": n,
                                "error": proc.stderr.strip().splitlines()[-1:]})  # fmt: skip
                continue
            res = json.loads(proc.stdout.strip().splitlines()[-1])
            res["child_wall_s"] = wall
            if "peer_hac_by_lags_s" in res and res["hac_lag"] > 0:
                per_unit = res["peer_hac_by_lags_s"] / (res["samples"] * res["hac_lag"])
            results.append(res)
            print(json.dumps(res), file=sys.stderr, flush=True)
    summary = {"cases": results, "scaling": _exponents(results)}
    print(json.dumps(summary, indent=1))
    return 0


def _exponents(results):
    """Log-log slopes of each time against the samples, per source (1 = linear)."""
    out = {}
    for source in {r["source"] for r in results}:
        rows = [r for r in results if r["source"] == source and "samples" in r]
        if len(rows) < 2:
            continue
        n = np.log([r["samples"] for r in rows])
        for key in ("release_s", "calibrate_warm_s", "hac_s", "peer_hac_by_lags_s"):
            pts = [(a, np.log(r[key])) for a, r in zip(n, rows, strict=True) if r.get(key)]
            if len(pts) >= 2:
                x, y = np.array(pts).T
                out[f"{source}:{key}"] = float(np.polyfit(x, y, 1)[0])
        rss = [(a, np.log(r["peak_rss_mb"])) for a, r in zip(n, rows, strict=True)]
        x, y = np.array(rss).T
        out[f"{source}:peak_rss_mb"] = float(np.polyfit(x, y, 1)[0])
    return out


if __name__ == "__main__":
    sys.exit(main())
