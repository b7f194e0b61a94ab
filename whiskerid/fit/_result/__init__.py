"""A calibration's result (:class:`Calibration`), its status, diagnostics, record and report:
the steps after the solve that the linear, added-mass and nonlinear fits share.
"""

from ._calibration import POOR_FIT_SNR_DB as POOR_FIT_SNR_DB
from ._calibration import Calibration as Calibration
from ._calibration import correlation_table as correlation_table
from ._calibration import fit_diagnostics as fit_diagnostics
from ._calibration import fit_status as fit_status
from ._calibration import poor_fit_warnings as poor_fit_warnings
from ._calibration import record_with_fit as record_with_fit
from ._calibration import recording_blocks as recording_blocks
from ._calibration import recording_diagnostics as recording_diagnostics
from ._calibration import reported_std as reported_std
from ._report import fit_report as fit_report
