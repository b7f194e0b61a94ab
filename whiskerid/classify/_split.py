"""Honest splits of labelled windows: whole recordings on one side only.

Windows of one recording are strongly correlated (same run, same speed, same sensor
mounting): a random window split would put near copies of a test window into the training
set and flatter every method. :func:`split_by_recording` and :func:`recording_folds` keep
each recording on one side, stratified by label and, where known, speed.
"""

import numpy as np

from ._dataset import WindowSet


def _strata(ws: WindowSet) -> np.ndarray:
    """Stratum per window: label, and speed where known (so splits cover every speed)."""
    sp = np.where(np.isfinite(ws.speeds), np.round(ws.speeds, 3), -1.0)
    return ws.labels * 100_000 + np.round(sp * 1000).astype(int)


def grouped_split(ws: WindowSet, fraction: float, seed: int) -> np.ndarray:
    """Mask of windows in a held-out set of whole recordings, about ``fraction`` per stratum.

    Strata with a single recording are split by windows instead (contiguous blocks would
    still be correlated, so this only happens when there is no other choice).
    """
    rng = np.random.default_rng(seed)
    held = np.zeros(len(ws), bool)
    strata = _strata(ws)
    for s in np.unique(strata):
        in_s = strata == s
        recs = np.unique(ws.recording[in_s])
        if recs.size >= 2:
            k = min(max(round(fraction * recs.size), 1), recs.size - 1)
            pick = rng.choice(recs, k, replace=False)
            held |= in_s & np.isin(ws.recording, pick)
        else:
            idx = np.flatnonzero(in_s)
            k = min(max(round(fraction * idx.size), 1), max(idx.size - 1, 0))
            held[rng.choice(idx, k, replace=False)] = True
    return held


def split_by_recording(ws: WindowSet, test_fraction: float = 0.25, seed: int = 0):
    """``(train, test)`` with no recording in both (stratified by label and speed)."""
    test = grouped_split(ws, test_fraction, seed)
    return ws.subset(~test), ws.subset(test)


def recording_folds(ws: WindowSet, folds: int, seed: int = 0) -> np.ndarray:
    """Fold (``0 … folds − 1``) of every window for cross-validation by recording.

    Whole recordings go to one fold each, stratified: the recordings of each stratum
    (label, and speed where known) are shuffled and dealt to the folds in turn, the
    dealing running on across strata, so every fold gets about ``1/folds`` of each
    stratum and ``folds`` equal to the number of recordings is leave-one-recording-out.

    Raises:
        ValueError: ``folds`` below 2 or above the number of recordings.
    """
    recs = np.unique(ws.recording)
    if not 2 <= folds <= recs.size:
        raise ValueError(
            f"folds = {folds} for {recs.size} recordings: pass 2 to {recs.size} "
            f"({recs.size}: leave one recording out)"
        )
    rng = np.random.default_rng(seed)
    strata = _strata(ws)
    first = np.array([np.flatnonzero(ws.recording == r)[0] for r in recs])
    order = np.concatenate(
        [rng.permutation(recs[strata[first] == s]) for s in np.unique(strata[first])]
    )
    dealt = (np.arange(order.size) + rng.integers(folds)) % folds
    fold_of = dict(zip(order.tolist(), dealt.tolist(), strict=True))
    return np.array([fold_of[r] for r in ws.recording.tolist()], dtype=int)
