"""Raspberry Pi side of whiskerid: ADS1115 driver, emulator, fixed-rate sampler, recorder,
and the online stream loop.

The driver side is light on purpose (numpy and, on the Pi, smbus2; no JAX), so it starts fast
on a small board. The stream loop (``OnlineClassifier``, ``BackgroundClassifier``,
``run_stream``, ``open_recorder``, ...) is NumPy too, and runs a model in NumPy when its
features allow (``_numpy_classifier``), else the JAX one; the terrain simulator
(``terrain_source``, ``terrain_signal``) needs JAX. These names load on first use, so
``import whiskerid.hw`` stays light.
See ``hw/README.md`` for wiring and setup.
"""

from typing import TYPE_CHECKING

from whiskerid.io import TornRecordingWarning as TornRecordingWarning

from ._ads1115 import ADS1115 as ADS1115
from ._ads1115 import DEFAULT_CONFIG as DEFAULT_CONFIG
from ._ads1115 import MUX_CODES as MUX_CODES
from ._ads1115 import POWER_ON_CONFIG as POWER_ON_CONFIG
from ._ads1115 import Config as Config
from ._ads1115 import ConversionTimeout as ConversionTimeout
from ._ads1115 import DriverStats as DriverStats
from ._ads1115 import I2CError as I2CError
from ._ads1115 import code_to_volts as code_to_volts
from ._ads1115 import decode_config as decode_config
from ._ads1115 import decode_conversion as decode_conversion
from ._ads1115 import encode_config as encode_config
from ._ads1115 import open_bus as open_bus
from ._ads1115 import volts_to_code as volts_to_code
from ._emulator import EmulatedADS1115 as EmulatedADS1115
from ._emulator import EmulatedBus as EmulatedBus
from ._emulator import FakeClock as FakeClock
from ._emulator import replay_sources as replay_sources
from ._emulator import source_from_recording as source_from_recording
from ._inputs import INPUT_MUX as INPUT_MUX
from ._inputs import Input as Input
from ._inputs import InputScan as InputScan
from ._inputs import Rounds as Rounds
from ._inputs import converter as converter
from ._inputs import data_rate_for as data_rate_for
from ._inputs import emulated_bus as emulated_bus
from ._inputs import max_scan_rate_hz as max_scan_rate_hz
from ._inputs import parse_inputs as parse_inputs
from ._live import MAX_SPEED_MPS as MAX_SPEED_MPS
from ._live import LabelSink as LabelSink
from ._live import SpeedFeed as SpeedFeed
from ._live import check_speed_mps as check_speed_mps
from ._live import odometry_speed as odometry_speed
from ._live import parse_endpoint as parse_endpoint
from ._realtime import PipeWriter as PipeWriter
from ._realtime import raise_priority as raise_priority
from ._realtime import raised_priority as raised_priority
from ._recorder import CSVRecording as CSVRecording
from ._recorder import Recorder as Recorder
from ._recorder import read_recording_csv as read_recording_csv
from ._recorder import unique_path as unique_path
from ._sampler import Gap as Gap
from ._sampler import Sample as Sample
from ._sampler import Sampler as Sampler
from ._sampler import SamplerStats as SamplerStats
from ._sampling_process import SamplerSpec as SamplerSpec
from ._sampling_process import SamplingError as SamplingError
from ._sampling_process import SamplingProcess as SamplingProcess
from ._sampling_process import open_sampler as open_sampler
from ._sampling_process import stream_config as stream_config

# The stream loop's public names, loaded on first use (PEP 562); the terrain simulator's
# bring in JAX.
_STREAM_NAMES = (
    "FAULT_LABELS",
    "BackgroundClassifier",
    "OnlineClassifier",
    "PendingWindow",
    "StreamSummary",
    "WindowLabel",
    "open_recorder",
    "run_stream",
    "terrain_signal",
    "terrain_source",
)


def __getattr__(name: str):
    if name in ("terrain_signal", "terrain_source"):  # the terrain simulator: JAX
        from . import _terrain_source

        return getattr(_terrain_source, name)
    if name in _STREAM_NAMES:  # NumPy only: the stream labels without JAX where it can
        from . import _stream, _stream_loop

        for module in (_stream, _stream_loop):
            if hasattr(module, name):
                return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_STREAM_NAMES))


if TYPE_CHECKING:
    from ._stream import FAULT_LABELS as FAULT_LABELS
    from ._stream import OnlineClassifier as OnlineClassifier
    from ._stream import PendingWindow as PendingWindow
    from ._stream import WindowLabel as WindowLabel
    from ._stream_loop import BackgroundClassifier as BackgroundClassifier
    from ._stream_loop import StreamSummary as StreamSummary
    from ._stream_loop import open_recorder as open_recorder
    from ._stream_loop import run_stream as run_stream
    from ._terrain_source import terrain_signal as terrain_signal
    from ._terrain_source import terrain_source as terrain_source
