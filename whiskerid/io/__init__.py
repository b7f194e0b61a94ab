"""Recordings on disk (CSV, NPZ, NPY), provenance, and the ADS1115's datasheet facts.

No JAX here: the Raspberry Pi side reads and writes through this package. It also holds
the NumPy-only parts of classification that the online stream runs without JAX: the window
checks (``_health``, ``_health_modes``; re-exported by :mod:`whiskerid.classify`) and the
fusion of consecutive windows' probabilities (``_context``).
"""

from ._added_mass import ADDED_MASS_KEY as ADDED_MASS_KEY
from ._added_mass import ADDED_MASS_STD_KEY as ADDED_MASS_STD_KEY
from ._added_mass import mass_from_meta as mass_from_meta
from ._added_mass import mass_text as mass_text
from ._added_mass import parse_mass as parse_mass
from ._ads1115_spec import CODE_MAX as CODE_MAX
from ._ads1115_spec import CODE_MIN as CODE_MIN
from ._atomic import WriteError as WriteError
from ._atomic import atomic_folder as atomic_folder
from ._atomic import atomic_path as atomic_path
from ._atomic import atomic_write as atomic_write
from ._atomic import clear_expected as clear_expected
from ._atomic import expect_new as expect_new
from ._atomic import fsync_folder as fsync_folder
from ._rate import RATE_METADATA_TOLERANCE as RATE_METADATA_TOLERANCE
from ._rate import recording_rate as recording_rate
from ._rate import timestamp_rate as timestamp_rate
from ._recording import RECORDER_KEY as RECORDER_KEY
from ._recording import Recording as Recording
from ._recording import RecordingError as RecordingError
from ._recording import TornRecordingWarning as TornRecordingWarning
from ._recording import check_out_path as check_out_path
from ._recording import check_samples as check_samples
from ._recording import read_csv_table as read_csv_table
from ._recording import read_recording as read_recording
from ._recording import same_file as same_file
from ._recording import sha256_of as sha256_of
from ._recording import write_csv as write_csv
