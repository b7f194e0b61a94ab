"""A scikit-learn estimator of terrain: the project's features and MLP behind ``fit``/``predict``.

scikit-learn is an optional dependency (``pip install whiskerid[sklearn]``); this module is
the only one that imports it, and :mod:`whiskerid.classify` loads it on first use of
:class:`TerrainClassifier`, so the rest of the package runs without it.

Two modes, chosen by ``rate_hz``:

- ``rate_hz=None``: ``X`` is a feature array ``(n, p)`` (any features, e.g. from
  :func:`whiskerid.classify.compute_features`);
- ``rate_hz`` given: ``X`` holds windows of samples ``(n, window)`` at that rate, one channel,
  and the estimator computes the project's features (``features``: ``fitted`` or ``paper``,
  :class:`~whiskerid.classify.FeatureSpec`) before the network.

The features are standardised (mean and σ of the training set) and the network is the
classifier's MLP (:func:`whiskerid.classify._mlp.train_mlp`), trained full batch for
``max_iter`` epochs on all of ``X`` (no early stopping: scikit-learn's ``fit(X, y)`` knows no
recordings to hold out; choose ``max_iter`` by :class:`~sklearn.model_selection.GridSearchCV`
with :class:`~sklearn.model_selection.GroupKFold` over recordings instead).
"""

from dataclasses import replace

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from ._features import FeatureSpec, compute_features
from ._mlp import TrainConfig, from_arrays, predict_proba, to_arrays, train_mlp


class TerrainClassifier(ClassifierMixin, BaseEstimator):
    """Terrain classifier with scikit-learn's interface (``Pipeline``, ``GridSearchCV``).

    Args:
        rate_hz: Sample rate of windows given as ``X`` (Hz); None: ``X`` is features.
        features: ``fitted`` or ``paper`` (windows only).
        hidden: Hidden layer widths of the MLP.
        max_iter: Training epochs (full batch: one step each).
        learning_rate: AdamW step size.
        weight_decay: AdamW's decoupled weight decay.
        input_noise: σ of Gaussian noise added to the standardised inputs while training.
        balance: Weight classes alike in the loss.
        random_state: Seed of the initialisation and the input noise.

    Attributes:
        classes_: The labels, in the order of :meth:`predict_proba`'s columns.
        n_features_in_: Columns of ``X`` (samples per window in the window mode).
        n_iter_: Epochs trained.
        feature_mean_, feature_std_: The standardisation of the features.
        weights_, layer_sizes_: The trained network (NumPy arrays: the estimator pickles and
            clones without JAX state).
    """

    def __init__(
        self,
        rate_hz: float | None = None,
        features: str = "fitted",
        hidden: tuple[int, ...] = (16,),
        max_iter: int = 300,
        learning_rate: float = 3e-3,
        weight_decay: float = 1.0,
        input_noise: float = 0.3,
        balance: bool = True,
        random_state: int = 0,
    ):
        self.rate_hz = rate_hz
        self.features = features
        self.hidden = hidden
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.weight_decay = weight_decay
        self.input_noise = input_noise
        self.balance = balance
        self.random_state = random_state

    def _features(self, X: np.ndarray) -> np.ndarray:
        if self.rate_hz is None:
            return np.asarray(X, float)
        spec = FeatureSpec(kind=self.features, rate_hz=float(self.rate_hz), window=X.shape[1])
        return np.asarray(compute_features(spec, X), float)

    def fit(self, X, y):
        """Compute the features, standardise them and train the network.

        Args:
            X: Features ``(n, p)``, or windows ``(n, window)`` with ``rate_hz``.
            y: Labels ``(n,)`` (any hashable values).

        Returns:
            self
        """
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        if self.rate_hz is not None and self.features not in ("fitted", "paper"):
            raise ValueError(f"features must be 'fitted' or 'paper', not {self.features!r}")
        if int(self.max_iter) < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        self.classes_, codes = np.unique(y, return_inverse=True)
        feats = self._features(X)
        self.feature_mean_ = feats.mean(axis=0)
        self.feature_std_ = np.maximum(feats.std(axis=0), 1e-6 * (np.abs(self.feature_mean_) + 1.0))
        z = (feats - self.feature_mean_) / self.feature_std_
        config = replace(
            TrainConfig(),
            hidden=tuple(int(h) for h in self.hidden),
            learning_rate=float(self.learning_rate),
            weight_decay=float(self.weight_decay),
            input_noise=float(self.input_noise),
            balance=bool(self.balance),
            seed=int(self.random_state),
            chunk=min(TrainConfig().chunk, int(self.max_iter)),
        )
        res = train_mlp(z, codes, z[:0], codes[:0], len(self.classes_), config,
                        epochs=int(self.max_iter))  # fmt: skip
        self.n_iter_ = int(res.epochs)
        self.weights_ = to_arrays(res.model)
        self.layer_sizes_ = list(res.model.sizes)
        return self

    def predict_proba(self, X) -> np.ndarray:
        """Class probabilities ``(n, len(classes_))``."""
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        z = (self._features(X) - self.feature_mean_) / self.feature_std_
        model = from_arrays(self.weights_, self.layer_sizes_)
        return np.asarray(predict_proba(model, z), float)

    def predict(self, X) -> np.ndarray:
        """The most probable label of each row."""
        check_is_fitted(self)
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]
