"""Synthetic 7 terrains × 5 speeds: the paper's pipeline and ours, split by recording.

Prints one JSON object (overall, per speed, per class; leave-one-speed-out; the paper's
random 75/25 window protocol) and saves confusion-matrix PNGs. Example::

    .venv/bin/python examples/classify_synthetic.py --out out/classify-synth --repeats 20

``--window 2`` cuts 2 s windows instead of the paper's 1 s (the robot covers twice the
terrain per window): a different task, to be reported as such.
"""

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import whiskerid as wi
from whiskerid._classify import (
    _proba_from_features,
    default_spec,
    evaluate_features,
    features_of,
    fit_on_features,
    format_confusion,
    plot_confusion,
)
from whiskerid._mlp import default_config


def _fit_eval(train, test, kind, seed):
    spec = default_spec(train, kind)
    cfg = replace(default_config(kind), seed=seed)
    model = fit_on_features(features_of(train, spec), train, spec, cfg)
    return evaluate_features(model, features_of(test, spec), test)


def _consecutive(model, feats, test, k):
    """Accuracy of the mean probability over ``k`` consecutive windows of one recording
    (non-overlapping groups; what a stream reports after ``k`` s). Per-window is the
    headline figure; this one is reported next to it."""
    p = _proba_from_features(model, feats)
    hits = []
    for r in np.unique(test.recording):
        idx = np.flatnonzero(test.recording == r)
        for lo in range(0, len(idx) - k + 1, k):
            g = idx[lo : lo + k]
            hits.append(np.argmax(p[g].mean(axis=0)) == test.labels[g[0]])
    return round(float(np.mean(hits)), 4)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/classify-synth"))
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--window", type=float, default=1.0, help="window (s); the paper's 1 s")
    ap.add_argument("--repeats", type=int, default=20, help="paper protocol repeats")
    ap.add_argument("--holdout-speeds", type=float, nargs="*", default=[0.1, 0.2, 0.3])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        wi.synthesize_dataset(tmp, runs=args.runs, duration_s=args.duration, seed=args.seed)
        ws = wi.load_dataset(tmp, window_s=args.window)
    print(f"synthesised and loaded {len(ws)} windows in {time.perf_counter() - t0:.1f} s",
          file=sys.stderr)  # fmt: skip
    train, test = wi.split_by_recording(ws, 0.25, seed=args.seed)
    result = {"windows": len(ws), "window_s": args.window, "recordings": len(ws.sources),
              "split_by_recording": {}}  # fmt: skip
    for kind in ("paper", "fitted"):
        spec = default_spec(train, kind)
        model = fit_on_features(
            features_of(train, spec), train, spec, replace(default_config(kind), seed=args.seed)
        )
        feats = features_of(test, spec)
        res = evaluate_features(model, feats, test)
        res["per_speed"] = {
            f"{v:.2f}": round(evaluate_features(model, feats[test.speeds == v],
                                                test.subset(test.speeds == v))["accuracy"], 4)
            for v in np.unique(test.speeds)
        }  # fmt: skip
        res["consecutive_5_windows"] = _consecutive(model, feats, test, 5)
        result["split_by_recording"][kind] = res
        png = plot_confusion(
            args.out / f"confusion_{kind}.png",
            res["confusion"],
            res["labels"],
            title=f"{kind} features, split by recording: {res['accuracy']:.3f}",
        )
        print(f"\n{kind}: accuracy {res['accuracy']:.3f} (split by recording)", file=sys.stderr)
        print(format_confusion(res["confusion"], res["labels"]), file=sys.stderr)
        res["png"] = str(png)
    # Leave one speed out: train without speed v, test on v.
    result["leave_one_speed_out"] = {}
    for v in args.holdout_speeds:
        held = np.isclose(ws.speeds, v)
        row = {}
        for kind in ("paper", "fitted"):
            row[kind] = round(_fit_eval(ws.subset(~held), ws.subset(held), kind, 0)["accuracy"], 4)
        result["leave_one_speed_out"][f"{v:.2f}"] = row
        print(f"left out {v:.2f} m/s: {row}", file=sys.stderr)
    if args.repeats:
        result["paper_protocol"] = {}
        for kind in ("paper", "fitted"):
            pp = wi.paper_protocol(ws, features=kind, repeats=args.repeats, seed=args.seed)
            result["paper_protocol"][kind] = {k: pp[k] for k in
                                              ("accuracy_mean", "accuracy_std", "per_class",
                                               "repeats")}  # fmt: skip
    result["elapsed_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
