"""whiskerid.classify.TerrainClassifier: a scikit-learn estimator on features or windows."""

import numpy as np
import pytest

pytest.importorskip("sklearn")

from sklearn.base import clone
from sklearn.model_selection import GroupKFold, cross_val_score
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from whiskerid.classify import TerrainClassifier

#: check_estimator's checks that do not apply, with the reason (none at present: the list is
#: passed to scikit-learn, which then expects these to fail and says so if one passes).
EXPECTED_FAILED: dict[str, str] = {}


def _small():
    return TerrainClassifier(hidden=(8,), max_iter=40)


def test_fit_predict_score_on_features():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((160, 4))
    y = np.where(X[:, 0] - X[:, 2] > 0, "gravel", "grass")
    clf = TerrainClassifier(hidden=(8,), max_iter=200).fit(X[:120], y[:120])
    assert list(clf.classes_) == ["grass", "gravel"]
    p = clf.predict_proba(X[120:])
    assert p.shape == (40, 2) and np.allclose(p.sum(axis=1), 1)
    assert clf.score(X[120:], y[120:]) > 0.85  # a linear boundary, learnt
    assert set(clf.predict(X[120:])) <= {"grass", "gravel"}
    assert clf.get_params()["max_iter"] == 200
    assert clone(clf).set_params(max_iter=5).get_params()["max_iter"] == 5
    # same seed, same network
    again = TerrainClassifier(hidden=(8,), max_iter=200).fit(X[:120], y[:120])
    assert np.array_equal(again.predict_proba(X[120:]), p)


@pytest.mark.slow
def test_windows_mode_in_a_grouped_pipeline():
    """Windows of samples at rate_hz: the project's features, then the network; in a
    Pipeline scored by recording (GroupKFold)."""
    rate, n = 200.0, 64
    rng = np.random.default_rng(1)
    t = np.arange(n) / rate
    X, y, groups = [], [], []
    for rec in range(6):  # 6 recordings, 2 terrains: a 20 Hz or a 60 Hz vibration
        f = 20.0 if rec % 2 else 60.0
        for _ in range(15):
            X.append(np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) + 0.3 * rng.standard_normal(n))
            y.append("soft" if rec % 2 else "hard")
            groups.append(rec)
    X, y = np.asarray(X), np.asarray(y)
    pipe = Pipeline([("clf", TerrainClassifier(rate_hz=rate, hidden=(8,), max_iter=100))])
    acc = cross_val_score(pipe, X, y, groups=groups, cv=GroupKFold(n_splits=3))
    assert acc.mean() > 0.9
    with pytest.raises(ValueError):  # windows of another length than those fitted
        pipe.fit(X, y).predict(X[:, :32])
    feats = Pipeline([("scale", StandardScaler()), ("clf", _small())])
    assert feats.fit(rng.standard_normal((30, 3)), y[:30]).predict(X[:2, :3]).shape == (2,)


@pytest.mark.slow
def test_check_estimator_on_features():
    from sklearn.utils.estimator_checks import check_estimator

    results = check_estimator(
        _small(), expected_failed_checks=EXPECTED_FAILED, on_fail=None, on_skip=None
    )
    failed = [(r["check_name"], str(r["exception"])[:200]) for r in results
              if r["status"] == "failed"]  # fmt: skip
    assert failed == []
    # Skipped by scikit-learn itself: only the array-API check, which runs only with
    # SCIPY_ARRAY_API=1 and an array-API estimator (this one converts to NumPy).
    skipped = {r["check_name"] for r in results if r["status"] == "skipped"}
    assert skipped <= {"check_array_api_input"}
    assert sum(r["status"] == "passed" for r in results) > 40
