"""Figures (matplotlib, saved as PNG): signals, spectra, calibrations, posteriors, classifiers.

matplotlib is imported when a figure is drawn, not when this package is imported (it is the
optional ``plot`` extra).
"""

from ._added_mass import plot_added_mass as plot_added_mass
from ._calibrate import plot_calibration as plot_calibration
from ._classify import plot_confusion as plot_confusion
from ._fleet import plot_fleet_history as plot_fleet_history
from ._plot import plot_dominant_frequencies as plot_dominant_frequencies
from ._plot import plot_modal_analysis as plot_modal_analysis
from ._plot import plot_recording_labels as plot_recording_labels
from ._plot import plot_signal_and_spectrum as plot_signal_and_spectrum
from ._plot import real_peaks as real_peaks
from ._posterior import plot_corner as plot_corner
from ._posterior import plot_predictive as plot_predictive
from ._posterior import plot_trace as plot_trace
from ._profile import plot_profile as plot_profile
from ._sidebands import plot_sidebands as plot_sidebands
