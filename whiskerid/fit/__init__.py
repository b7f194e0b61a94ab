"""Fitting the model to recordings: least squares, calibration, window fits, start values."""

from .. import _jax_setup as _jax_setup
from ._calibrate import Calibration as Calibration
from ._calibrate import CalibrationError as CalibrationError
from ._calibrate import Observation as Observation
from ._calibrate import StaticTest as StaticTest
from ._calibrate import WindowFits as WindowFits
from ._calibrate import calibrate as calibrate
from ._calibrate import fit_windows as fit_windows
from ._calibrate import read_static_test as read_static_test
from ._signal import Peak as Peak
from ._signal import amplitude_spectrum as amplitude_spectrum
from ._signal import dominant_peaks as dominant_peaks
from ._signal import find_peaks as find_peaks
from ._signal import resample_uniform as resample_uniform
