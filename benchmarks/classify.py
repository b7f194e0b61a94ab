"""Classifier benchmark: training time to convergence on 7 × 300 windows (fitted features;
early stopping on held-out recordings, then the refit on all windows) against
scikit-learn's MLPClassifier (same hidden sizes) on the same features, batched inference
throughput, and warm single-window latency (features + MLP). Prints one JSON object.

    .venv/bin/python benchmarks/classify.py
"""

import json
import os
import time

import numpy as np

import whiskerid as wi
from whiskerid.classify import (
    TrainConfig,
    default_config,
    default_spec,
    features_of,
    fit_on_features,
)
from whiskerid.terrain import RunSpec


def main() -> None:
    t0 = time.perf_counter()
    specs = [RunSpec(t, v, r) for t in wi.TERRAINS for v in (0.1, 0.2, 0.3) for r in range(2)]
    recs = wi.synthesize_runs(specs, duration_s=51.0)  # 6 runs × 50 windows = 300 per terrain
    import tempfile

    from whiskerid.io import write_csv

    with tempfile.TemporaryDirectory() as tmp:
        for s, r in zip(specs, recs, strict=True):
            write_csv(f"{tmp}/{s.terrain}/{s.terrain}_{s.speed_mps}_{s.run}.csv", r)
        ws = wi.load_dataset(tmp)
    synth_s = time.perf_counter() - t0
    spec = default_spec(ws, "fitted")
    t0 = time.perf_counter()
    feats = features_of(ws, spec)
    feat_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    model = fit_on_features(feats, ws, spec, default_config("fitted"))
    train_s = time.perf_counter() - t0

    from sklearn.neural_network import MLPClassifier

    z = (feats - model.mean) / model.std
    t0 = time.perf_counter()
    sk = MLPClassifier(hidden_layer_sizes=TrainConfig().hidden, early_stopping=True,
                       random_state=0, max_iter=300).fit(z, ws.labels)  # fmt: skip
    sk_s = time.perf_counter() - t0

    batch = ws.windows[:2048]
    speeds = ws.speeds[:2048]
    model.predict_windows(batch, speeds)
    t0 = time.perf_counter()
    for _ in range(3):
        model.predict_windows(batch, speeds)
    batch_rate = 3 * len(batch) / (time.perf_counter() - t0)

    one = ws.windows[0]
    model.predict_window(one, speed=0.2)
    times = []
    for i in range(200):
        t0 = time.perf_counter()
        model.predict_window(ws.windows[i % len(ws)], speed=0.2)
        times.append(time.perf_counter() - t0)
    print(json.dumps({
        "windows": len(ws), "features": spec.n_features, "synthesis_s": round(synth_s, 2),
        "feature_extraction_s_incl_compile": round(feat_s, 2),
        "train_s_incl_compile": round(train_s, 2), "train_epochs": model.info["epochs"],
        "refit_epochs": model.info["refit_epochs"],
        "ensemble_members": model.info["members"],
        "load_average_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
        "sklearn_mlp_train_s": round(sk_s, 2), "sklearn_epochs": int(sk.n_iter_),
        "batched_inference_windows_per_s": round(batch_rate),
        "single_window_latency_ms": {"median": round(1e3 * float(np.median(times)), 3),
                                     "p95": round(1e3 * float(np.percentile(times, 95)), 3)},
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
