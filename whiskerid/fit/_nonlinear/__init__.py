"""The weakly nonlinear fit: its problem (slow flow of mode 1), backbone, free higher modes,
compiled program, the fit and the selection of its terms or knots.
"""

from ._fit import NonlinearCalibration as NonlinearCalibration
from ._fit import fit_nonlinear as fit_nonlinear
from ._fit import friction_waveform as friction_waveform
from ._fit import rss_of_curves as rss_of_curves
from ._free_modes import free_modes_table as free_modes_table
from ._logpoly import backbone_at as backbone_at
from ._problem import ALL_TERMS as ALL_TERMS
from ._problem import COEFFICIENT_OF as COEFFICIENT_OF
from ._problem import NL_TERMS as NL_TERMS
from ._problem import NonlinearProblem as NonlinearProblem
from ._problem import tip_per_sensor as tip_per_sensor
from ._select import calibrate_logpoly_backbone as calibrate_logpoly_backbone
from ._select import calibrate_nonlinear as calibrate_nonlinear
from ._select import calibrate_nonlinear_selected as calibrate_nonlinear_selected
from ._select import criterion as criterion
from ._select import term_z as term_z
