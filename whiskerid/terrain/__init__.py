"""The terrain simulator: profiles, wheels, drivetrain, and the whisker's response to them."""

from .. import _jax_setup as _jax_setup
from ._terrain import SPEEDS_MPS as SPEEDS_MPS
from ._terrain import TERRAIN_FAMILIES as TERRAIN_FAMILIES
from ._terrain import TERRAINS as TERRAINS
from ._terrain import synthesize_dataset as synthesize_dataset
from ._terrain import synthesize_runs as synthesize_runs
from ._terrain import wheel_filter as wheel_filter
