"""A profile-likelihood interval for one parameter (lmfit's ``conf_interval`` habit).

The parameter is fixed on a grid around its free fit (:class:`whiskerid.fit.Parameters`),
the others refitted at each value; ``Δχ²(v) = Σ_i (RSS_i(v) − RSS_i(v̂))/σ_i²`` over the
recordings (σ_i² the free fit's residual variance of each), and the interval is where
``Δχ² = 1`` is crossed on either side (linear interpolation between grid values). Where the
model is nearly linear in the parameter it matches the 1σ of the covariance; where it is not,
it is asymmetric. The grid's fits share one compiled program (the fixed value is a traced
number). Correlated residuals are not accounted for (the sandwich 1σ does that).
"""

import numpy as np

from ._calibrate import calibrate
from ._data import CalibrationError
from ._linear import LIMITABLE, Parameters

#: Δχ² of a 1σ (68.3 %) interval for one parameter.
DELTA_CHI2 = 1.0


def _rss(cal) -> np.ndarray:
    return np.array([float(np.sum((y - m) ** 2)) for _, y, m in cal.curves])


def profile_interval(record, observations, name: str, *, points: int = 21, span: float = 4.0,
                     **options) -> dict:  # fmt: skip
    """The profile of ``name`` (``f1_hz`` or ``zeta``) and its Δχ² = 1 interval.

    Args:
        record: The whisker's record.
        observations: Its recordings (as :func:`whiskerid.calibrate`).
        name: The parameter to profile.
        points: Grid values (odd: the free value is one of them).
        span: Half-width of the grid in units of the free fit's 1σ.
        **options: Passed to :func:`whiskerid.calibrate` (linear model).

    Returns:
        ``{"name", "value", "std", "grid", "delta_chi2", "lower", "upper", "status"}``:
        the free fit's value and 1σ, Δχ² on the grid, the interval's ends (None where the
        grid does not reach Δχ² = 1 on that side) and the free fit's status.
    """
    if name not in LIMITABLE:
        raise CalibrationError(f"--profile {name!r}: give one of {', '.join(LIMITABLE)}")
    if points < 5:
        raise CalibrationError(f"--profile: {points} grid values are too few (5 or more)")
    free = calibrate(record, observations, **options)
    value, std = free.params[name]["value"], free.params[name]["std"]
    if not (free.ok and std is not None and np.isfinite(std) and std > 0):
        raise CalibrationError(
            f"--profile {name}: the free fit has no finite 1σ ({free.status}); fix the fit first"
        )
    rss0 = _rss(free)
    sigma2 = rss0 / np.array([len(y) for _, y, _ in free.curves])
    lo_ok, hi_ok = (1e-6, 0.949) if name == "zeta" else (1e-3, 1e5)
    grid = np.linspace(max(value - span * std, lo_ok), min(value + span * std, hi_ok), points)
    dchi2 = []
    for v in grid:
        cal = calibrate(record, observations, parameters=Parameters().fix(name, float(v)),
                        **options)  # fmt: skip
        dchi2.append(float(np.sum((_rss(cal) - rss0) / sigma2)))
    dchi2 = np.asarray(dchi2)
    return {
        "name": name,
        "value": value,
        "std": std,
        "grid": grid.tolist(),
        "delta_chi2": dchi2.tolist(),
        "lower": _crossing(grid, dchi2, value, -1),
        "upper": _crossing(grid, dchi2, value, +1),
        "status": free.status,
    }


def _crossing(grid, dchi2, value, side: int) -> float | None:
    """Where Δχ² first reaches :data:`DELTA_CHI2` going from ``value`` towards ``side``."""
    idx = np.flatnonzero(grid >= value) if side > 0 else np.flatnonzero(grid <= value)[::-1]
    prev_v, prev_d = value, 0.0
    for i in idx:
        v, d = grid[i], dchi2[i]
        if d >= DELTA_CHI2:
            if d == prev_d:
                return float(v)
            return float(prev_v + (DELTA_CHI2 - prev_d) * (v - prev_v) / (d - prev_d))
        prev_v, prev_d = v, max(d, 0.0)
    return None
