"""The posterior beside the calibration it starts from: its warnings, and the widths compared.

The calibration's 1σ is a HAC (heteroscedasticity- and autocorrelation-consistent) covariance
with its model-error terms: it widens where the residuals are correlated or the model is
wrong. The posterior's likelihood takes the residuals as white noise, so on such a recording
its intervals come out narrower than the data allow. Nothing is changed here; the user is
told: every warning the calibration recorded (``[fit] warnings``, and its status when not
``ok``) is repeated, and each reported quantity's 68 % half-width ``(q84 − q16)/2`` is divided
by the calibration's 1σ; a ratio below ``1/NARROW`` is a warning.
"""

import math

#: A posterior half-width narrower than calibrate's 1σ by more than this factor is reported.
NARROW = 1.5


def calibration_agreement(record, params: dict[str, dict]) -> dict:
    """What the calibration in ``record`` said, and the width ratios of ``params`` to it.

    Args:
        record: The record the posterior started from (its ``[fit]`` table, if any).
        params: The posterior's reported quantities (``q16``, ``q84`` each).

    Returns:
        ``status`` (the calibration's, or None without a ``[fit]`` table),
        ``calibration_warnings`` (its warnings, and its status when not ``ok``),
        ``width_ratio`` (quantity → posterior 68 % half-width / calibrate's 1σ, for the
        quantities both report with a finite, positive width) and ``warnings`` (those
        repeated, then one per quantity narrower by more than :data:`NARROW`).
    """
    fit = record.extra.get("fit") or {}
    status = fit.get("status")
    repeated = [f"calibration: {w}" for w in fit.get("warnings") or []]
    if status is not None and status != "ok":
        repeated.insert(0, f"calibration: status {status}")
    ratios = {}
    for name, cal in (fit.get("params") or {}).items():
        q = params.get(name)
        std = float(cal.get("std", float("nan"))) if isinstance(cal, dict) else float("nan")
        if q is None or not (math.isfinite(std) and std > 0):
            continue
        half = 0.5 * (q["q84"] - q["q16"])
        if math.isfinite(half) and half > 0:
            ratios[name] = half / std
    narrow = [
        f"{name}: the posterior's 68 % half-width is {r:.3g} x calibrate's 1-sigma (narrower "
        f"by more than {NARROW:g}x): its likelihood takes the residuals as white noise, "
        "calibrate's 1-sigma (HAC, model error) does not; trust the wider one"
        for name, r in ratios.items()
        if r < 1.0 / NARROW
    ]
    return {
        "status": status,
        "calibration_warnings": repeated,
        "width_ratio": ratios,
        "warnings": repeated + narrow,
    }
