"""The terrain classifier as a scikit-learn estimator: a Pipeline tuned by GridSearchCV with
GroupKFold, so that the windows of one recording are never split between training and test.

A small synthetic dataset (3 terrains × 2 speeds × 3 runs of 8 s, made with
:func:`whiskerid.synthesize_dataset`, as ``whiskerid dataset synth`` makes it) is cut into 1 s
windows; :class:`whiskerid.classify.TerrainClassifier` computes the project's ``fitted``
features of each window (``rate_hz`` given) and trains its MLP. Prints one JSON object: the
grid's scores, the best parameters and the accuracy on recordings held out of the search.
Needs ``pip install "whiskerid[sklearn]"``. Example::

    .venv/bin/python examples/sklearn_pipeline.py --out out/sklearn-synth
"""

import argparse
import json
from pathlib import Path

import numpy as np
from sklearn.model_selection import GridSearchCV, GroupKFold, GroupShuffleSplit
from sklearn.pipeline import Pipeline

import whiskerid as wi
from whiskerid.classify import TerrainClassifier


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/sklearn-synth"), help="dataset folder")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    data = args.out / "dataset"
    # replace_synthetic: a rerun replaces this script's own recordings, and nothing else
    wi.synthesize_dataset(data, terrains=("flat", "brick", "sand"), speeds=(0.1, 0.2),
                          runs=3, duration_s=8.0, seed=args.seed,
                          replace_synthetic=True)  # fmt: skip
    ws = wi.load_dataset(data)
    X, y = ws.windows, np.asarray(ws.label_names)[ws.labels]
    groups = ws.recording  # one group per recording

    # Recordings held out of the search altogether, for an honest final score.
    split = GroupShuffleSplit(n_splits=1, test_size=0.25, random_state=args.seed)
    train, test = next(split.split(X, y, groups))
    pipe = Pipeline([("clf", TerrainClassifier(rate_hz=ws.rate_hz))])
    grid = GridSearchCV(
        pipe,
        {"clf__hidden": [(8,), (16,)], "clf__max_iter": [100, 300]},
        cv=GroupKFold(n_splits=3),
    )
    grid.fit(X[train], y[train], groups=groups[train])

    def plain(params: dict) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}

    results = grid.cv_results_
    scores = zip(results["params"], results["mean_test_score"], strict=True)
    out = {
        "windows": len(y),
        "recordings": len(ws.sources),
        "classes": list(ws.label_names),
        "grid": [{"params": plain(p), "mean_accuracy": round(float(s), 4)} for p, s in scores],
        "best_params": plain(grid.best_params_),
        "held_out_recordings": len(np.unique(groups[test])),
        "held_out_accuracy": round(float(grid.score(X[test], y[test])), 4),
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
