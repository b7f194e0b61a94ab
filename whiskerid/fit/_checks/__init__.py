"""Checks of a converged fit: residual correlation and lines, HAC covariance, bounds and
plausibility, the residual spectrum against the sensor noise.
"""

from ._checks import LAG1_MAX as LAG1_MAX
from ._checks import bartlett_meat as bartlett_meat
from ._checks import check_fit as check_fit
from ._checks import data_side as data_side
from ._checks import decay_sampling_rates_hz as decay_sampling_rates_hz
from ._checks import hac_covariance as hac_covariance
from ._checks import lag1 as lag1
from ._checks import lag_below as lag_below
from ._checks import moments as moments
from ._checks import no_smaller_than as no_smaller_than
from ._checks import residual_peak as residual_peak
from ._checks import robust_covariance as robust_covariance
from ._spectral_floor import residual_spectra as residual_spectra
