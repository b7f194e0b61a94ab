"""Figures (matplotlib, saved as PNG): signals, spectra, calibrations, posteriors, classifiers."""
