"""whiskerid: differentiable system identification for compliant whisker sensors (JAX).

Public API, re-exported from the sub-packages below (SI units throughout):

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

Sub-packages, along the data path (imports run one way, from the top of this list down):
``cli`` → ``hw`` → ``classify`` / ``posterior`` / ``plot`` → ``fit`` / ``terrain`` → ``model``
→ ``io``. The names above are loaded on first use, so ``import whiskerid`` is cheap and does not
start JAX; the first JAX-using name turns on float64 (``jax_enable_x64``): the models need it
(the modal sums near the clamp and the root finding lose their accuracy in float32).
"""

import importlib
from typing import TYPE_CHECKING

# public name -> the sub-package (or module) that defines it (loaded on first use, PEP 562;
# even the version, which the installed package's metadata gives, but slowly)
_LAZY = {
    "__version__": "_version",
    "ClassifierModel": "classify",
    "FeatureSpec": "classify",
    "ModelError": "classify",
    "WindowSet": "classify",
    "band_energies": "classify",
    "base_band_levels": "classify",
    "WhiskerResponse": "classify",
    "SensorPlanes": "terrain",
    "compute_features": "classify",
    "cross_validate": "classify",
    "evaluate_classifier": "classify",
    "fuse_context": "classify",
    "load_borealtc": "classify",
    "load_dataset": "classify",
    "paper_protocol": "classify",
    "recording_scores": "classify",
    "spectral_peaks": "classify",
    "split_by_recording": "classify",
    "train_classifier": "classify",
    "Calibration": "fit",
    "CalibrationError": "fit",
    "Observation": "fit",
    "Peak": "fit",
    "StaticTest": "fit",
    "WindowFits": "fit",
    "amplitude_spectrum": "fit",
    "calibrate": "fit",
    "dominant_peaks": "fit",
    "find_peaks": "fit",
    "fit_windows": "fit",
    "read_static_test": "fit",
    "resample_uniform": "fit",
    "Recording": "io",
    "RecordingError": "io",
    "check_samples": "io",
    "read_recording": "io",
    "write_csv": "io",
    "ADS1115Model": "model",
    "BaseMotion": "model",
    "CoilSpring": "model",
    "HallSensor": "model",
    "ModalState": "model",
    "PAPER_D": "model",
    "RecordError": "model",
    "UniformBeam": "model",
    "Whisker": "model",
    "WhiskerRecord": "model",
    "base_motion_response": "model",
    "cantilever_roots": "model",
    "free_decay": "model",
    "harmonic_from_rest": "model",
    "harmonic_steady_state": "model",
    "load_record": "model",
    "modal_params": "model",
    "mode_shape": "model",
    "observe": "model",
    "paper_coil": "model",
    "paper_eq1": "model",
    "paper_record": "model",
    "paper_whisker": "model",
    "participation_factors": "model",
    "pluck": "model",
    "project_initial_shape": "model",
    "simulate": "model",
    "tap": "model",
    "whisker_from_structure": "model",
    "Posterior": "posterior",
    "PosteriorError": "posterior",
    "sample_posterior": "posterior",
    "setup_posterior": "posterior",
    "SPEEDS_MPS": "terrain",
    "TERRAINS": "terrain",
    "TERRAIN_FAMILIES": "terrain",
    "synthesize_dataset": "terrain",
    "synthesize_runs": "terrain",
    "wheel_filter": "terrain",
}

if TYPE_CHECKING:  # static tools see every name
    from ._version import __version__ as __version__
    from .classify import ClassifierModel as ClassifierModel
    from .classify import FeatureSpec as FeatureSpec
    from .classify import ModelError as ModelError
    from .classify import WhiskerResponse as WhiskerResponse
    from .classify import WindowSet as WindowSet
    from .classify import band_energies as band_energies
    from .classify import base_band_levels as base_band_levels
    from .classify import compute_features as compute_features
    from .classify import cross_validate as cross_validate
    from .classify import evaluate_classifier as evaluate_classifier
    from .classify import fuse_context as fuse_context
    from .classify import load_borealtc as load_borealtc
    from .classify import load_dataset as load_dataset
    from .classify import paper_protocol as paper_protocol
    from .classify import recording_scores as recording_scores
    from .classify import spectral_peaks as spectral_peaks
    from .classify import split_by_recording as split_by_recording
    from .classify import train_classifier as train_classifier
    from .fit import Calibration as Calibration
    from .fit import CalibrationError as CalibrationError
    from .fit import Observation as Observation
    from .fit import Peak as Peak
    from .fit import StaticTest as StaticTest
    from .fit import WindowFits as WindowFits
    from .fit import amplitude_spectrum as amplitude_spectrum
    from .fit import calibrate as calibrate
    from .fit import dominant_peaks as dominant_peaks
    from .fit import find_peaks as find_peaks
    from .fit import fit_windows as fit_windows
    from .fit import read_static_test as read_static_test
    from .fit import resample_uniform as resample_uniform
    from .io import Recording as Recording
    from .io import RecordingError as RecordingError
    from .io import check_samples as check_samples
    from .io import read_recording as read_recording
    from .io import write_csv as write_csv
    from .model import PAPER_D as PAPER_D
    from .model import ADS1115Model as ADS1115Model
    from .model import BaseMotion as BaseMotion
    from .model import CoilSpring as CoilSpring
    from .model import HallSensor as HallSensor
    from .model import ModalState as ModalState
    from .model import RecordError as RecordError
    from .model import UniformBeam as UniformBeam
    from .model import Whisker as Whisker
    from .model import WhiskerRecord as WhiskerRecord
    from .model import base_motion_response as base_motion_response
    from .model import cantilever_roots as cantilever_roots
    from .model import free_decay as free_decay
    from .model import harmonic_from_rest as harmonic_from_rest
    from .model import harmonic_steady_state as harmonic_steady_state
    from .model import load_record as load_record
    from .model import modal_params as modal_params
    from .model import mode_shape as mode_shape
    from .model import observe as observe
    from .model import paper_coil as paper_coil
    from .model import paper_eq1 as paper_eq1
    from .model import paper_record as paper_record
    from .model import paper_whisker as paper_whisker
    from .model import participation_factors as participation_factors
    from .model import pluck as pluck
    from .model import project_initial_shape as project_initial_shape
    from .model import simulate as simulate
    from .model import tap as tap
    from .model import whisker_from_structure as whisker_from_structure
    from .posterior import Posterior as Posterior
    from .posterior import PosteriorError as PosteriorError
    from .posterior import sample_posterior as sample_posterior
    from .posterior import setup_posterior as setup_posterior
    from .terrain import SPEEDS_MPS as SPEEDS_MPS
    from .terrain import TERRAIN_FAMILIES as TERRAIN_FAMILIES
    from .terrain import TERRAINS as TERRAINS
    from .terrain import SensorPlanes as SensorPlanes
    from .terrain import synthesize_dataset as synthesize_dataset
    from .terrain import synthesize_runs as synthesize_runs
    from .terrain import wheel_filter as wheel_filter


def __getattr__(name: str):
    try:
        pkg = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'whiskerid' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f".{pkg}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])


__all__ = sorted(_LAZY)
