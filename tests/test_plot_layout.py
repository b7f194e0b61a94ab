"""The calibration figure reads at its default size: residuals in a panel of their own under
the spectrum, the fit drawn over the data in a contrasting style, no title cut off by the
figure's edge and no tick labels overlapping (the nonlinear fit's backbone row included)."""

from types import SimpleNamespace

import numpy as np
import pytest

from whiskerid.plot import _calibrate

pytest.importorskip("matplotlib")


def _cal(nonlinear: bool):
    t = np.arange(2000) / 200.0
    model = 12000 * np.exp(-11.6 * t) * np.cos(2 * np.pi * 46 * t) + 13000
    y = model + np.random.default_rng(0).normal(0, 2.0, t.size)
    info = {"observable": "adc", "name": "a-rather-long-recording-name-pluck-001.csv",
            "selection": "decay from 0.2021 s to 9.9971 s (the release found at 0.2 s)",
            "t_start_s": 0.2, "rms_residual": 2.0, "lag1_autocorr": -0.02}  # fmt: skip
    params = {"f1_hz": {"value": 46.0, "std": 0.003}, "f2_hz": {"value": 288.2, "std": 0.02},
              "zeta": {"value": 0.04, "std": 1e-4}}  # fmt: skip
    backbone = None
    if nonlinear:
        a = np.geomspace(2e-6, 2e-3, 9)
        backbone = {"amplitude_m": a, "f_hz": 46 * (1 + 3e4 * 3 * a**2 / 8),
                    "f_std": np.full(9, 0.003), "zeta": 0.04 + 0 * a,
                    "zeta_std": np.full(9, 1e-4),
                    "windows": {"amplitude_m": a, "f_hz": 46 + 0 * a,
                                "zeta": 0.04 + 0 * a}}  # fmt: skip
    return SimpleNamespace(curves=[(t, y, model)], per_recording=[info], params=params,
                           record=SimpleNamespace(name="paper-whisker"), status="ok",
                           backbone=backbone)  # fmt: skip


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.mark.parametrize("nonlinear", [False, True])
def test_the_calibration_figure_has_no_clipped_title_or_overlapping_ticks(tmp_path, monkeypatch,
                                                                           nonlinear):  # fmt: skip
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figs = []
    monkeypatch.setattr(_calibrate, "_save", lambda fig, path: figs.append(fig) or path)
    _calibrate.plot_calibration(tmp_path / "fit.png", _cal(nonlinear))
    (fig,) = figs
    canvas = FigureCanvasAgg(fig)
    canvas.draw()  # the layout as saved
    r = canvas.get_renderer()
    edge = fig.bbox
    texts = [fig._suptitle] + [a.title for a in fig.axes] + [a.xaxis.label for a in fig.axes]
    for txt in texts:
        if txt is not None and txt.get_visible() and txt.get_text():
            bb = txt.get_window_extent(r)
            assert edge.x0 - 1 <= bb.x0 and bb.x1 <= edge.x1 + 1, txt.get_text()
            assert edge.y0 - 1 <= bb.y0 and bb.y1 <= edge.y1 + 1, txt.get_text()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            labels = [t for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            boxes = [t.get_window_extent(r) for t in labels]
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    assert not _overlap(boxes[i], boxes[j]), (labels[i], labels[j])
    # the residuals' spectrum is a panel of its own, the fit a dashed black line over the data
    res = [a for a in fig.axes if a.get_ylabel() == "residuals"]
    assert len(res) == 1
    top = [a for a in fig.axes if a.get_yscale() == "log" and a.get_legend()
           and "fit" in [t.get_text() for t in a.get_legend().get_texts()]]  # fmt: skip
    (fit,) = [ln for ln in top[0].get_lines() if ln.get_label() == "fit"]
    assert fit.get_linestyle() == "--" and fit.get_color() == "k"
    assert fit.get_zorder() > max(ln.get_zorder() for ln in top[0].get_lines() if ln is not fit)


def test_the_fleet_figure_flags_only_the_parameter_that_changed(tmp_path, monkeypatch):
    from whiskerid.plot import _fleet

    figs = []
    monkeypatch.setattr(_fleet, "_save", lambda fig, path: figs.append(fig) or path)
    sessions = [f"s{i}" for i in range(5)]
    values = {"f1_hz": np.full(5, 46.0), "zeta": np.array([0.04, 0.04, 0.04, 0.06, 0.06])}
    errors = {"f1_hz": np.full(5, 0.01), "zeta": np.full(5, 0.001)}
    _fleet.plot_fleet_history(tmp_path / "w.png", "whisker-001", sessions, values, errors, {},
                              baseline=2, centre={"f1_hz": 46.0, "zeta": 0.04},
                              band={"f1_hz": 0.05, "zeta": 0.005},
                              flagged={"f1_hz": [], "zeta": ["s3", "s4"]})  # fmt: skip
    (fig,) = figs
    legends = {ax.get_ylabel(): [t.get_text() for t in ax.get_legend().get_texts()]
               for ax in fig.axes}  # fmt: skip
    assert "flagged" not in legends["f1 (Hz)"] and "flagged" in legends["zeta"]
