"""The linear free-decay (and forced) fit: its problem, start values, variable projection, the
compiled program, window fits and the host helpers it needs.
"""

from ._decay import conversion_average as conversion_average
from ._decay import decay_rates as decay_rates
from ._decay import free_decay_columns as free_decay_columns
from ._host_whisker import nominal_whisker as nominal_whisker
from ._limits import LIMITABLE as LIMITABLE
from ._limits import Parameters as Parameters
from ._limits import at_bound as at_bound
from ._limits import problem_limits as problem_limits
from ._modulus import MODULUS_TOLERANCE as MODULUS_TOLERANCE
from ._modulus import check_tolerance as check_tolerance
from ._modulus import modulus_covariance as modulus_covariance
from ._problem import ZETA_MAX as ZETA_MAX
from ._problem import FitProblem as FitProblem
from ._problem import RecordingModel as RecordingModel
from ._problem import StaticTestModel as StaticTestModel
from ._problem import covariance as covariance
from ._problem import flat_residuals as flat_residuals
from ._problem import nominal_gain as nominal_gain
from ._problem import recording_design as recording_design
from ._problem import reported_names as reported_names
from ._problem import reported_with_jacobian as reported_with_jacobian
from ._problem import residuals as residuals
from ._problem import residuals_and_jacobian as residuals_and_jacobian
from ._problem import solve as solve
from ._program import GTOL as GTOL
from ._program import bucket as bucket
from ._program import fit_problem as fit_problem
from ._program import padded_problem as padded_problem
from ._program import padded_rows as padded_rows
from ._program import positions as positions
from ._program import solve_masked as solve_masked
from ._program import solve_status as solve_status
from ._program import unflatten_numpy as unflatten_numpy
from ._start import start_values as start_values
from ._windows import WindowFits as WindowFits
from ._windows import fit_windows as fit_windows
from ._windows import window_model_residuals as window_model_residuals
from ._windows import window_start as window_start
