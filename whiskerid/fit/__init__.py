"""Fitting the model to recordings: least squares, calibration, window fits, start values.

The fit problem is public, so that other packages (the posterior) build on it:
:class:`FitProblem` (built from a record and :class:`Observation` objects) gives the whisker at a
parameter pytree, each recording's design columns ``(D, g)``, the residuals
(:func:`residuals` in optimistix's ``fn(y, args)`` form), the parameter flattening and the
reported quantities; :func:`start_values`, :func:`solve` and :func:`covariance` are the
calibration's steps, and :class:`Calibration` carries the problem, its optimum and the
covariance.
"""

from .. import _jax_setup as _jax_setup
from ..io import sha256_of as sha256_of  # its home is whiskerid.io (kept: posterior, cli use it)
from ._added_mass import AddedMass as AddedMass
from ._added_mass import AddedMassProblem as AddedMassProblem
from ._added_mass import calibrate_added_mass as calibrate_added_mass
from ._added_mass import rho_a_from_frequencies as rho_a_from_frequencies
from ._batch import BATCH_LANES as BATCH_LANES
from ._batch import PluckFit as PluckFit
from ._batch import calibrate_each as calibrate_each
from ._batch import problem_shape as problem_shape
from ._batch import stack_problems as stack_problems
from ._calibrate import GTOL as GTOL
from ._calibrate import Calibration as Calibration
from ._calibrate import calibrate as calibrate
from ._data import G0 as G0
from ._data import CalibrationError as CalibrationError
from ._data import Decay as Decay
from ._data import Observation as Observation
from ._data import Peak as Peak
from ._data import StaticTest as StaticTest
from ._data import amplitude_spectrum as amplitude_spectrum
from ._data import check_sampling as check_sampling
from ._data import dominant_peaks as dominant_peaks
from ._data import find_decays as find_decays
from ._data import find_peaks as find_peaks
from ._data import observation_from_recording as observation_from_recording
from ._data import observations_from_file as observations_from_file
from ._data import observations_from_recording as observations_from_recording
from ._data import read_static_test as read_static_test
from ._data import release_time as release_time
from ._data import resample_uniform as resample_uniform
from ._data import steady_line as steady_line
from ._linear import LIMITABLE as LIMITABLE
from ._linear import MODULUS_TOLERANCE as MODULUS_TOLERANCE
from ._linear import ZETA_MAX as ZETA_MAX
from ._linear import FitProblem as FitProblem
from ._linear import Parameters as Parameters
from ._linear import RecordingModel as RecordingModel
from ._linear import StaticTestModel as StaticTestModel
from ._linear import WindowFits as WindowFits
from ._linear import conversion_average as conversion_average
from ._linear import covariance as covariance
from ._linear import decay_rates as decay_rates
from ._linear import fit_windows as fit_windows
from ._linear import free_decay_columns as free_decay_columns
from ._linear import nominal_gain as nominal_gain
from ._linear import recording_design as recording_design
from ._linear import reported_names as reported_names
from ._linear import residuals as residuals
from ._linear import solve as solve
from ._linear import start_values as start_values
from ._linear import window_model_residuals as window_model_residuals
from ._linear import window_start as window_start
from ._nonlinear import ALL_TERMS as ALL_TERMS
from ._nonlinear import NL_TERMS as NL_TERMS
from ._nonlinear import NonlinearCalibration as NonlinearCalibration
from ._nonlinear import NonlinearProblem as NonlinearProblem
from ._nonlinear import calibrate_nonlinear as calibrate_nonlinear
from ._nonlinear import calibrate_nonlinear_selected as calibrate_nonlinear_selected
from ._numerics import SOLVERS as SOLVERS
from ._numerics import FitResult as FitResult
from ._numerics import cho_solve_small as cho_solve_small
from ._numerics import cholesky_small as cholesky_small
from ._numerics import from_interval as from_interval
from ._numerics import gradient_cosine as gradient_cosine
from ._numerics import least_squares as least_squares
from ._numerics import sincos as sincos
from ._numerics import to_interval as to_interval
from ._profile import profile_interval as profile_interval
from ._result import fit_report as fit_report
