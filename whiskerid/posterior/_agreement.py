"""The posterior beside the calibration it starts from: its warnings, and the widths compared.

The calibration's 1σ is built in three layers: the white-noise 1σ ``s²(JᵀJ)⁻¹``
(``std_white``), a sandwich (heteroskedasticity- and, where the residuals are correlated,
autocorrelation-consistent) that widens it where the residuals' spread changes along the
recording or they are correlated (``std_without_model_error``), and a model-error term where
the data prefer a model the fit does not have (``std``, the one reported). The posterior's
likelihood takes the residuals as white noise of constant σ under the calibration's model, so
it matches the first layer only, and on a recording where the others matter its intervals come
out narrower than the data allow. Nothing is changed here; the user is told: every warning the
calibration recorded (``[fit] warnings``, and its status when not ``ok``) is repeated, and each
reported quantity's 68 % half-width ``(q84 − q16)/2`` is divided by the calibration's 1σ
(``width_ratio``; a ratio below ``1/NARROW`` is a warning), and, where the calibration computed
them, by its white-noise 1σ (``width_ratio_white``) and its 1σ without model error
(``width_ratio_sandwich``), which say which layer the difference comes from.
"""

import math

#: A posterior half-width narrower than calibrate's 1σ by more than this factor is reported.
NARROW = 1.5


def calibration_agreement(
    record, params: dict[str, dict], calibration: dict[str, dict] | None = None
) -> dict:
    """What the calibration in ``record`` said, and the width ratios of ``params`` to it.

    Args:
        record: The record the posterior started from (its ``[fit]`` table, if any).
        params: The posterior's reported quantities (``q16``, ``q84`` each).
        calibration: The calibration the posterior ran (its reported quantities, with
            ``std`` and, where computed, ``std_white`` and ``std_without_model_error``):
            the 1σ where the record has none, and the layers of it.

    Returns:
        ``status`` (the calibration's, or None without a ``[fit]`` table),
        ``calibration_warnings`` (its warnings, and its status when not ``ok``),
        ``width_ratio`` (quantity → posterior 68 % half-width / calibrate's 1σ, for the
        quantities both report with a finite, positive width), ``width_ratio_white`` and
        ``width_ratio_sandwich`` (the same against the layers of the 1σ, where known) and
        ``warnings`` (those repeated, then one naming the quantities narrower by more than
        :data:`NARROW`, if any).
    """
    fit = record.extra.get("fit") or {}
    status = fit.get("status")
    repeated = [f"calibration: {w}" for w in fit.get("warnings") or []]
    if status is not None and status != "ok":
        repeated.insert(0, f"calibration: status {status}")
    stated = fit.get("params") or calibration or {}
    ratios = _ratios(params, stated, "std")
    layers = calibration or {}
    narrow = [f"{name} {r:.3g}x" for name, r in ratios.items() if r < 1.0 / NARROW]
    if narrow:
        narrow = [
            f"the posterior's 68 % half-widths are narrower than calibrate's 1-sigma by more "
            f"than {NARROW:g}x ({', '.join(narrow)}): its likelihood is white noise of one "
            "sigma per recording under the calibration's model, calibrate's 1-sigma also "
            "carries the residuals' changing spread or correlation and any model error; trust "
            "the wider one"
        ]
    sandwich = _ratios(params, layers, "std_without_model_error")
    spread = [name for name, r in sandwich.items() if r < 1.0 / NARROW]
    if narrow and spread:
        narrow[0] += (
            f"; narrower than calibrate's 1-sigma without model error too ({', '.join(spread)}): "
            "the residuals' spread changes along the recording, as when a free decay is "
            "followed by the whisker at rest on one ADC code; sample the decay only "
            "(--t-end on the command line)"
        )
    return {
        "status": status,
        "calibration_warnings": repeated,
        "width_ratio": ratios,
        "width_ratio_white": _ratios(params, layers, "std_white"),
        "width_ratio_sandwich": sandwich,
        "warnings": repeated + narrow,
    }


def _ratios(params: dict, stds: dict, key: str) -> dict[str, float]:
    """Posterior 68 % half-width / ``stds[name][key]`` where both are finite and positive."""
    out = {}
    for name, cal in stds.items():
        q = params.get(name)
        std = float(cal.get(key, float("nan"))) if isinstance(cal, dict) else float("nan")
        if q is None or not (math.isfinite(std) and std > 0):
            continue
        half = 0.5 * (q["q84"] - q["q16"])
        if math.isfinite(half) and half > 0:
            out[name] = half / std
    return out
