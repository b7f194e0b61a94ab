"""An absurd robot speed (a unit error: mm/s, km/h) is refused, never used to label."""

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.classify._dataset import MAX_SPEED_MPS, check_speed, recording_speed


@pytest.mark.parametrize("v", [50.0, 1e6, 0.0, -0.1, np.nan, np.inf])
def test_absurd_speeds_are_refused_in_words(v):
    with pytest.raises(ValueError, match="metres per second"):
        check_speed(v)
    rec = wi.Recording(t=np.arange(10) / 200, columns={"adc": np.zeros(10)},
                       meta={"speed_mps": str(v)})  # fmt: skip
    with pytest.raises(wi.RecordingError, match="metres per second"):
        recording_speed(rec)


def test_plausible_speeds_pass():
    check_speed(np.array([0.05, 0.3, MAX_SPEED_MPS]))
    rec = wi.Recording(t=np.arange(10) / 200, columns={"adc": np.zeros(10)},
                       meta={"speed_mps": "0.2"})  # fmt: skip
    assert recording_speed(rec) == 0.2
