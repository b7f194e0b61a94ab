"""Evaluating classifiers: scores and confusion matrices, labels per window, per fused
context and per whole recording; cross-validation by recording, and the paper's protocol
(random 75/25 window split, 20 repeats) for comparability."""

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..io._context import check_context, default_context_s, fuse_context
from ._dataset import WindowSet
from ._mlp import (
    TrainConfig,
    default_config,
    predict_proba,
)
from ._model_file import ClassifierModel
from ._split import recording_folds
from ._train import (
    check_classes,
    default_spec,
    features_of,
    fit_on_features,
    span_count,
    with_span_features,
)
from ._whisker import WhiskerResponse


def confusion_matrix(y_true, y_pred, n_classes: int) -> np.ndarray:
    """Counts ``C[i, j]`` of windows of class ``i`` predicted as ``j``."""
    c = np.zeros((n_classes, n_classes), dtype=int)
    np.add.at(c, (np.asarray(y_true), np.asarray(y_pred)), 1)
    return c


def classification_report(conf: np.ndarray, labels) -> dict:
    """Precision, recall, F1 and support per class, with their macro (plain mean over the
    classes that have windows) and weighted (by support) averages, as scikit-learn's
    ``classification_report`` defines them (a class never predicted has precision 0).
    """
    conf = np.asarray(conf)
    tp, rows, cols = conf.diagonal(), conf.sum(axis=1), conf.sum(axis=0)
    precision = np.where(cols > 0, tp / np.maximum(cols, 1), 0.0)
    recall = np.where(rows > 0, tp / np.maximum(rows, 1), 0.0)
    f1 = np.where(precision + recall > 0,
                  2 * precision * recall / np.maximum(precision + recall, 1e-300), 0.0)  # fmt: skip
    rounded = zip(labels, precision, recall, f1, rows, strict=True)
    per = {lab: {"precision": round(float(p), 4), "recall": round(float(r), 4),
                 "f1": round(float(f), 4), "support": int(n)}
           for lab, p, r, f, n in rounded}  # fmt: skip
    seen = rows > 0
    total = max(int(rows.sum()), 1)

    def avg(weights):
        return {
            name: round(float(np.sum(v * weights) / max(np.sum(weights), 1e-300)), 4)
            for name, v in (("precision", precision), ("recall", recall), ("f1", f1))
        }

    return {"per_class": per,
            "macro_avg": {**avg(seen.astype(float)), "support": int(rows.sum())},
            "weighted_avg": {**avg(rows / total), "support": int(rows.sum())}}  # fmt: skip


def format_report(report: dict) -> str:
    """:func:`classification_report` as a text table (scikit-learn's layout)."""
    names = list(report["per_class"])
    width = max(12, *(len(n) for n in names))
    head = " " * width + "  precision    recall  f1-score   support"
    rows = [head, ""]
    lines = [*report["per_class"].items(), ("", None), ("macro avg", report["macro_avg"]),
             ("weighted avg", report["weighted_avg"])]  # fmt: skip
    for name, r in lines:
        if r is None:
            rows.append("")
            continue
        rows.append(f"{name:>{width}}  {r['precision']:9.3f} {r['recall']:9.3f} "
                    f"{r['f1']:9.3f} {r['support']:9d}")  # fmt: skip
    return "\n".join(rows)


def scores(conf: np.ndarray, labels) -> dict:
    """Accuracy, per-class accuracy (recall; None for a class without windows), the
    confusion matrix and :func:`classification_report` (``report``) as a JSON-able dict."""
    total, rows = conf.sum(), conf.sum(axis=1)
    per = conf.diagonal() / np.maximum(rows, 1)
    return {
        "report": classification_report(conf, labels),
        "accuracy": float(conf.trace() / max(total, 1)),
        "per_class": {
            lab: round(float(a), 4) if n else None  # None: no windows of it
            for lab, a, n in zip(labels, per, rows, strict=True)
        },
        "confusion": conf.tolist(),
        "labels": list(labels),
        "n_windows": int(total),
    }


def evaluate(model: ClassifierModel, ws: WindowSet) -> dict:
    """Scores of ``model`` on labelled windows (labels must be among the model's).

    Labels fuse each window's context as the model says (``context_s``); the accuracy of
    every window on its own is reported next to them (``accuracy_per_window``), and that of
    whole-recording labels (:func:`recording_scores`).
    """
    missing = sorted(set(ws.label_names) - set(model.labels))
    if missing:
        raise ValueError(
            f"dataset labels {missing} are not classes of the model {list(model.labels)}"
        )
    y = np.array([model.labels.index(ws.label_names[k]) for k in ws.labels], dtype=int)
    p = model.predict_proba(ws.windows, ws.speeds if model.needs_speed else None)
    return _scores_with_context(model, p, y, ws)


def _scores_with_context(model: ClassifierModel, p: np.ndarray, y: np.ndarray, ws) -> dict:
    fused = model.fuse(p, ws.recording, ws.starts())
    out = scores(confusion_matrix(y, np.argmax(fused, axis=1), len(model.labels)), model.labels)
    out["context_s"] = model.context_s
    out["accuracy_per_window"] = float(np.mean(np.argmax(p, axis=1) == y))
    out.update(recording_scores(p, y, ws, model.labels))
    return out


def recording_scores(proba: np.ndarray, labels: np.ndarray, ws: WindowSet,
                     label_names=None) -> dict:  # fmt: skip
    """Whole-recording labels: the mean of each recording's window probabilities, as
    ``classify`` labels a recording.

    A different task from a label per window: it waits for the end of the recording, and
    there are far fewer recordings than windows to count.

    Args:
        proba: Class probabilities per window of ``ws``.
        labels: True class per window (indices into ``label_names``).
        ws: The windows (their recordings and sources).
        label_names: Class names; ``ws.label_names`` by default.

    Returns:
        ``accuracy_per_recording`` (share of recordings labelled right), ``n_recordings``
        and ``wrong_recordings``: each recording labelled wrong, as ``label/file``, with
        its predicted label and that label's mean probability.
    """
    names = ws.label_names if label_names is None else label_names
    right, wrong = [], []
    for r in np.unique(ws.recording).tolist():
        mean = proba[ws.recording == r].mean(axis=0)
        pred, true = int(np.argmax(mean)), int(labels[ws.recording == r][0])
        right.append(pred == true)
        if pred != true:
            wrong.append({"recording": f"{names[true]}/{Path(ws.sources[r]).name}",
                          "predicted": names[pred],
                          "confidence": round(float(mean[pred]), 4)})  # fmt: skip
    return {"accuracy_per_recording": float(np.mean(right)), "n_recordings": len(right),
            "wrong_recordings": wrong}  # fmt: skip


def format_confusion(conf, labels) -> str:
    """The confusion matrix as a text table (rows: true class; columns: predicted)."""
    conf = np.asarray(conf)
    short = [str(lab) for lab in labels]  # whole: "soft-grass" cut to 9 read "soft-gras"
    width = max(9, max(len(s) for s in short))
    lines = ["true \\ pred".ljust(width + 2) + " ".join(s.rjust(width) for s in short) + "  acc"]
    for i, lab in enumerate(short):
        acc = f"{conf[i, i] / conf[i].sum():.3f}" if conf[i].sum() else "    -"  # none seen
        cells = " ".join(str(v).rjust(width) for v in conf[i])
        lines.append(lab.ljust(width + 2) + cells + f"  {acc}")
    return "\n".join(lines)


def paper_protocol(
    ws: WindowSet,
    *,
    features: str = "paper",
    repeats: int = 20,
    test_fraction: float = 0.25,
    seed: int = 0,
    config: TrainConfig | None = None,
) -> dict:
    """The paper's protocol: random 75/25 *window* split, ``repeats`` times.

    Windows of one recording land on both sides, so this flatters every method; it is
    reported for comparability with the paper's 85.6 %, next to the split by recording.

    Returns:
        Mean and standard deviation of the accuracy, per-class mean accuracy and the
        summed confusion matrix.
    """
    if config is None:
        config = default_config(features)
    spec = default_spec(ws, features)
    feats = features_of(ws, spec)
    rng = np.random.default_rng(seed)
    accs, total = [], np.zeros((len(ws.label_names),) * 2, int)
    for r in range(repeats):
        test = np.zeros(len(ws), bool)
        test[rng.permutation(len(ws))[: round(test_fraction * len(ws))]] = True
        # Random-window validation too, as the paper had no notion of recordings.
        train_ws = replace(ws.subset(~test), recording=np.arange(int((~test).sum())))
        model = fit_on_features(feats[~test], train_ws, spec, replace(config, seed=config.seed + r))
        pred = np.argmax(_proba_from_features(model, feats[test]), axis=1)
        conf = confusion_matrix(ws.labels[test], pred, len(ws.label_names))
        accs.append(conf.trace() / conf.sum())
        total += conf
    out = scores(total, ws.label_names)
    out.update(accuracy_mean=float(np.mean(accs)), accuracy_std=float(np.std(accs)),
               repeats=repeats)  # fmt: skip
    return out


def cross_validate(
    ws: WindowSet,
    *,
    features: str = "fitted",
    folds: int = 5,
    seed: int = 0,
    config: TrainConfig | None = None,
    context_s: float | None = None,
    use_speed: bool | None = None,
    progress: bool = False,
    whisker=None,
    window_fit: bool = False,
    span_whiskers: int | None = None,
) -> dict:
    """Cross-validation by recording: every recording is tested once, by a model that
    never saw it (:func:`recording_folds`).

    The estimate of how well a classifier trained on all of ``ws`` does on a *new*
    recording, with more of the data in each training set than one 75/25 split and
    without the luck of which recordings were held out. ``folds`` equal to the number of
    recordings is leave-one-recording-out.

    Args:
        ws: Labelled windows.
        features: ``fitted`` or ``paper``.
        folds: Number of folds (2 to the number of recordings).
        seed: Seeds the folds and the networks (fold ``k`` trains with ``seed + k``).
        config: Training settings; :func:`default_config` of ``features`` by default.
        context_s: Signal each label rests on (s); :func:`default_context_s` by default.
        use_speed: Speed-normalised features; by default when every recording has a speed.
        progress: Show a progress bar over the folds (on stderr).
        whisker: The calibrated whisker (:class:`WhiskerResponse`) that recorded ``ws``,
            for whisker-aware features (see :func:`train_classifier`).
        window_fit: Per-window damped-oscillation fits among the features.
        span_whiskers: Whiskers of the span each training window is also seen through
            (see :func:`train_classifier`); only the training folds' windows, never a
            test fold's.

    Returns:
        :func:`scores` of the fused labels pooled over all windows, plus
        ``accuracy_per_window``, :func:`recording_scores` (whole-recording labels),
        ``context_s``, ``folds``, ``accuracy_by_fold`` (fused
        labels) and ``per_recording`` (source and label → fused accuracy).
    """
    check_classes(ws)
    fold = recording_folds(ws, folds, seed)
    config = default_config(features) if config is None else config
    if whisker is not None:
        channels = ws.windows.shape[1] if ws.windows.ndim == 3 else 1
        whisker = WhiskerResponse(whisker.record, whisker.amplifier, channels)
    spec = default_spec(ws, features, use_speed=use_speed, whisker=whisker is not None,
                        window_fit=window_fit)  # fmt: skip
    window_s = spec.window / spec.rate_hz
    context_s = default_context_s(features, window_s) if context_s is None else context_s
    check_context(context_s, window_s)
    count = span_count(span_whiskers, whisker)
    plain = features_of(ws, spec, whisker)
    feats, all_ws, index = with_span_features(plain, ws, spec, whisker, count, config.seed)
    proba = np.zeros((len(ws), len(ws.label_names)))
    for k in _progress(range(folds), progress, desc="folds"):
        test = fold == k
        train = ~test[index]
        model = fit_on_features(feats[train], all_ws.subset(train), spec,
                                replace(config, seed=config.seed + seed + k),
                                whisker=whisker)  # fmt: skip
        proba[test] = _proba_from_features(model, plain[test])
    lookback = max(context_s - window_s, 0.0)
    fused = fuse_context(proba, ws.recording, ws.starts(), lookback_s=lookback)
    pred, y = np.argmax(fused, axis=1), ws.labels
    out = scores(confusion_matrix(y, pred, len(ws.label_names)), ws.label_names)
    out.update(
        accuracy_per_window=float(np.mean(np.argmax(proba, axis=1) == y)),
        **recording_scores(proba, y, ws),
        context_s=context_s,
        folds=folds,
        accuracy_by_fold=[round(float(np.mean(pred[fold == k] == y[fold == k])), 4)
                          for k in range(folds)],
        per_recording={
            f"{ws.label_names[y[ws.recording == r][0]]}/{Path(ws.sources[r]).name}":
                round(float(np.mean(pred[ws.recording == r] == y[ws.recording == r])), 4)
            for r in np.unique(ws.recording).tolist()
        },
    )  # fmt: skip
    return out


def _progress(items, show: bool, desc: str):
    return tqdm(items, desc=desc, disable=not show, file=sys.stderr, leave=False)


def _proba_from_features(model: ClassifierModel, feats: np.ndarray) -> np.ndarray:
    z = (np.asarray(feats, np.float32) - model.mean) / model.std
    return np.mean([np.asarray(predict_proba(n, z)) for n in model.nets], axis=0)


def evaluate_features(model: ClassifierModel, feats: np.ndarray, ws: WindowSet) -> dict:
    """:func:`evaluate` from precomputed features of ``ws`` (same spec and labels as the
    model)."""
    return _scores_with_context(model, _proba_from_features(model, feats), ws.labels, ws)


#: The public name of :func:`evaluate` (``whiskerid.evaluate_classifier``).
evaluate_classifier = evaluate
