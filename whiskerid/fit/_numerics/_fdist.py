"""The F distribution's survival function, without importing ``scipy.stats``.

The noise-floor test of :mod:`._noise_floor` needs ``P(F_{d1,d2} > x)`` once per recording.
``scipy.stats`` takes longer to import than a warm calibration takes to run, so the survival
function is computed here from the regularised incomplete beta function (Abramowitz & Stegun
26.6.2):

    P(F_{d1,d2} > x) = I_{d2/(d2 + d1 x)}(d2/2, d1/2),

with ``I_z(a, b)`` by its continued fraction (A&S 26.5.8, evaluated by the modified Lentz
method), using the symmetry ``I_z(a, b) = 1 − I_{1−z}(b, a)`` where the fraction converges
slowly (``z > (a + 1)/(a + b + 2)``). Degrees of freedom may be any positive reals.
"""

import math

_EPS = 1e-15
_TINY = 1e-300
_MAX_TERMS = 10_000


def _beta_fraction(z: float, a: float, b: float) -> float:
    """The continued fraction of ``I_z(a, b)`` (A&S 26.5.8), by the modified Lentz method."""
    c, d = 1.0, 1.0 - (a + b) * z / (a + 1.0)
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, _MAX_TERMS):
        for num in (
            m * (b - m) * z / ((a + 2 * m - 1) * (a + 2 * m)),
            -(a + m) * (a + b + m) * z / ((a + 2 * m) * (a + 2 * m + 1)),
        ):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + num / c
            c = c if abs(c) > _TINY else _TINY
            h *= d * c
        if abs(d * c - 1.0) < _EPS:
            break
    return h


def betainc(a: float, b: float, z: float) -> float:
    """The regularised incomplete beta function ``I_z(a, b)`` for ``a, b > 0`` and ``0 ≤ z ≤ 1``."""
    if not (a > 0 and b > 0):
        raise ValueError(f"betainc needs a > 0 and b > 0, not a={a!r}, b={b!r}")
    if math.isnan(z):
        return math.nan
    if z <= 0.0:
        return 0.0
    if z >= 1.0:
        return 1.0
    log_front = (
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(z) + b * math.log1p(-z)
    )
    if z < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_fraction(z, a, b) / a
    return 1.0 - math.exp(log_front) * _beta_fraction(1.0 - z, b, a) / b


def f_sf(x: float, d1: float, d2: float) -> float:
    """``P(F_{d1,d2} > x)``: the F distribution's survival function (1 for ``x ≤ 0``)."""
    if not (d1 > 0 and d2 > 0):
        raise ValueError(f"degrees of freedom must be positive, not d1={d1!r}, d2={d2!r}")
    x = float(x)
    if math.isnan(x):
        return math.nan
    if x <= 0.0:
        return 1.0
    if math.isinf(x):
        return 0.0
    return min(max(betainc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * x)), 0.0), 1.0)
