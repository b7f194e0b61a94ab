"""whiskerid: differentiable system identification for compliant whisker sensors (JAX).

Public API, re-exported from private modules (SI units throughout):

* whiskers: :class:`Whisker` (the parameter pytree), :class:`CoilSpring`,
  :class:`UniformBeam`, :func:`whisker_from_structure`, :func:`paper_whisker`;
* records: :class:`WhiskerRecord`, :func:`load_record`, :func:`paper_record`;
* modes: :func:`cantilever_roots`, :func:`mode_shape`, :func:`participation_factors`;
* responses: :func:`paper_eq1` (Eq. 1 as printed) and the exact modal model
  (:func:`harmonic_steady_state`, :func:`harmonic_from_rest`, :func:`free_decay`,
  :func:`base_motion_response`, :func:`observe`);
* sensing: :class:`HallSensor`, :class:`ADS1115Model`, :func:`simulate`;
* calibration: :func:`calibrate` (κ/f_1, ζ, EI or C with uncertainties from recordings and
  static tests), :class:`Observation`, :class:`StaticTest`, :class:`Calibration`, and
  :func:`fit_windows` (batched per-window damped-oscillation fits);
* posteriors: :func:`sample_posterior` (emcee, jointly over recordings, Gaussian or
  Student-t, HDF5 resume, τ-based convergence), :func:`setup_posterior`, :class:`Posterior`;
* terrain classification: :func:`synthesize_dataset` (simulated terrains),
  :func:`compute_features` / :class:`FeatureSpec`, :func:`load_dataset`,
  :func:`train_classifier`, :func:`evaluate_classifier`, :func:`cross_validate`
  (every recording tested once, by a model that never saw it), :func:`paper_protocol`,
  :func:`fuse_context` (labels from a window and the windows before it), and
  :class:`ClassifierModel` (``predict_window`` / ``window_proba`` for online use);
* signals and files: :func:`dominant_peaks`, :class:`Recording`, :func:`read_recording`,
  :func:`write_csv`.

Importing whiskerid turns on float64 in JAX (``jax_enable_x64``): the models need it (the
modal sums near the clamp and the root finding lose their accuracy in float32).
"""

__version__ = "0.1.0"

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._borealtc import load_borealtc as load_borealtc
from ._calibrate import Calibration as Calibration
from ._calibrate import CalibrationError as CalibrationError
from ._calibrate import Observation as Observation
from ._calibrate import StaticTest as StaticTest
from ._calibrate import WindowFits as WindowFits
from ._calibrate import calibrate as calibrate
from ._calibrate import fit_windows as fit_windows
from ._calibrate import read_static_test as read_static_test
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
from ._io import Recording as Recording
from ._io import RecordingError as RecordingError
from ._io import check_samples as check_samples
from ._io import read_recording as read_recording
from ._io import write_csv as write_csv
from ._modes import PAPER_D as PAPER_D
from ._modes import cantilever_roots as cantilever_roots
from ._modes import mode_shape as mode_shape
from ._modes import participation_factors as participation_factors
from ._paper import paper_eq1 as paper_eq1
from ._posterior import Posterior as Posterior
from ._posterior import PosteriorError as PosteriorError
from ._posterior import sample_posterior as sample_posterior
from ._posterior import setup_posterior as setup_posterior
from ._record import RecordError as RecordError
from ._record import WhiskerRecord as WhiskerRecord
from ._record import load_record as load_record
from ._record import paper_record as paper_record
from ._response import ModalState as ModalState
from ._response import base_motion_response as base_motion_response
from ._response import free_decay as free_decay
from ._response import harmonic_from_rest as harmonic_from_rest
from ._response import harmonic_steady_state as harmonic_steady_state
from ._response import modal_params as modal_params
from ._response import observe as observe
from ._response import pluck as pluck
from ._response import project_initial_shape as project_initial_shape
from ._response import tap as tap
from ._sensor import ADS1115Model as ADS1115Model
from ._sensor import HallSensor as HallSensor
from ._signal import Peak as Peak
from ._signal import amplitude_spectrum as amplitude_spectrum
from ._signal import dominant_peaks as dominant_peaks
from ._signal import find_peaks as find_peaks
from ._signal import resample_uniform as resample_uniform
from ._simulate import BaseMotion as BaseMotion
from ._simulate import simulate as simulate
from ._terrain import SPEEDS_MPS as SPEEDS_MPS
from ._terrain import TERRAIN_FAMILIES as TERRAIN_FAMILIES
from ._terrain import TERRAINS as TERRAINS
from ._terrain import synthesize_dataset as synthesize_dataset
from ._terrain import synthesize_runs as synthesize_runs
from ._terrain import wheel_filter as wheel_filter
from ._whisker import CoilSpring as CoilSpring
from ._whisker import UniformBeam as UniformBeam
from ._whisker import Whisker as Whisker
from ._whisker import paper_coil as paper_coil
from ._whisker import paper_whisker as paper_whisker
from ._whisker import whisker_from_structure as whisker_from_structure
