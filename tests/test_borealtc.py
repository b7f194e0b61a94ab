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
