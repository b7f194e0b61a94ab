"""Whisker health across a fleet: many whiskers calibrated session after session, and the
sessions in which one has changed.

:func:`discover` finds the sessions of ``ROOT/<whisker-id>/<session>/<recordings>``;
:func:`calibrate_fleet` fits them (skipping those done, in this process or on a Ray cluster
through :func:`ray_runner`) into one record per session and the table ``fleet.csv``;
:func:`identify_driving` finds a whisker's f_1 and ζ from driving data (no pluck), a
session of the health log ``health.csv``; :func:`check_fleet` searches each whisker's
history for a lasting change;
:func:`simulate_fleet` writes a simulated fleet with known damage to try it on.
"""

from .. import _jax_setup as _jax_setup
from ._calibrate import FleetRun as FleetRun
from ._calibrate import FleetSettings as FleetSettings
from ._calibrate import bucket_length as bucket_length
from ._calibrate import calibrate_fleet as calibrate_fleet
from ._calibrate import fit_session as fit_session
from ._calibrate import fit_sessions as fit_sessions
from ._calibrate import iter_fit_sessions as iter_fit_sessions
from ._calibrate import local_runner as local_runner
from ._calibrate import session_key as session_key
from ._check import FleetCheck as FleetCheck
from ._check import WhiskerHistory as WhiskerHistory
from ._check import check_fleet as check_fleet
from ._check import refuse_corrupt_values as refuse_corrupt_values
from ._driving import BLOCK_S as BLOCK_S
from ._driving import MIN_BLOCKS as MIN_BLOCKS
from ._driving import SEGMENT_S as SEGMENT_S
from ._driving import DriveFit as DriveFit
from ._driving import combine_blocks as combine_blocks
from ._driving import drive_problem as drive_problem
from ._driving import driving_blocks as driving_blocks
from ._driving import health_row as health_row
from ._driving import identify_driving as identify_driving
from ._driving import mad_factor as mad_factor
from ._layout import LayoutError as LayoutError
from ._layout import Session as Session
from ._layout import discover as discover
from ._ray import ray_runner as ray_runner
from ._simulate import FleetTruth as FleetTruth
from ._simulate import simulate_fleet as simulate_fleet
from ._table import COLUMNS as COLUMNS
from ._table import HEALTH_NAME as HEALTH_NAME
from ._table import TABLE_NAME as TABLE_NAME
from ._table import FleetError as FleetError
from ._table import read_table as read_table
from ._table import write_table as write_table
