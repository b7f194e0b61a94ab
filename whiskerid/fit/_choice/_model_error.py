"""How far an amplitude-averaged linear fit may sit from the small-amplitude whisker: a
model-error term for its 1σ when the data prefer the nonlinear model by BIC.

A linear fit of a mildly nonlinear decay reports the frequency and damping averaged over the
decay's amplitudes, not their small-amplitude (``a → 0``) values ``f₀``, ``ζ₀``. When the
change is large the score tests of :mod:`._amplitude` reject the fit (``check``); below
their thresholds the data may still prefer the nonlinear model, and a long clean recording
then puts the averaged value many of its own 1σ from ``f₀`` (0.1 % stiffening at 860 Hz:
f₁ 7–10σ above ``f₀``, score tests at p ≈ 2e-3).

**Preference by BIC, from the score statistics.** For a subset ``S`` of the nonlinear
columns (cubic, velocity-squared, friction: :data:`._amplitude.NONLINEAR`), the score
statistic ``T_S`` (HAC) approximates ``Δ(−2 log L)`` of adding those terms, so the Bayesian
information criterion prefers the bigger model when ``T_S > |S| ln n`` (``n`` samples). The
subset with the largest ``T_S − |S| ln n`` is taken; if none is positive the linear model is
preferred and nothing changes.

**The bias and its 1σ.** One Gauss–Newton step along ``[J, Z_S]`` from the linear optimum
moves the linear parameters by ``δθ = B G⁻¹ Z_⊥ᵀ r`` (``B`` the regression of ``Z_S`` on
``J``, ``G = Z_⊥ᵀZ_⊥``): at ``Z_S``'s zero amplitude that is the ``a → 0`` whisker, so
``b = θ_linear − θ₀ = −δθ`` estimates the averaging bias of ``log κ`` (hence ``f₁``,
``b_f = −f₁ δlog κ / 2``) and of ζ. ``δθ`` is linear in the residuals, ``δθ = Xᵀr``, so
its 1σ ``σ_b`` is the HAC (Newey–West) variance of ``X_t r_t`` (residuals of the step,
never below white noise): a Hausman-type difference of the two models' estimates.

**The term.** ``b`` is itself uncertain by ``σ_b``, so the linear value's distance from the
``a → 0`` value is covered by ``b² + σ_b²`` (its expected square is ``b_true² + σ_b²``).
That is added to the variance of f₁ and ζ (and, through ``κ ∝ f₁²``, of κ, the higher
frequencies and the quantities derived from κ), the fit stays ``ok``, and a warning says
that the values are amplitude averages and points to ``--model nonlinear``. On linear
recordings the preference is rare (a few percent of recordings, by chance, or where the
release or the modes left out leave a misfit): their 1σ then grows, their values do not move.
"""

import numpy as np

from .._linear import ZETA_MAX, positions
from .._numerics import ColumnSubsets, LinearPart, pinv_columns
from ._scores import NONLINEAR, lags_per_recording, score_meat, score_statistic, white_statistics


def _subset_statistics(lin, r, zs, sizes, known=None, zp=None):
    """``{subset: (T_S, residuals after the Gauss–Newton step with S, their test lag per
    recording or None)}`` over every non-empty subset of the columns of ``zs`` (``known``:
    subsets already computed, ``(T_S, residuals)``; ``zp``: ``lin.project(zs)``, when
    already computed)."""
    out = {idx: (stat, r_alt, None) for idx, (stat, r_alt) in (known or {}).items()}
    # column by column, so each subset's Z⊥ is its columns of it; factored once for all
    subsets = ColumnSubsets(lin.project(zs) if zp is None else zp)
    todo = [idx for idx in (tuple(j for j in range(zs.shape[1]) if mask >> j & 1)
                            for mask in range(1, 2 ** zs.shape[1])) if idx not in out]  # fmt: skip
    if not todo:
        return out
    # as LinearPart.alternative: the residuals each subset's step leaves
    r_alts = lin.off(r)[None, :] - subsets.steps(todo, r) @ subsets.zp.T
    lags = lags_per_recording(r_alts, sizes)  # each recording's lags, all subsets at once
    white = white_statistics(subsets.zp, r, r_alts, todo)
    for k, idx in enumerate(todo):
        own = [lag[k] for lag in lags]
        if any(own):
            stat = score_statistic(subsets.zp[:, idx], r, r_alts[k], sizes, own)["statistic"]
        else:  # no lag in any recording (white residuals, the usual case): the batch's
            stat = float(white[k])
        out[idx] = (stat, r_alts[k], own)
    return out


def step_map(jac, z, idx, lin=None) -> np.ndarray:
    """``X`` with ``Xᵀr`` the least-squares step of parameters ``idx`` along ``[J, Z]``
    from residuals ``r`` (minimising ``|r + [J, Z]δ|²``), taken off ``J``'s columns.

    The step is ``δ_J = −J⁺(r + Zδ_Z)`` with ``δ_Z = −Z⊥⁺r`` (see
    :class:`._projector.LinearPart`). Off ``J``'s columns (``J⁺r = 0`` for any ``r``
    orthogonal to them), ``δ_J = B Z⊥⁺ r`` with ``B = J⁺Z``, the regression of ``Z`` on
    ``J``: ``X = (Z⊥⁺)ᵀ B[idx]ᵀ``. At the optimum of ``J`` alone (``Jᵀr = 0``) that step is
    the difference of the two models' estimates, and ``σ²XᵀX`` is its variance (Hausman).

    Args:
        jac: ``J`` (``n × p``).
        z: ``Z`` (``n × k``).
        idx: Positions among ``J``'s parameters.
        lin: ``LinearPart(jac)``, when already factored.
    """
    lin = LinearPart(jac) if lin is None else lin
    b = lin.solve(z)
    return pinv_columns(lin.project(z)).T @ b[idx].T


def model_error(cal, jac, r, cols, *, lin=None, known=None, zp=None) -> dict:
    """Whether BIC prefers the nonlinear model, and the linear fit's averaging bias.

    Args:
        cal: The linear calibration.
        jac, r: Its weighted Jacobian and residuals at the optimum.
        cols: The amplitude test's columns per recording (``_amplitude._columns``).
        lin: ``LinearPart(jac)``, when already factored.
        known: Subsets whose statistic and residuals are already known (the amplitude
            test's own: all three columns).
        zp: The nonlinear columns of ``cols`` projected off ``J`` (``lin.project``), when
            already computed (the amplitude test's own).

    Returns:
        ``preferred`` (bool), ``terms`` (the subset chosen), ``ln_n``, ``bic_gain``
        (``T_S − |S| ln n``), and for ``f1_hz`` and ``zeta`` the bias ``b`` (linear minus
        ``a → 0``) and its 1σ ``std``, in the reported units.
    """
    zs = np.concatenate([c["nonlinear"] for c in cols], axis=0)
    sizes = [c["n"] for c in cols]
    ln_n = float(np.log(sum(sizes)))
    lin = LinearPart(jac) if lin is None else lin
    stats = _subset_statistics(lin, r, zs, sizes, known, zp)
    best = max(stats, key=lambda s: stats[s][0] - len(s) * ln_n)
    gain = float(stats[best][0] - len(best) * ln_n)
    out = {"preferred": bool(gain > 0), "terms": [NONLINEAR[j] for j in best],
           "ln_n": ln_n, "bic_gain": gain}  # fmt: skip
    z = zs[:, list(best)]
    idx = [int(np.ravel(positions(cal.problem, k))[0]) for k in ("log_kappa", "zeta_u")]
    x = step_map(jac, z, idx, lin)
    delta = x.T @ r
    r_alt = stats[best][1]
    blocks, start = [], 0
    for m in sizes:
        blocks.append((x[start : start + m], r_alt[start : start + m], True))
        start += m
    meat, lag = score_meat(blocks, stats[best][2])  # the subset's own lags, when known
    var = np.maximum(np.diag(meat), float(np.mean(r_alt**2)) * np.sum(x**2, axis=0))
    f1 = float(cal.params["f1_hz"]["value"])
    zeta = float(cal.params["zeta"]["value"])
    dzeta_du = zeta * (1.0 - zeta / ZETA_MAX)  # ζ = ZETA_MAX·logistic(u)
    out["f1_hz"] = {"bias": -0.5 * f1 * float(delta[0]), "std": 0.5 * f1 * float(np.sqrt(var[0]))}
    out["zeta"] = {"bias": -dzeta_du * float(delta[1]), "std": dzeta_du * float(np.sqrt(var[1]))}
    out["hac_lag"] = int(lag)
    finite = all(np.isfinite(out[k][v]) for k in ("f1_hz", "zeta") for v in ("bias", "std"))
    out["preferred"] = bool(out["preferred"] and finite)
    return out


#: Reported quantities and their power of f₁ (κ ∝ f₁²; EI = κρa under the geometry pin,
#: ρa = EI/κ under the material pin); ζ's are handled apart.
_POWER_OF_F1 = {"EI": 2.0, "E": 2.0, "G_w": 2.0, "rho_a": -2.0, "C": -2.0}


def apply_model_error(cal, me: dict) -> None:
    """Add the model-error term of ``me`` (:func:`model_error`) to ``cal``'s 1σ, in place:
    ``params``, the record's ``[fit]`` table, a warning and ``diagnostics``."""
    f1 = float(cal.params["f1_hz"]["value"])
    rel_f = np.hypot(me["f1_hz"]["bias"], me["f1_hz"]["std"]) / f1
    dz = float(np.hypot(me["zeta"]["bias"], me["zeta"]["std"]))
    for name, p in cal.params.items():
        if name in ("zeta", "zeta_1"):
            extra = dz
        elif name.startswith("f") and name.endswith("_hz"):
            extra = rel_f * abs(p["value"])
        elif name in _POWER_OF_F1 and str(p.get("source", "")).startswith("derived from kappa"):
            extra = abs(_POWER_OF_F1[name]) * rel_f * abs(p["value"])
        elif name == "kappa":
            extra = 2.0 * rel_f * abs(p["value"])
        else:
            continue
        p["std_without_model_error"] = p["std"]
        p["std"] = float(np.hypot(p["std"], extra))
    fit = cal.record.extra.get("fit")
    if isinstance(fit, dict):
        for name, p in fit.get("params", {}).items():
            if name in cal.params:
                p["std"] = cal.params[name]["std"]
    f = me["f1_hz"]
    text = (
        f"the data prefer a nonlinear model by BIC ({', '.join(me['terms'])}: score gain "
        f"{me['bic_gain']:.3g} over ln n = {me['ln_n']:.3g}), by less than the amplitude "
        f"test rejects: f1 and zeta are averages over the decay's amplitudes, about "
        f"{f['bias']:+.3g} +- {f['std']:.2g} Hz and {me['zeta']['bias']:+.3g} +- "
        f"{me['zeta']['std']:.2g} from their small-amplitude values; their 1-sigma include "
        "that (model error); fit with --model nonlinear for the small-amplitude values"
    )
    cal.warnings.append(f"amplitude-averaged: {text}")
    cal.diagnostics["model_error"] = {**me, "message": text}
    if isinstance(fit, dict):
        fit["warnings"] = list(cal.warnings)
