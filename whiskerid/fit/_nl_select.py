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

from ._nonlinear import ALL_TERMS, COEFFICIENT_OF, calibrate_nonlinear


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
        cal = calibrate_nonlinear(linear, obs, terms=terms, **kwargs)
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
