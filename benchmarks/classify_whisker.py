"""Whisker-aware classification: transfer across whiskers, two sensors against one, and the
base-motion spectrum estimated through the whisker's own response.

Trains on the paper whisker (synthetic, split by recording: test recordings come from
another dataset seed) and tests on recordings of whiskers with f_1 x0.7 and x1.3, zeta 0.02
and 0.08, and f_1 x0.8 with zeta 0.05, each calibrated by ``whiskerid calibrate`` from its
own simulated pluck (``--truth``: the true records instead). Pipelines: raw fitted
features and whisker-aware ones (``train --whisker``: recoloured to the training whisker,
noise floor matched), on one Hall sensor (``hall_a``), on two (``hall_a,hall_b``), and on
the lateral one alone (raw).
Prints one JSON object.

    .venv/bin/python benchmarks/classify_whisker.py [--runs 3] [--duration 10] [--truth]
        [--train-seed 0] [--test-seed 1]
"""

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from whiskerid.classify import (
    ALIAS_SLOPE,
    WhiskerResponse,
    base_band_levels,
    evaluate_classifier,
    load_dataset,
    train_classifier,
)
from whiskerid.classify._features import through_filter
from whiskerid.io import write_csv
from whiskerid.model import load_record, paper_record
from whiskerid.terrain import TERRAINS, RunSpec, dataset_paths, run_base_motion, synthesize_runs

SPEEDS = (0.1, 0.2, 0.3)
CALIBRATION = "whiskerid calibrate on a simulated pluck (ADC, 200 Hz, 2 s, 30 dB SNR)"
VARIANTS = {"same": (1.0, 0.04), "f1 x0.7": (0.7, 0.04), "f1 x1.3": (1.3, 0.04),
            "zeta 0.02": (1.0, 0.02), "zeta 0.08": (1.0, 0.08),
            "f1 x0.8 zeta 0.05": (0.8, 0.05)}  # fmt: skip


def variant(name: str):
    base = paper_record()
    ratio, zeta = VARIANTS[name]
    g = base.structure.shear_modulus_pa * ratio**2  # f ∝ √κ ∝ √G for a coil
    s = dataclasses.replace(base.structure, shear_modulus_pa=g)
    slug = name.replace(" ", "-").replace(".", "")
    return base.replace(name=f"whisker-{slug}", structure=s, zeta=zeta)


def calibrated(record, tmp: Path):
    """``whiskerid calibrate`` on the whisker's simulated pluck (ADC codes, 30 dB SNR)."""
    exe = [sys.executable, "-m", "whiskerid.cli"]
    true = record.save(tmp / f"{record.name}.toml")
    pluck = tmp / f"{record.name}-pluck.csv"
    out = tmp / f"{record.name}-cal.toml"
    subprocess.run(
        [
            *exe,
            "simulate",
            "--whisker",
            str(true),
            "--excitation",
            "decay",
            "--observable",
            "adc",
            "--rate",
            "200",
            "--duration",
            "2",
            "--noise-db",
            "30",
            "--out",
            str(pluck),
        ],
        check=True,
        capture_output=True,
    )
    nominal = paper_record().save(tmp / "nominal.toml")
    subprocess.run([*exe, "calibrate", str(pluck), "--whisker", str(nominal), "--out", str(out)],
                   check=True, capture_output=True)  # fmt: skip
    return load_record(out)


def dataset(root: Path, record, runs: int, duration: float, seed: int) -> Path:
    specs = [RunSpec(t, v, r) for t in TERRAINS for v in SPEEDS for r in range(runs)]
    recs = synthesize_runs(specs, record=record, duration_s=duration, seed=seed, channels=2)
    for path, rec in zip(dataset_paths(root, specs), recs, strict=True):
        write_csv(path, rec)
    return root


def band_error(ws, record, seed: int, duration: float) -> dict:
    """Median |error| (dB) of base-motion band levels estimated from windows of ``ws``
    (vertical plane, one sensor) against the simulator's true base acceleration."""
    from whiskerid.classify import FeatureSpec

    spec = FeatureSpec(
        rate_hz=ws.rate_hz,
        window=ws.windows.shape[-1],
        deconvolve=True,
        extend_edges=True,
        alias_slope=ALIAS_SLOPE,
    )
    resp = WhiskerResponse(record, 20.0, 1)
    num = spec.numbers(resp)
    edges = np.asarray(spec.octave_edges())
    errs = []
    n = spec.window
    for r, src in enumerate(ws.sources):
        meta = ws.metas[r]
        run = RunSpec(meta["terrain"], float(meta["speed_mps"]), int(meta["run"]))
        t_grid, acc = run_base_motion(run, duration_s=duration, seed=seed, channels=2)
        from whiskerid.io import read_recording

        t0 = read_recording(src).t[0]
        idx = np.flatnonzero(ws.recording == r)
        for i in idx:
            win = ws.windows[i][None]  # hall_a: the vertical plane
            est = np.asarray(base_band_levels(through_filter(win, num.to_base, True), ws.rate_hz,
                                              edges))[0]  # fmt: skip
            start = t0 + ws.start_s[i]
            fine = (t_grid >= start) & (t_grid < start + n / ws.rate_hz)
            rate = 1 / (t_grid[1] - t_grid[0])
            true = np.asarray(base_band_levels(acc[0][fine], rate, edges))
            errs.append(est - true)
    errs = np.asarray(errs)
    return {"median_abs_db": round(float(np.median(np.abs(errs))), 2),
            "median_abs_db_per_band": [round(float(v), 2) for v in np.median(np.abs(errs), 0)],
            "median_db_per_band": [round(float(v), 2) for v in np.median(errs, 0)],
            "band_edges_hz": [round(float(e), 2) for e in edges]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="training runs per terrain and speed")
    ap.add_argument("--test-runs", type=int, default=2, help="test runs per terrain and speed")
    ap.add_argument("--duration", type=float, default=10.0, help="recording length (s)")
    ap.add_argument("--truth", action="store_true", help="true records, not calibrated ones")
    ap.add_argument("--train-seed", type=int, default=0, help="dataset seed of the training set")
    ap.add_argument("--test-seed", type=int, default=1, help="dataset seed of the test sets")
    args = ap.parse_args()
    out: dict = {"terrains": len(TERRAINS), "speeds_mps": SPEEDS, "train_runs": args.runs,
                 "test_runs": args.test_runs, "duration_s": args.duration,
                 "calibration": "true record" if args.truth else CALIBRATION}  # fmt: skip
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paper = paper_record()
        train_ws = {}
        root = dataset(tmp / "train", paper, args.runs, args.duration, seed=args.train_seed)
        for ch in ("hall_a", "hall_b", "hall_a,hall_b"):
            train_ws[ch] = load_dataset(root, channel=ch)
        tests, cal = {}, {}
        for name in VARIANTS:
            rec = paper if name == "same" else variant(name)
            cal[name] = rec if (name == "same" or args.truth) else calibrated(rec, tmp)
            root = dataset(
                tmp / f"test-{len(tests)}", rec, args.test_runs, args.duration, seed=args.test_seed
            )
            tests[name] = {ch: load_dataset(root, channel=ch) for ch in train_ws}
        out["calibrated_f1_hz"] = {n: round(float(r.whisker().natural_frequencies_hz[0]), 3)
                                   for n, r in cal.items()}  # fmt: skip
        out["calibrated_zeta"] = {n: float(np.ravel(r.zeta)[0]) for n, r in cal.items()}
        true = {n: paper if n == "same" else variant(n) for n in VARIANTS}
        out["true_f1_hz"] = {n: round(float(r.whisker().natural_frequencies_hz[0]), 3)
                             for n, r in true.items()}  # fmt: skip
        acc = {}
        sensors = {"hall_a": "one sensor", "hall_b": "lateral sensor alone",
                   "hall_a,hall_b": "two sensors"}  # fmt: skip
        for ch, ws in train_ws.items():
            for aware in (False, True) if ch != "hall_b" else (False,):
                key = f"{sensors[ch]}, " + ("whisker-aware" if aware else "raw")
                t0 = time.perf_counter()
                model = train_classifier(ws, whisker=WhiskerResponse(paper, 20.0) if aware
                                         else None)  # fmt: skip
                row = {"train_s": round(time.perf_counter() - t0, 1)}
                for name, sets in tests.items():
                    if aware:
                        model.use_whisker(WhiskerResponse(cal[name], 20.0))
                    res = evaluate_classifier(model, sets[ch])
                    row[name] = [
                        round(100 * res["accuracy_per_window"], 1),
                        round(100 * res["accuracy"], 1),
                    ]
                acc[key] = row
                print(key, row, file=sys.stderr)
        out["accuracy_percent_per_window_and_three_windows"] = acc
        out["base_motion_band_error"] = {
            name: band_error(tests[name]["hall_a"], cal[name], args.test_seed, args.duration)
            for name in ("same", "f1 x0.7", "zeta 0.08")
        }
    out["total_s"] = round(time.perf_counter() - t_start, 1)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
