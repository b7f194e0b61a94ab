"""How ``calibrate``'s cost grows with the number of decays in one recording (issue 44, item 2).

A recording of ``--samples`` samples at 4 kHz tapped N times (``real_recordings.py``'s
:func:`taps_recording`: a 16.3 Hz beam, second mode at 6.27 f_1, each decay falling by e³
before the next tap) is cut into the decays :func:`whiskerid.find_decays` finds, and those are
calibrated jointly (linear model), each N in a fresh child process with an empty compilation
cache of its own. Per N it prints: decays found, time cold (compiling) and warm (the same
shapes again), the child's peak RSS, and the XLA compilations the cold call caused with
their summed tracing and compile seconds (JAX's monitoring events). The warm call must
compile nothing; the cold call's compilations are one per program, so their count stays
flat while the program's size (and its trace and compile time) grows with the decays while
the fit unrolls its Python list of recordings (docs/benchmarks.md, "Cost per decay: where
the fit unrolls its recordings").

Usage::

    python benchmarks/decay_count_cost.py [--taps 1,4,16] [--samples 20000] [--timeout 300]
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

ROOT = Path(__file__).resolve().parents[1]

_EVENTS = {
    "/jax/core/compile/backend_compile_duration": "compile",
    "/jax/core/compile/jaxpr_trace_duration": "trace",
}


def child(n_taps: int, n_samples: int) -> dict:
    """Calibrate one tapped recording cold and warm here; its figures as a dict."""
    # imported here, in the child only: the parent stays without JAX (light, and each
    # child's peak RSS and compilations are its own)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    sys.path.insert(0, str(ROOT / "examples"))
    import jax
    from calibrate_cantilever import beam_record
    from real_recordings import find_decays, taps_recording

    import whiskerid as wi

    seen: list[tuple[str, float]] = []

    def listen(event, duration, **kwargs):
        if event in _EVENTS:
            seen.append((_EVENTS[event], duration))

    jax.monitoring.register_event_duration_secs_listener(listen)
    t, y = taps_recording(n_taps, n=n_samples)
    decays = find_decays(t, y)
    obs = wi.Observation(t, y, observable="acceleration", name=f"taps-{n_taps}")
    obs = [obs.window(d.start_s, d.end_s) for d in decays]
    out = {"taps": n_taps, "samples": int(t.size), "found": len(decays)}
    for key in ("cold", "warm"):
        before = len(seen)
        t0 = time.perf_counter()
        cal = wi.calibrate(beam_record(30), obs if len(obs) > 1 else obs[0])
        out[f"{key}_s"] = round(time.perf_counter() - t0, 2)
        mine = seen[before:]
        out[f"{key}_compiles"] = sum(1 for kind, _ in mine if kind == "compile")
        for kind in ("trace", "compile"):
            out[f"{key}_{kind}_s"] = round(sum(d for k, d in mine if k == kind), 2)
    out["status"] = cal.status
    out["f1_hz"] = cal.params["f1_hz"]["value"]
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taps", default="1,4,16", help="numbers of taps, comma-separated")
    ap.add_argument("--samples", type=int, default=20_000, help="samples per recording")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per case")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(args.child, args.samples)))
        return 0
    try:
        taps = [int(x) for x in args.taps.split(",")]
    except ValueError:
        print(f"--taps: not a comma-separated list of integers: {args.taps!r}", file=sys.stderr)
        return 2
    rows = []
    for n_taps in taps:
        with tempfile.TemporaryDirectory(prefix="whiskerid-decays-") as cache:
            env = {**os.environ, "WHISKERID_COMPILE_CACHE": cache}
            cmd = [sys.executable, __file__, "--child", str(n_taps), "--samples", str(args.samples)]
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, env=env,
                                      timeout=args.timeout)  # fmt: skip
                last = proc.stdout.strip().splitlines()[-1:] or ["{}"]
                row = json.loads(last[0]) if proc.returncode == 0 else {
                    "taps": n_taps, "error": proc.stderr.strip().splitlines()[-1:]}  # fmt: skip
            except subprocess.TimeoutExpired:
                row = {"taps": n_taps, "error": f"over {args.timeout:.0f} s"}
        rows.append(row)
        print(json.dumps(row), file=sys.stderr)
    print(json.dumps({"samples": args.samples, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
