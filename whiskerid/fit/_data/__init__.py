"""Recordings as the fits see them: observations, release (decay) detection, the noise floor,
signal helpers (spectra, peaks, resampling).
"""

from ._noise_floor import check_noise_floor as check_noise_floor
from ._observation import G0 as G0
from ._observation import CalibrationError as CalibrationError
from ._observation import Observation as Observation
from ._observation import StaticTest as StaticTest
from ._observation import check_sampling as check_sampling
from ._observation import nominal_gain as nominal_gain
from ._observation import observation_from_recording as observation_from_recording
from ._observation import observations_from_file as observations_from_file
from ._observation import observations_from_recording as observations_from_recording
from ._observation import read_static_test as read_static_test
from ._observation import release_time as release_time
from ._release import Decay as Decay
from ._release import find_decays as find_decays
from ._release import steady_line as steady_line
from ._ringing import quantum as quantum
from ._signal import Peak as Peak
from ._signal import amplitude_spectrum as amplitude_spectrum
from ._signal import dominant_peaks as dominant_peaks
from ._signal import fast_length as fast_length
from ._signal import find_peaks as find_peaks
from ._signal import line_fit as line_fit
from ._signal import median as median
from ._signal import resample_uniform as resample_uniform
from ._signal import spectral_window as spectral_window
