"""BorealTC loader (skipped when ../shared/data/borealtc is absent)."""

from pathlib import Path

import numpy as np
import pytest

import whiskerid as wi

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "borealtc"


@pytest.mark.skipif(not DATA.is_dir(), reason="BorealTC data not present")
def test_loader_gives_labelled_windows_of_vertical_acceleration():
    ws = wi.load_borealtc(DATA, max_runs=1)
    assert ws.label_names == ("ASPHALT", "FLOORING", "ICE", "SANDY_LOAM", "SNOW")
    assert ws.windows.shape[1] == 100 and ws.rate_hz == 100.0
    assert set(ws.labels) == set(range(5)) and len(ws.sources) == 5
    assert 8.0 < float(np.median(ws.windows)) < 11.0  # az includes gravity (m/s²)


@pytest.mark.skipif(not DATA.is_dir(), reason="BorealTC data not present")
def test_loader_all_six_imu_axes_with_overlapping_windows():
    one = wi.load_borealtc(DATA, max_runs=1)
    ws = wi.load_borealtc(DATA, max_runs=1, channel="all", window_s=2.0, hop_s=0.5)
    assert ws.windows.shape[1:] == (6, 200) and ws.recording.max() == 4
    # Hop 0.5 s with 2 s windows: about twice as many windows as 1 s without overlap.
    assert 1.7 * len(one) < len(ws) < 2.1 * len(one)
    az = ws.windows[:, 5]
    assert 8.0 < float(np.median(az)) < 11.0  # the sixth axis is the vertical acceleration
    assert float(np.abs(np.median(ws.windows[:, 2]))) < 1.0  # yaw rate (rad/s), not gravity
    first = one.windows[one.recording == 0]
    np.testing.assert_allclose(az[0, :100], first[0])  # same resampling as the single channel
