"""BorealTC (real IMU, 5 terrains, 100 Hz): both pipelines, split by run.

Example::

    .venv/bin/python examples/classify_borealtc.py --data ../shared/data/borealtc --out out/borealtc
"""

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import whiskerid as wi
from whiskerid._classify import (
    default_spec,
    evaluate_features,
    features_of,
    fit_on_features,
    format_confusion,
    plot_confusion,
)
from whiskerid._mlp import default_config

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "borealtc")
    ap.add_argument("--out", type=Path, default=Path("out/classify-borealtc"))
    ap.add_argument("--window", type=float, default=1.0, help="window (s)")
    ap.add_argument("--splits", type=int, default=3, help="random splits by run")
    args = ap.parse_args()
    if not args.data.is_dir():
        sys.exit(f"no BorealTC data at {args.data} (pass --data)")
    ws = wi.load_borealtc(args.data, window_s=args.window)
    out = {"windows": len(ws), "runs": len(ws.sources), "labels": list(ws.label_names)}
    args.out.mkdir(parents=True, exist_ok=True)
    for kind in ("paper", "fitted"):
        spec = default_spec(ws, kind)
        feats = features_of(ws, spec)
        accs = []
        for s in range(args.splits):
            test = wi.split_by_recording(ws, 0.25, seed=s)[1]
            mask = __import__("numpy").isin(ws.recording, test.recording)
            train = ws.subset(~mask)
            cfg = replace(default_config(kind), seed=s)
            model = fit_on_features(feats[~mask], train, spec, cfg)
            res = evaluate_features(model, feats[mask], ws.subset(mask))
            accs.append(res["accuracy"])
            if s == 0:
                out[kind] = res
                plot_confusion(
                    args.out / f"confusion_{kind}.png",
                    res["confusion"],
                    res["labels"],
                    title=f"BorealTC, {kind}, split by run: {res['accuracy']:.3f}",
                )
                print(
                    f"{kind}:\n" + format_confusion(res["confusion"], res["labels"]),
                    file=sys.stderr,
                )
        out[kind]["accuracy_by_split"] = [round(a, 4) for a in accs]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
