"""The whisker as a physical model: modes, the equivalent beam, the paper's Eq. 1, the exact
modal response, the Hall sensor and ADS1115 observation, whisker records and simulation.
"""

from .. import _jax_setup as _jax_setup
from ._modes import PAPER_D as PAPER_D
from ._modes import cantilever_roots as cantilever_roots
from ._modes import mode_shape as mode_shape
from ._modes import participation_factors as participation_factors
from ._nonlinear import NonlinearMode as NonlinearMode
from ._nonlinear import nonlinear_coefficients as nonlinear_coefficients
from ._nonlinear import nonlinear_pluck_state as nonlinear_pluck_state
from ._nonlinear import nonlinear_response as nonlinear_response
from ._nonlinear import slow_flow as slow_flow
from ._nonlinear import slow_flow_decay as slow_flow_decay
from ._paper import paper_eq1 as paper_eq1
from ._pluck import PLUCK_KINDS as PLUCK_KINDS
from ._pluck import PluckTruth as PluckTruth
from ._pluck import simulate_pluck as simulate_pluck
from ._record import RecordError as RecordError
from ._record import WhiskerRecord as WhiskerRecord
from ._record import load_record as load_record
from ._record import paper_record as paper_record
from ._response import ModalState as ModalState
from ._response import base_motion_response as base_motion_response
from ._response import free_decay as free_decay
from ._response import harmonic_from_rest as harmonic_from_rest
from ._response import harmonic_steady_state as harmonic_steady_state
from ._response import modal_params as modal_params
from ._response import observe as observe
from ._response import pluck as pluck
from ._response import project_initial_shape as project_initial_shape
from ._response import tap as tap
from ._sensor import ADS1115Model as ADS1115Model
from ._sensor import HallSensor as HallSensor
from ._simulate import BaseMotion as BaseMotion
from ._simulate import simulate as simulate
from ._whisker import CoilSpring as CoilSpring
from ._whisker import UniformBeam as UniformBeam
from ._whisker import Whisker as Whisker
from ._whisker import paper_coil as paper_coil
from ._whisker import paper_whisker as paper_whisker
from ._whisker import whisker_from_structure as whisker_from_structure
