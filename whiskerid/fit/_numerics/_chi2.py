"""The χ² distribution's survival function for whole degrees of freedom, in closed form.

The score tests of :mod:`._amplitude` need ``P(χ²_k > x)`` for a few whole ``k``. SciPy's
``scipy.stats.chi2.sf`` gives it, but importing ``scipy.stats`` takes longer than the rest of
a warm calibration; for whole ``k`` the survival function is a finite sum (the regularised
upper incomplete gamma function ``Q(k/2, x/2)`` of a whole or half-whole argument,
Abramowitz & Stegun 26.4.4–26.4.5):

* ``k`` even: ``Q = e^{−x/2} Σ_{i=0}^{k/2−1} (x/2)^i / i!``;
* ``k`` odd: ``Q = erfc(√(x/2)) + e^{−x/2} Σ_{i=1}^{(k−1)/2} (x/2)^{i−1/2} / Γ(i + 1/2)``.

Each term is evaluated as the exponential of its logarithm, so that nothing overflows for a
large statistic (a term is then ``e^{−x/2 + …}``, far below one, as it should be).
"""

import math


def chi2_sf(x: float, k: int) -> float:
    """``P(χ²_k > x)``: the χ² survival function with ``k`` (a whole number ≥ 1) degrees of
    freedom at ``x`` (1 for ``x ≤ 0``; NaN for NaN)."""
    if k < 1 or int(k) != k:
        raise ValueError(f"degrees of freedom must be a whole number >= 1, not {k!r}")
    k = int(k)
    x = float(x)
    if math.isnan(x):
        return math.nan
    if x <= 0.0:
        return 1.0
    if math.isinf(x):
        return 0.0
    h = 0.5 * x
    log_h = math.log(h)
    if k % 2 == 0:
        total = sum(math.exp(-h + i * log_h - math.lgamma(i + 1)) for i in range(k // 2))
    else:
        total = math.erfc(math.sqrt(h)) + sum(
            math.exp(-h + (i - 0.5) * log_h - math.lgamma(i + 0.5)) for i in range(1, (k + 1) // 2)
        )
    return min(total, 1.0)
