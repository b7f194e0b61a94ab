"""Which nonlinear terms a recording asks for: backward elimination by an information criterion.

Each extra term of :class:`whiskerid.model.NonlinearMode` (``kappa``, ``cubic``,
``quadratic``, ``coulomb``) bends the backbone ``f(a)`` or ``ζ(a)`` in its own way, but over
the one or two decades of amplitude a decay spans, several of them can trade against each
other; fitting all of them then widens every 1σ and can let one term's sign swing to cancel
another's. So the terms are chosen by the data: all candidates are fitted, and the weakest
term is dropped while the Bayesian information criterion says the data do not need it.

For one parameter the BIC's change is ``Δ(−2 log L) − ln n``; at the optimum, the first
term equals the Wald statistic ``z² = (θ̂/σ)²``. Here ``σ`` is the fit's own HAC 1σ, so
residuals that stay correlated (a real beam's) do not make a term look better determined
than it is: a term stays if ``z² ≥ ln n`` (``n`` the samples fitted, ``|z| ≳ 3`` for a few
thousand). The elimination stops at the first term that stays; if even the last one does
not, the linear model is enough, and the returned fit says so in its diagnostics.
"""

import numpy as np

from .._result import Calibration
from ._fit import NonlinearCalibration, fit_nonlinear, rss_of_curves
from ._logpoly import KNOTS
from ._problem import ALL_TERMS, COEFFICIENT_OF, NL_TERMS


def term_z(cal) -> dict[str, float]:
    """``z = value/1σ`` of each fitted nonlinear coefficient of ``cal``."""
    out = {}
    for term in cal.problem.terms:
        p = cal.params[COEFFICIENT_OF[term]]
        out[term] = float(p["value"] / p["std"]) if p["std"] > 0 else 0.0
    return out


def calibrate_nonlinear_selected(linear, observations, *, candidates=ALL_TERMS, **kwargs):
    """The nonlinear fit with the terms the data ask for (backward elimination by BIC).

    Args:
        linear: The converged linear :class:`Calibration` to start from.
        observations: The recordings (free decays).
        candidates: Terms to choose from (a subset of :data:`ALL_TERMS`).
        **kwargs: Passed to :func:`calibrate_nonlinear` (``solver``, ``max_steps``).

    Returns:
        The :class:`NonlinearCalibration` of the chosen terms; its
        ``diagnostics["term_selection"]`` lists each step (terms, their ``z``, the BIC
        threshold ``ln n``, the term dropped) and ``"needed"``: False when not even one
        term passed (the linear fit is then the better description).
    """
    obs = list(observations)
    terms = tuple(t for t in ALL_TERMS if t in candidates)
    threshold = float(np.log(sum(o.t.size for o in obs)))
    steps = []
    while True:
        cal = fit_nonlinear(linear, obs, terms=terms, **kwargs)
        z = term_z(cal)
        weakest = min(terms, key=lambda t: abs(z[t]))
        keep = z[weakest] ** 2 >= threshold or not cal.ok
        steps.append({"terms": list(terms), "z": z, "status": cal.status,
                      "dropped": None if keep or len(terms) == 1 else weakest})  # fmt: skip
        if keep or len(terms) == 1:
            break
        terms = tuple(t for t in terms if t != weakest)
    cal.diagnostics["term_selection"] = {
        "criterion": "BIC (Wald form with the HAC 1-sigma): keep a term if z^2 >= ln n",
        "ln_n": threshold,
        "steps": steps,
        "chosen": list(terms),
        "needed": bool(keep),
    }
    return cal


def information_scale(cal) -> tuple[float, float, int]:
    """``(s², r, n)`` of a fit for the criterion: unweighted residual variance (normalised
    data), median HAC-over-white variance ratio of its reported values, samples."""
    rss = rss_of_curves(cal)
    n = sum(int(r.t.size) for r in cal.problem.base.recordings)
    p = int(cal.problem.flatten(cal.optimum).size)
    ratios = [(v["std"] / v["std_white"]) ** 2 for v in cal.params.values()
              if v.get("std_white", 0) > 0 and np.isfinite(v["std"])]  # fmt: skip
    return rss / max(n - p, 1), max(float(np.median(ratios)) if ratios else 1.0, 1.0), n


def criterion(cal, scale) -> float:
    """``RSS/(s²r) + p ln n`` of ``cal`` on the common ``scale = (s², r, n)``."""
    s2, r, n = scale
    p = int(cal.problem.flatten(cal.optimum).size)
    return rss_of_curves(cal) / (s2 * r) + p * np.log(n)


def calibrate_logpoly_backbone(linear, observations, *, knots=KNOTS, **kwargs):
    """The log-polynomial backbone fit with the number of knots chosen by the criterion.

    Args:
        linear: The converged linear :class:`Calibration` to start from.
        observations: The recordings (free decays).
        knots: Knot counts to try (each ≥ 2).
        **kwargs: Passed to :func:`whiskerid.fit.calibrate_nonlinear` (``solver``,
            ``max_steps``, ``free_modes``).

    Returns:
        The chosen fit; ``diagnostics["knot_selection"]`` holds each count's criterion
        (relative to the best) on the scale of the fit with the most knots.
    """
    obs = list(observations)
    fits = {k: fit_nonlinear(linear, obs, knots=k, **kwargs) for k in sorted(knots)}
    scale = information_scale(fits[max(fits)])
    crit = {k: criterion(c, scale) for k, c in fits.items() if c.ok}
    best = min(crit, key=crit.get) if crit else max(fits)
    out = fits[best]
    out.diagnostics["knot_selection"] = {
        "criterion": "BIC, RSS/(s2 r) + p ln n on the most flexible fit's s2 and HAC ratio r",
        "delta": {str(k): float(v - crit[best]) for k, v in crit.items()},
        "chosen": int(best),
        "scale": {"s2": scale[0], "hac_ratio": scale[1], "n": scale[2]},
    }
    return out


def calibrate_nonlinear(
    linear: Calibration,
    observations,
    *,
    terms: tuple[str, ...] = NL_TERMS,
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    free_modes: bool = False,
    knots: int = 0,
) -> NonlinearCalibration:
    """Fit the nonlinear model, starting from a converged linear calibration.

    Args:
        linear: The linear :class:`Calibration` of the same record and recordings.
        observations: The recordings (free decays only).
        terms: Nonlinear terms to fit (a subset of :data:`ALL_TERMS`), or ``"auto"``: every
            term, then the ones the data do not need dropped by an information criterion
            (:func:`whiskerid.fit.calibrate_nonlinear_selected`).
        solver: As :func:`whiskerid.fit.calibrate`.
        max_steps: Solver step limit.
        free_modes: Modes 2… (when the linear fit has them) with their own frequency and
            damping, started at the data's line (:mod:`._nl_free_modes`), not the beam's.
        knots: 0 for the parametric backbone (``terms``); ``K ≥ 2`` for ``f(a)``, ``ζ(a)``
            as polynomials in ``ln a`` through ``K`` knots (:mod:`._nl_logpoly`; ``terms``
            ignored; ``f1_hz`` and ``zeta`` are then the values at the smallest informed
            amplitude ``diagnostics["a_lo_m"]``, not ``a → 0``). A study tool: on SciPy
            plucks its ``f(a)`` is right within its 1σ, its ``ζ(a)`` under velocity-squared
            damping is not (pulls to 6).

    Returns:
        A :class:`NonlinearCalibration`; never raises on a failed solve (see ``status``).
    """
    if terms == "auto" or terms == ("auto",):
        return calibrate_nonlinear_selected(linear, observations, solver=solver,
                                            max_steps=max_steps, free_modes=free_modes)  # fmt: skip
    return fit_nonlinear(linear, observations, terms=terms, solver=solver, max_steps=max_steps,
                         free_modes=free_modes, knots=knots)  # fmt: skip
