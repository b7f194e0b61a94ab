"""Terrain classification: datasets of windows, features, the MLP, training, evaluation,
context fusion and model files.

The modules, along the data path: ``_dataset`` (recordings → labelled windows at one rate),
``_features`` (a feature vector per window; its settings in ``_features_spec``, its
whisker-aware filters in ``_features_whisker``), ``_mlp`` (the network and its training loop),
``_split`` (splits and folds by recording), ``_train`` (a :class:`ClassifierModel` from
windows), ``_model_file`` (the model, its compiled predict functions and its files),
``_whisker`` (the whisker's own transfer function, divided out of whisker-aware
features), ``_evaluate`` (scores, cross-validation, the paper's protocol),
``_borealtc`` (a public IMU dataset) and ``_sklearn`` (:class:`TerrainClassifier`, a
scikit-learn estimator; loaded on first use, as it needs scikit-learn). The window checks
(:func:`window_health`) and the context fusion (:func:`fuse_context`) are NumPy only and
live in :mod:`whiskerid.io` (``_health``, ``_health_modes``, ``_context``), so that the
online stream runs them without JAX; they are re-exported here.
"""

from .. import _jax_setup as _jax_setup
from ..io._context import fuse_context as fuse_context
from ..io._health import HealthReference as HealthReference
from ..io._health import window_health as window_health
from ._analysis import analyze_dataset as analyze_dataset
from ._borealtc import load_borealtc as load_borealtc
from ._dataset import RATE_TOLERANCE as RATE_TOLERANCE
from ._dataset import WindowSet as WindowSet
from ._dataset import load_dataset as load_dataset
from ._dataset import recorded_amplifier as recorded_amplifier
from ._dataset import recording_rate as recording_rate
from ._dataset import timestamp_rate as timestamp_rate
from ._evaluate import classification_report as classification_report
from ._evaluate import confusion_matrix as confusion_matrix
from ._evaluate import cross_validate as cross_validate
from ._evaluate import evaluate_classifier as evaluate_classifier
from ._evaluate import evaluate_features as evaluate_features
from ._evaluate import format_confusion as format_confusion
from ._evaluate import format_report as format_report
from ._evaluate import paper_protocol as paper_protocol
from ._evaluate import recording_scores as recording_scores
from ._evaluate import scores as scores
from ._features import FeatureSpec as FeatureSpec
from ._features import band_energies as band_energies
from ._features import base_band_levels as base_band_levels
from ._features import compute_features as compute_features
from ._features import spectral_peaks as spectral_peaks
from ._line_sidebands import TEST_NAME as TEST_NAME
from ._line_sidebands import line_f as line_f
from ._line_sidebands import line_f_at as line_f_at
from ._line_sidebands import line_sideband_test as line_sideband_test
from ._mlp import TrainConfig as TrainConfig
from ._mlp import default_config as default_config
from ._model_file import ClassifierModel as ClassifierModel
from ._model_file import ModelError as ModelError
from ._model_file import trained_on as trained_on
from ._sidebands import sideband_test as sideband_test
from ._sidebands import welch_dof as welch_dof
from ._sidebands import welch_power as welch_power
from ._split import grouped_split as grouped_split
from ._split import recording_folds as recording_folds
from ._split import split_by_recording as split_by_recording
from ._train import default_spec as default_spec
from ._train import features_of as features_of
from ._train import fit_on_features as fit_on_features
from ._train import span_features as span_features
from ._train import train_classifier as train_classifier
from ._whisker import ALIAS_SLOPE as ALIAS_SLOPE
from ._whisker import SPAN_WHISKERS as SPAN_WHISKERS
from ._whisker import WhiskerResponse as WhiskerResponse
from ._whisker import deflection_per_acc as deflection_per_acc


def __getattr__(name: str):
    """:class:`TerrainClassifier` on first use: it needs scikit-learn, an optional dependency
    (``pip install whiskerid[sklearn]``), which the rest of this package does without."""
    if name == "TerrainClassifier":
        from ._sklearn import TerrainClassifier

        return TerrainClassifier
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
