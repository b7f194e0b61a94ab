"""Real recordings as they come: decays found against decays marked, f_1 and ζ against a
model-free estimate, time and memory.

Every real free-decay recording available is read from where it lies (never copied into the
repository):

* ``--shared DIR`` (default ``../shared/data/cantilever`` beside the repository): the
  aluminium cantilever, 30 cm and 50 cm, five plucks each (ADXL357, about 4 kHz).
* ``--corpus DIR``: more recordings of the same public repository, **EnesDemirkaya/
  Vibration-Tester-ADXL357-FFT** (https://github.com/EnesDemirkaya/Vibration-Tester-ADXL357-FFT,
  MIT licence, Copyright 2024 Enes Demirkaya): the same beam at 30, 40, 50 and 60 cm, and
  an LSM accelerometer on a box (empty, or with sand). To build it, clone the repository and
  write every version of every ``accelerometer_data.npy`` that its history holds under its
  run folder's name::

      git clone https://github.com/EnesDemirkaya/Vibration-Tester-ADXL357-FFT enes
      cd enes && git log --all --name-only --format= -- '*accelerometer_data.npy' | sort -u |
        while read -r f; do
          run=$(basename "$(dirname "$f")"); top=$(basename "$(dirname "$(dirname "$f")")")
          git show "HEAD:$f" > "../corpus/${top}__${run}.npy" 2>/dev/null
        done

  (files deleted from the tip: ``git show <commit>:<path>`` with the commit that last held
  them, from ``git log --all -- <path>``.) Each file is a float64 array of shape (2, N):
  wall-clock time (s) and acceleration (g). Files forced by the vibration generator
  (``test_with_vibration_generator_*``) are not free decays and are left out, as are two
  the authors named ``delete``; a corpus file identical to a shared one is reported once.

The decays a person marks are in ``benchmarks/real_recordings_marked.json`` (counted by eye
on plots of each whole recording). For each recording the benchmark prints (one JSON
object): decays found against marked, and for each decay a model-free estimate: f_1 from
zero crossings of the signal low-passed at 2 f (zero-phase), ζ from the logarithmic
decrement of its cycle amplitudes (while they stand above a tenth of the first). With
``--fit``, the cantilever files (length known from the name) are also calibrated as
``examples/calibrate_cantilever.py`` does (linear model, all decays jointly): status and
reasons, f_1, ζ, their 1σ, and the time of the first call (cold: compiling) and of a
second (warm), with the process's peak memory. The authors' f_1 (README) is 16.49 Hz at
30 cm and 6.02 Hz at 50 cm; at 40 and 60 cm none is published, so the model-free one stands.

With ``--cost 1,10,...``: 80 000 samples at 4 kHz with that many taps (:func:`taps_recording`)
calibrated jointly, each in a fresh process with an empty compilation cache: decays found,
time cold and warm, peak memory (the cost's growth with the number of decays).

    .venv/bin/python benchmarks/real_recordings.py --quick
    .venv/bin/python benchmarks/real_recordings.py --corpus /path/to/corpus [--fit] [--cost 1,10]
"""

import argparse
import hashlib
import itertools
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import signal

from whiskerid.fit import find_decays

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "cantilever"
MARKED = Path(__file__).resolve().parent / "real_recordings_marked.json"
#: The authors' measured f_1 (their README).
AUTHORS_F1 = {30: 16.49, 50: 6.02}
SKIP = {"vibration_generator": "forced by a vibration generator: not a free decay",
        "_delete": "named 'delete' by the authors: no pluck to mark"}  # fmt: skip


def model_free(t, y, f):
    """f (Hz) from zero crossings and ζ from the log decrement of one decay (band-limited)."""
    dt = float(np.median(np.diff(t)))
    n = t.size
    tu = t[0] + dt * np.arange(n)
    u = np.interp(tu, t, y)
    u = u - np.polyval(np.polyfit(tu - tu[0], u, 1), tu - tu[0])
    wn = min(2.0 * f * 2 * dt, 0.9)
    sos = signal.butter(4, wn, output="sos")
    u = signal.sosfiltfilt(sos, u)
    up = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0))
    if up.size < 4:
        return None, None
    # crossing times by linear interpolation
    tc = tu[up] - u[up] * dt / (u[up + 1] - u[up])
    amps = np.array([0.5 * (u[a:b].max() - u[a:b].min()) for a, b in itertools.pairwise(up)])
    keep = np.flatnonzero(amps >= 0.1 * amps[: max(1, amps.size // 20)].max())
    last = keep[-1] if np.all(np.diff(keep) == 1) else keep[np.argmax(np.diff(keep) > 1)]
    m = max(3, int(last) + 1)
    f_zc = (m) / (tc[m] - tc[0]) if m < tc.size else (tc.size - 1) / (tc[-1] - tc[0])
    mid = 0.5 * (tc[:-1] + tc[1:])[:m]
    sigma = -np.polyfit(mid, np.log(amps[:m]), 1)[0]
    return float(f_zc), float(sigma / (2 * np.pi * f_zc))


def length_cm(path: Path):
    m = re.search(r"(\d\d)cm_adxl", path.name) or re.fullmatch(r"(\d\d)cm", path.parent.name)
    return int(m.group(1)) if m else None


def fit(path, length, decays):
    """Calibrate as examples/calibrate_cantilever.py does: (status, reasons, f1, ζ, times)."""
    sys.path.insert(0, str(ROOT / "examples"))
    from calibrate_cantilever import beam_record

    import whiskerid as wi
    from whiskerid.fit import G0

    a = np.load(path)
    obs = wi.Observation(a[0], a[1] * G0, observable="acceleration", name=path.name)
    obs = [obs.window(d.start_s, d.end_s) for d in decays]
    record = beam_record(length)
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        cal = wi.calibrate(record, obs if len(obs) > 1 else obs[0])
        times.append(time.perf_counter() - t0)
    p = cal.params
    return {
        "status": cal.status,
        "reasons": sorted(cal.checks) + list(cal.warnings),
        "f1_hz": p["f1_hz"]["value"], "f1_std": p["f1_hz"]["std"],
        "zeta": p["zeta"]["value"], "zeta_std": p["zeta"]["std"],
        "cold_s": round(times[0], 2), "warm_s": round(times[1], 2),
    }  # fmt: skip


def taps_recording(n_taps: int, n: int = 80_000, seed: int = 0):
    """``n`` samples at 4 kHz (jittered) of a 16.3 Hz beam tapped ``n_taps`` times, evenly
    spaced, at random phases (acceleration, m/s²; second mode at 6.27 f_1, 2 % noise).
    Each decay falls by e³ before the next tap."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(np.full(n, 2.5e-4) * (1.0 + 0.05 * rng.standard_normal(n)))
    span = t[-1] / n_taps
    y = 0.02 * 10.0 * rng.standard_normal(n)
    # damped so that each decay falls by e³ before the next tap (a person marks each)
    zeta = float(np.clip(3.0 / (2 * np.pi * 16.3 * span), 0.005, 0.1))
    for k in range(n_taps):
        tau = t - (0.1 + k * span)
        on = tau >= 0
        for f, z, a in ((16.3, zeta, 10.0), (6.27 * 16.3, zeta, 4.0)):
            w = 2 * np.pi * f
            y[on] += a * np.exp(-z * w * tau[on]) * np.sin(w * tau[on] + rng.uniform(0, 6.3))
    return t, y


def cost_child(n_taps: int) -> dict:
    """Calibrate :func:`taps_recording` (all decays found, jointly) cold and warm, here."""
    sys.path.insert(0, str(ROOT / "examples"))
    from calibrate_cantilever import beam_record

    import whiskerid as wi

    t, y = taps_recording(n_taps)
    t0 = time.perf_counter()
    decays = find_decays(t, y)
    out = {"taps": n_taps, "samples": int(t.size), "found": len(decays),
           "detect_s": round(time.perf_counter() - t0, 2)}  # fmt: skip
    obs = wi.Observation(t, y, observable="acceleration", name=f"taps-{n_taps}")
    obs = [obs.window(d.start_s, d.end_s) for d in decays]
    for key in ("cold_s", "warm_s"):
        t0 = time.perf_counter()
        cal = wi.calibrate(beam_record(30), obs if len(obs) > 1 else obs[0])
        out[key] = round(time.perf_counter() - t0, 2)
    out["status"] = cal.status
    out["f1_hz"] = cal.params["f1_hz"]["value"]
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    return out


def cost(taps: list[int], timeout_s: float) -> list[dict]:
    """:func:`cost_child` for each number of taps, each in a fresh process with an empty
    compilation cache of its own (cold means compiling)."""
    rows = []
    for n_taps in taps:
        with tempfile.TemporaryDirectory(prefix="whiskerid-real-") as cache:
            env = {**os.environ, "WHISKERID_COMPILE_CACHE": cache}
            cmd = [sys.executable, __file__, "--cost-child", str(n_taps)]
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, env=env,
                                      timeout=timeout_s)  # fmt: skip
                last = proc.stdout.strip().splitlines()[-1:] or ["{}"]
                row = json.loads(last[0]) if proc.returncode == 0 else {
                    "taps": n_taps, "error": proc.stderr.strip().splitlines()[-1:]}  # fmt: skip
            except subprocess.TimeoutExpired:
                row = {"taps": n_taps, "error": f"over {timeout_s:.0f} s"}
        rows.append(row)
        print(json.dumps(row), file=sys.stderr)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=SHARED, help="the shared cantilever folder")
    ap.add_argument("--corpus", type=Path, help="the corpus folder (see the docstring)")
    ap.add_argument("--quick", action="store_true", help="shared data only (CI)")
    ap.add_argument("--fit", action="store_true", help="also calibrate the cantilever files")
    ap.add_argument(
        "--cost",
        type=str,
        metavar="N,N,...",
        help="also calibrate 80 k-sample recordings with N taps (time, memory)",
    )
    ap.add_argument("--cost-timeout", type=float, default=300.0, help="seconds per case")
    ap.add_argument("--cost-child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.cost_child is not None:
        print(json.dumps(cost_child(args.cost_child)))
        return 0
    marked = json.loads(MARKED.read_text())["marked"]
    paths = sorted(args.shared.glob("*/*.npy")) if args.shared.is_dir() else []
    if args.corpus and not args.quick:
        if not args.corpus.is_dir():
            print(f"--corpus {args.corpus}: no such folder", file=sys.stderr)
            return 2
        paths += sorted(args.corpus.glob("*.npy"))
    if not paths:
        print(f"--shared {args.shared}: no recordings (give --shared or --corpus)", file=sys.stderr)
        return 2
    seen, rows, left_out = {}, [], []
    for path in paths:
        why = next((v for k, v in SKIP.items() if k in path.name), None)
        if why:
            left_out.append({"file": path.name, "why": why})
            continue
        raw = path.read_bytes()
        digest = hashlib.sha256(raw).hexdigest()
        if digest in seen:
            left_out.append({"file": path.name, "why": f"same bytes as {seen[digest]}"})
            continue
        seen[digest] = path.name
        a = np.load(path)
        t, y = a[0], a[1]
        t0 = time.perf_counter()
        decays = find_decays(t, y)
        detect_s = time.perf_counter() - t0
        length = length_cm(path)
        row = {
            "file": path.name,
            "length_cm": length,
            "samples": int(t.size),
            "marked": marked.get(path.name),
            "found": len(decays),
            "detect_s": round(detect_s, 2),
            "decays": [],
        }
        for d in decays:
            sel = (t >= d.start_s) & (t <= d.end_s)
            f_zc, zeta_ld = (
                model_free(t[sel], y[sel], d.frequency_hz) if sel.sum() > 64 else (None, None)
            )
            row["decays"].append({
                "start_s": round(d.start_s - t[0], 3),
                "end_s": round(d.end_s - t[0], 3),
                "f_detector_hz": round(d.frequency_hz, 4),
                "f_zero_crossings_hz": f_zc,
                "zeta_log_decrement": zeta_ld,
            })  # fmt: skip
        if length in AUTHORS_F1:
            row["f1_authors_hz"] = AUTHORS_F1[length]
        if args.fit and length and decays and "LSM" not in path.name:
            row["fit"] = fit(path, length, decays)
        rows.append(row)
        print(json.dumps({k: row[k] for k in ("file", "marked", "found")}), file=sys.stderr)
    counted = [r for r in rows if r["marked"] is not None]
    out = {
        "recordings": rows,
        "left_out": left_out,
        "count_exact": sum(r["found"] == r["marked"] for r in counted),
        "counted": len(counted),
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }
    if args.cost:
        out["cost"] = cost([int(k) for k in args.cost.split(",")], args.cost_timeout)
    print(json.dumps(out, indent=1))
    return 0 if out["count_exact"] == out["counted"] else 1


if __name__ == "__main__":
    sys.exit(main())
