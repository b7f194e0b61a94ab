"""The terrain simulator: profiles, wheels, drivetrain, and the whisker's response to them."""

from .. import _jax_setup as _jax_setup
from ._terrain import AMPLIFIER as AMPLIFIER
from ._terrain import LATERAL_MODEL as LATERAL_MODEL
from ._terrain import MIN_DATASET_DURATION_S as MIN_DATASET_DURATION_S
from ._terrain import PLANE_COLUMNS as PLANE_COLUMNS
from ._terrain import SPEEDS_MPS as SPEEDS_MPS
from ._terrain import TERRAIN_FAMILIES as TERRAIN_FAMILIES
from ._terrain import TERRAINS as TERRAINS
from ._terrain import RunSpec as RunSpec
from ._terrain import SensorPlanes as SensorPlanes
from ._terrain import TerrainFamily as TerrainFamily
from ._terrain import amplified_hall as amplified_hall
from ._terrain import base_acceleration as base_acceleration
from ._terrain import base_acceleration_planes as base_acceleration_planes
from ._terrain import dataset_paths as dataset_paths
from ._terrain import hall_voltage as hall_voltage
from ._terrain import iso8608_roughness as iso8608_roughness
from ._terrain import iter_runs as iter_runs
from ._terrain import run_base_motion as run_base_motion
from ._terrain import speed_tag as speed_tag
from ._terrain import synthesize_dataset as synthesize_dataset
from ._terrain import synthesize_runs as synthesize_runs
from ._terrain import wheel_filter as wheel_filter
