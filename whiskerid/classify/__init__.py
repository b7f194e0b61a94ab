"""Terrain classification: features, the MLP, datasets, model files, training and evaluation."""

from .. import _jax_setup as _jax_setup
from ._borealtc import load_borealtc as load_borealtc
from ._classify import ClassifierModel as ClassifierModel
from ._classify import ModelError as ModelError
from ._classify import WindowSet as WindowSet
from ._classify import cross_validate as cross_validate
from ._classify import evaluate_classifier as evaluate_classifier
from ._classify import fuse_context as fuse_context
from ._classify import load_dataset as load_dataset
from ._classify import paper_protocol as paper_protocol
from ._classify import recording_scores as recording_scores
from ._classify import split_by_recording as split_by_recording
from ._classify import train_classifier as train_classifier
from ._features import FeatureSpec as FeatureSpec
from ._features import band_energies as band_energies
from ._features import compute_features as compute_features
from ._features import spectral_peaks as spectral_peaks
