"""Numerical tools of the fits: least squares (optimistix, a small host Levenberg–Marquardt), the
ahead-of-time program cache, BLAS threads, trigonometry, χ² and F tail probabilities, column
projections.
"""

from . import _lsq as _lsq
from ._aot import cached_call as cached_call
from ._aot import compile_cache as compile_cache
from ._aot import with_compile_cache as with_compile_cache
from ._chi2 import chi2_sf as chi2_sf
from ._fdist import f_sf as f_sf
from ._lm import lm_least_squares as lm_least_squares
from ._lsq import SOLVERS as SOLVERS
from ._lsq import FitResult as FitResult
from ._lsq import cho_solve_small as cho_solve_small
from ._lsq import cholesky_small as cholesky_small
from ._lsq import from_interval as from_interval
from ._lsq import gradient_cosine as gradient_cosine
from ._lsq import gradient_cosine_from as gradient_cosine_from
from ._lsq import least_squares as least_squares
from ._lsq import residual_variance as residual_variance
from ._lsq import scaled_inverse_gram as scaled_inverse_gram
from ._lsq import to_interval as to_interval
from ._projector import ColumnSubsets as ColumnSubsets
from ._projector import LinearPart as LinearPart
from ._projector import pinv_columns as pinv_columns
from ._projector import subset_mask as subset_mask
from ._threads import single_blas_thread as single_blas_thread
from ._trig import sincos as sincos

#: The least-squares module itself (its functions are used as ``lsq.least_squares``: their names
#: are the module's, shared with other solvers').
lsq = _lsq
