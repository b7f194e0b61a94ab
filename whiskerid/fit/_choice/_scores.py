"""Score statistics shared by the amplitude test and the model-error term: the test's lags,
the HAC (Newey–West) variance of per-sample scores, the score statistic of projected columns
and its white-noise form over column subsets."""

import numpy as np

from .._checks import bartlett_meat, lag_below
from .._numerics import chi2_sf, subset_mask

#: Columns of each test.
NONLINEAR = ("cubic", "quadratic", "coulomb")


def test_lag(r: np.ndarray) -> int:
    """Lag after which the residuals' autocorrelation stays below what white noise reaches.

    The fit's :func:`._checks.hac_lag` stops at 0.1; the autocorrelation of ``n`` white
    samples has a 1σ of ``1/√n`` at each lag and reaches ``√(2 ln n / n)`` somewhere among
    its ``n`` lags (0.33 for the 78 samples of a strongly damped decay at 200 Hz, where 0.1
    took the lag to ``n/4``). A Bartlett sum to such a lag is a variance estimate with a few
    degrees of freedom, and a score statistic divided by it has tails far beyond its χ²: a
    linear pluck (73 Hz, ζ 0.073, white residuals, lag-1 0.02) was rejected at p = 2e-5 with
    19 lags and gave p = 0.27 with none. So the threshold here is the larger of the two;
    residuals a misfit leaves correlated (a nonlinear whisker's) keep their lags."""
    return test_lags(r[None, :])[0]


def test_lags(rs: np.ndarray) -> list[int]:
    """:func:`test_lag` of each row of ``rs`` (``m × n``), their autocorrelations by one FFT
    call (:func:`._checks.lag_below` of the rows; the model-error term asks it of six
    residual vectors of each recording)."""
    n = rs.shape[1]
    lags = lag_below(rs, max(0.1, float(np.sqrt(2.0 * np.log(max(n, 2)) / n))))
    # no lag at all where even lag 1 looks white (the fit's rule keeps one)
    return [0 if lag <= 1 else int(min(lag, n // 4)) for lag in lags]


def lags_per_recording(rows: np.ndarray, sizes) -> list[list[int]]:
    """:func:`test_lags` of each recording's part of each row of ``rows`` (``m × n``), per
    recording: one FFT call a recording for every row."""
    out, start = [], 0
    for n in sizes:
        out.append(test_lags(rows[:, start : start + n]))
        start += n
    return out


def score_meat(blocks, lags=None) -> tuple[np.ndarray, int]:
    """``Σ`` over recordings of the Bartlett (Newey–West) sum of the per-sample scores
    ``Z_t r_t`` to :func:`test_lag` (none where the residuals look white), and the largest
    lag; blocks are ``(Z, r, _)``; ``lags``: their :func:`test_lag`, when already known."""
    meat, most = 0.0, 0
    for k, (z, r, _) in enumerate(blocks):
        lag = test_lag(r) if lags is None else lags[k]
        most = max(most, lag)
        meat = meat + bartlett_meat(z * r[:, None], lag)
    return meat, most


def score_statistic(zp, r, r_alt, sizes, lags=None):
    """The score statistic of the columns ``zp`` (already projected off ``J``: see
    :class:`._projector.LinearPart`) at residuals ``r``, its HAC variance from ``r_alt``
    (``lags``: :func:`test_lag` of each recording's ``r_alt``, when already known)."""
    if lags is not None and not any(lags):  # white residuals (the usual case): no lag sum
        stat, dof = white_statistics(zp, r, r_alt[None, :], [range(zp.shape[1])], dof=True)
        k = int(dof[0])
        return {"statistic": float(stat[0]), "dof": k,
                "p_value": chi2_sf(float(stat[0]), k) if k else 1.0, "hac_lag": 0}  # fmt: skip
    scale = np.linalg.norm(zp, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    zp = zp / scale
    blocks, start = [], 0
    for n in sizes:
        blocks.append((zp[start : start + n], r_alt[start : start + n], True))
        start += n
    meat, lag = score_meat(blocks, lags)
    white = float(np.mean(r_alt**2)) * (zp.T @ zp)
    # never more certain than white noise would make it
    v = np.maximum(np.diag(meat), np.diag(white))
    sd = np.sqrt(np.maximum(np.diag(meat), 1e-300))
    corr = meat / np.outer(sd, sd)
    v = corr * np.sqrt(np.outer(v, v))
    s = zp.T @ r
    # a column the fit's own Jacobian spans (zero once projected: e.g. an envelope that is
    # zero where a fit to noise put ζ at its bound) carries no information: left out, not a
    # singular variance
    keep = np.diag(v) > 0
    if not keep.all():
        v, s = v[np.ix_(keep, keep)], s[keep]
    k = int(keep.sum())
    stat = float(s @ np.linalg.solve(v, s)) if k else 0.0
    p_value = chi2_sf(stat, k) if k else 1.0
    return {"statistic": stat, "dof": k, "p_value": p_value, "hac_lag": lag}


def white_statistics(zp, r, r_alts, subsets, *, dof: bool = False):
    """:func:`._amplitude.score_statistic`'s statistic of each subset ``subsets[k]`` of the columns
    of ``zp`` at ``r``, its variance from ``r_alts[k]``, for residuals that need no lag: all
    at once, as batched ``k × k`` products and solves (one ``score_statistic`` a subset was most of
    the model-error term's time).

    The same statistic: each column scaled to unit norm (a subset's columns keep their own
    norms), ``meat = Σ_t r_t² z_t z_tᵀ`` (Bartlett's sum with no lag; over all the
    recordings' rows at once, which is the sum of their blocks; one product of the columns
    weighted by the squared residuals with the columns for every subset), the variance never
    below white noise's ``mean(r²) ZᵀZ`` on its diagonal, and ``T = sᵀV⁻¹s`` with
    ``s = Zᵀr`` over the subset's columns whose variance is positive. The columns outside a
    subset, or left out, are an identity block of ``V`` with a zero score, which adds nothing
    to ``T``. With ``dof``, also the number of columns each statistic kept.
    """
    zt = np.ascontiguousarray(zp.T)  # columns as rows: the products below run along them
    k = zt.shape[0]
    scale = np.sqrt(np.einsum("ij,ij->i", zt, zt))
    zt /= np.where(scale > 0, scale, 1.0)[:, None]
    r2 = r_alts**2
    # one k × n product a subset (the k² pairwise products of every sample at once would hold
    # k² × n numbers: 180 MB for six columns of a 640 000-sample recording)
    meat = np.stack([(zt * w) @ zt.T for w in r2])
    white = np.mean(r2, axis=1)[:, None, None] * (zt @ zt.T)
    dm = np.diagonal(meat, axis1=1, axis2=2)
    v = np.maximum(dm, np.diagonal(white, axis1=1, axis2=2))
    sd = np.sqrt(np.maximum(dm, 1e-300))
    v = meat / (sd[:, :, None] * sd[:, None, :]) * np.sqrt(v[:, :, None] * v[:, None, :])
    keep = subset_mask(subsets, k) & (np.diagonal(v, axis1=1, axis2=2) > 0)
    v = np.where(keep[:, :, None] & keep[:, None, :], v, np.eye(k))
    s = np.where(keep, zt @ r, 0.0)
    stat = np.einsum("mi,mi->m", s, np.linalg.solve(v, s[:, :, None])[:, :, 0])
    return (stat, keep.sum(axis=1)) if dof else stat
