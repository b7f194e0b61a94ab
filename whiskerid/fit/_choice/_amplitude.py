"""Does a linear fit of free decays hide amplitude dependence? A score test, and the choice
of model.

A linear fit averages a frequency that drifts and a damping that changes along a decay: its
residuals then sit at the whisker's own frequency, where a lag-1 autocorrelation test is blind
at low oversampling (lag-1 autocorrelation of a line at ``f`` is ``cos 2πf/f_s``), and its
white-noise 1σ is far too small. Two score (Lagrange multiplier) tests at the linear optimum
ask whether the data pull away from it, with no second fit:

* **nonlinear terms**: the derivatives of the model in the slow-flow parameters of
  :mod:`._nonlinear` at zero (``g``: frequency ``∝ a²``; ``ζ_v``: damping ``∝ a``; ``ζ_c``:
  damping ``∝ 1/a``) are closed-form functions of time times the fitted mode-1 signal
  (``∂φ/∂g = ω₀x₀²(1−e^{−2σt})/(2σ)``, ``∂ln a/∂ζ_v = −ω₀x₀(1−e^{−σt})/σ``,
  ``∂ln a/∂ζ_c = −ω₀(e^{σt}−1)/(σx₀)``, ``x₀ = a₀/a_ref``);
* **early against late**: a change of ``ζ`` and of ``f`` after the time that splits the
  decay's signal energy in two (``∂ln a/∂δζ = −ω₀(t−t_½)₊``, ``∂φ/∂(δf/f) = ω₀(t−t_½)₊``).

Each set of columns ``Z`` is projected off the linear Jacobian ``J`` (``Z⊥``); the score
``S = Z⊥ᵀr`` has the HAC (Newey–West) variance ``V`` of its per-sample terms (with the
residuals that one Gauss–Newton step along ``[J, Z]`` leaves, so that a misfit the
alternative explains does not widen its own yardstick), so that correlated noise does not
fake a detection, and ``T = SᵀV⁻¹S`` is χ² with as many degrees of
freedom as columns under a linear whisker. A statistic beyond its χ² quantile at
:data:`P_FALSE`, with a change of at least :data:`MIN_REL_CHANGE_ZETA` in ζ or
:data:`MIN_REL_CHANGE_F` in f, or both statistics beyond it whatever the change, marks the
linear fit ``check``; a Gauss–Newton step along
``[J, Z]`` estimates what the data found (``ζ`` and ``f`` at the largest and smallest
amplitudes, or early and late), and the message says it. A fit not rejected, whose data
still prefer the nonlinear terms by BIC, keeps ``ok`` with a model-error term in its 1σ
(:mod:`._model_error`).
"""

import numpy as np

from .._checks import residual_spectra
from .._data import check_noise_floor
from .._linear import ZETA_MAX, padded_problem, positions, residuals_and_jacobian
from .._nonlinear import NL_TERMS, calibrate_nonlinear, tip_per_sensor
from .._numerics import LinearPart
from ._model_error import apply_model_error, model_error
from ._scores import (
    NONLINEAR,
    lags_per_recording,
    score_statistic,
)

#: False-alarm probability of each test on a linear whisker.
P_FALSE = 1e-4
#: Columns of the early-against-late test (those of the nonlinear terms: ``NONLINEAR``).
SPLIT = ("zeta-late", "f-late")
#: The early part of the early-against-late test spans at least this many periods of f1.
MIN_CYCLES_BEFORE_SPLIT = 3
#: A rejection also needs a change this large over the recording's amplitudes (or between
#: its early and late parts): relative, of ζ or of f. Smaller ones are left to the linear
#: fit, whose values average over them (half the nonlinear fit's own targets: 10 % in ζ0,
#: 0.15 % in f0, so that the linear values stay within what a nonlinear fit could resolve).
MIN_REL_CHANGE_ZETA = 0.05
MIN_REL_CHANGE_F = 1e-3


def amplitude_test_applies(cal) -> bool:
    """Whether the test applies: a converged fit of free decays only, no static test."""
    p = cal.problem
    return (
        cal.ok
        and p is not None
        and p.static_test is None
        and all(r.excitation == "decay" for r in p.recordings)
    )


def amplitude_test(cal, *, resid=None, jac=None, core=None) -> dict:
    """Score tests of a linear calibration (see the module docstring).

    Args:
        cal: The linear calibration.
        resid, jac: Its weighted residuals and their Jacobian at the optimum, as the
            calibration's compiled program returned them (computed here when not given).
        core: What that program computed of the whisker for this test
            (``CoreResult.amplitude``; computed here when not given). With all three the
            test runs in NumPy, nothing is traced or compiled.

    Returns:
        ``{"nonlinear": {...}, "split": {...}, "rejects": bool, "message": str}``; each test
        has its statistic ``T``, degrees of freedom, p-value, and the Gauss–Newton estimates.
    """
    problem, opt = cal.problem, cal.optimum
    if resid is None or jac is None:
        resid, jac = residuals_and_jacobian(problem, problem.flatten(opt))
    r, jac = np.asarray(resid), np.asarray(jac)
    terms = core if core is not None else _whisker_terms(problem, opt)
    cols, info = _score_columns(problem, opt, terms)
    out = {}
    # factored once for the two tests and the model-error subsets (by the program, if given)
    lin = LinearPart(jac, None if core is None else core.get("svd"))
    sizes = [c["n"] for c in cols]
    steps = {}
    for name in ("nonlinear", "split"):
        z = np.concatenate([c[name] for c in cols], axis=0)
        zp = lin.project(z)
        # the score's variance from the residuals the alternative leaves (a Wald-type
        # estimate): a misfit the nonlinear terms explain does not widen its own yardstick
        steps[name] = (zp, *lin.gauss_newton(r, z, zp))
    lags = lags_per_recording(np.stack([steps[k][3] for k in steps]), sizes)
    for j, (name, (zp, d_j, d_z, r_alt)) in enumerate(steps.items()):
        out[name] = score_statistic(zp, r, r_alt, sizes, [lag[j] for lag in lags])
        out[name]["step"] = d_z.tolist()
        # the step of the two parameters _found reads (log κ and ζ's logit), not a pytree
        out[name]["linear_step"] = {k: d_j[positions(problem, k)] for k in ("log_kappa", "zeta_u")}
        out[name]["r_alt"] = r_alt
    found = {k: _found(cal, opt, out, info, k) for k in ("nonlinear", "split")}
    for k, (zetas, freqs, _) in found.items():
        out[k]["rel_change_zeta"] = abs(zetas[1] - zetas[0]) / max(abs(zetas[0]), 1e-12)
        out[k]["rel_change_f"] = abs(freqs[1] - freqs[0]) / max(abs(freqs[0]), 1e-12)
    # Significant and large enough to matter: on clean recordings (ADC rounding the only
    # noise) the test also finds misfits of the release and of the modes left out, a few
    # per mille of ζ and tens of ppm of f, which the linear fit's values survive.
    rejecting = [k for k in ("nonlinear", "split") if out[k]["p_value"] < P_FALSE
                 and (out[k]["rel_change_zeta"] >= MIN_REL_CHANGE_ZETA
                      or out[k]["rel_change_f"] >= MIN_REL_CHANGE_F)]  # fmt: skip
    # Both tests significant: the model's terms and the model-free early/late split agree
    # that the whisker changes along the decay. A change below the sizes above then still
    # biases the linear values by many of their own 1σ where the recording is long and clean
    # (0.1 % stiffening at 860 Hz: f1 8.6σ off); the misfits of a clean linear recording
    # (release, modes left out) reach one test, not both.
    if all(out[k]["p_value"] < P_FALSE for k in ("nonlinear", "split")):
        rejecting = ["nonlinear", "split"]
    out["rejects"] = bool(rejecting)
    best = min(rejecting, key=lambda k: out[k]["p_value"]) if rejecting else None
    out["message"] = found[best][2] if best else ""
    # the model-error term's subset of all three columns is the nonlinear test itself
    known = {
        tuple(range(len(NONLINEAR))): (out["nonlinear"]["statistic"], out["nonlinear"]["r_alt"])
    }
    for k in ("nonlinear", "split"):
        out[k].pop("linear_step")
        out[k].pop("r_alt")
    # the same columns, projected once for both
    out["model_error"] = model_error(cal, jac, r, cols, lin=lin, known=known,
                                     zp=steps["nonlinear"][0])  # fmt: skip
    return out


def _whisker_terms(problem, opt) -> dict:
    """What :func:`_score_columns` reads of the whisker at ``opt`` (as ``CoreResult.amplitude``),
    computed with JAX here (a calibration's compiled program returns it)."""
    w = problem.whisker(opt)
    nm = problem.n_modes
    # the design on the recordings padded to their shape buckets, as the calibration's
    # program pads them: one compiled design per bucket, not per recording length
    padded, _ = padded_problem(problem)
    designs = [
        np.asarray(D)[: r.t.size]
        for (D, _), r in zip(padded.design(opt), problem.recordings, strict=True)
    ]
    return {
        "w0": float(w.omega_rad_s[0]),
        "zeta0": float(w.zeta[0]),
        "tip": [float(tip_per_sensor(w, r.x_m)) for r in problem.recordings],
        "mode1": [D[:, [2, 2 + nm]] for D in designs],
        "dc": [D @ np.asarray(p["c"]) for D, p in zip(designs, opt["recs"], strict=True)],
    }


def _score_columns(problem, opt, terms):
    """Score columns per recording (weighted like the residuals) and the amplitudes."""
    nm = problem.n_modes
    w0, z0 = terms["w0"], terms["zeta0"]
    sigma = z0 * w0
    amps, per_ms = [], []
    for rec, p, tip in zip(problem.recordings, opt["recs"], terms["tip"], strict=True):
        per_m = (w0**2 if rec.observable == "acceleration" else 1.0) / tip
        per_ms.append(per_m)
        amps.append(float(np.hypot(p["c"][2], p["c"][2 + nm])) / (abs(float(rec.scale)) * per_m))
    a_ref = max(amps)
    out = []
    for d1, dc, rec, p, a0, per_m in zip(terms["mode1"], terms["dc"], problem.recordings,
                                         opt["recs"], amps, per_ms, strict=True):  # fmt: skip
        d1, c, t = np.asarray(d1), np.asarray(p["c"]), np.asarray(rec.t)
        wgt = float(rec.weight)
        m1 = d1[:, 0] * c[2] + d1[:, 1] * c[2 + nm]
        q = d1[:, 0] * c[2 + nm] - d1[:, 1] * c[2]  # ∂m1/∂φ
        x0 = a0 / a_ref
        e = np.exp(-sigma * t)
        dphi_g = w0 * x0**2 * (1 - e**2) / (2 * sigma)
        cubic = q * dphi_g
        if rec.observable == "acceleration":  # ω(a)² scales an accelerometer's amplitude
            cubic = cubic + m1 * 2 * x0**2 * (e**2 - 1)
        quad = m1 * (-w0 * x0 * (1 - e) / sigma)
        coul = m1 * (-w0 * (1 / e - 1) / (sigma * x0))
        if rec.observable != "acceleration":  # friction's square wave, its fundamental
            coul = coul - 2 * q / (x0 * e)
        energy = np.cumsum(m1**2)
        t_half = t[int(np.searchsorted(energy, 0.5 * energy[-1]))]
        # A damping or frequency "before" the split needs cycles to be one: over the first
        # cycle or two after a release the modes left out of the fit and the release itself
        # still show, and a linear whisker would be called amplitude-dependent for them.
        t_half = max(float(t_half), float(t[0]) + MIN_CYCLES_BEFORE_SPLIT * 2 * np.pi / w0)
        late = np.maximum(t - t_half, 0.0)
        cols = {
            "cubic": cubic, "quadratic": quad, "coulomb": coul,
            "zeta-late": m1 * (-w0 * late), "f-late": q * (w0 * late),
        }  # fmt: skip
        z = {k: wgt * np.stack([cols[n] for n in names], axis=1)
             for k, names in (("nonlinear", NONLINEAR), ("split", SPLIT))}  # fmt: skip
        z["n"] = t.size
        z["a_end"] = a0 * float(e[-1])
        z["t_half"] = float(t_half)
        resid_rms = float(np.std(np.asarray(rec.y) - dc))
        z["noise_m"] = np.sqrt(2) * resid_rms / (abs(float(rec.scale)) * per_m)
        out.append(z)
    info = {"a_ref": a_ref, "w0": w0, "zeta0": z0, "cols": out}
    return out, info


def _found(cal, opt, out, info, test: str):
    """What test ``test`` found, in the units of the report: ``((ζ before, ζ after),
    (f before, f after), message)``, before/after being the largest and smallest amplitude
    (``nonlinear``) or the early and late part of the decay (``split``)."""
    f1 = float(cal.params["f1_hz"]["value"])
    res = out[test]
    lin = res["linear_step"]
    u = float(np.ravel(opt["zeta_u"] + lin["zeta_u"])[0])
    zeta0 = ZETA_MAX * 0.5 * (1.0 + np.tanh(0.5 * u))  # to_interval(u, 0, ZETA_MAX), no overflow
    f0 = f1 * float(np.exp(0.5 * np.ravel(lin["log_kappa"])[0]))
    if test == "nonlinear":
        g, zv, zc = res["step"]
        a_ref = info["a_ref"]
        lo = max(min(max(c["a_end"], 3 * c["noise_m"]) for c in info["cols"]), a_ref / 30)
        parts = []
        for a in (a_ref, lo):
            x = a / a_ref
            parts.append((a, zeta0 + zv * x + zc / x, f0 * (1 + g * x**2)))
        (a1, z1, f_1), (a2, z2, f_2) = parts
        verb = "falls" if z2 < z1 else "rises"
        fverb = "falls" if f_2 < f_1 else "rises"
        return (
            (z1, z2),
            (f_1, f_2),
            (
                f"the decay is not linear (score test p = {res['p_value']:.2g}): zeta {z1:.3g} "
                f"at {_mm(a1)} {verb} to {z2:.3g} at {_mm(a2)}, f1 {f_1:.5g} Hz {fverb} to "
                f"{f_2:.5g} Hz: amplitude-dependent damping and stiffness; "
                "fit with --model nonlinear"
            ),
        )
    dz, df = res["step"]
    t_half = min(c["t_half"] for c in info["cols"])
    return (
        (zeta0, zeta0 + dz),
        (f0, f0 * (1 + df)),
        (
            "early and late parts of the decay disagree (score test p = "
            f"{res['p_value']:.2g}): zeta {zeta0:.3g} and f1 {f0:.5g} Hz before "
            f"{t_half:.3g} s, zeta {zeta0 + dz:.3g} and f1 "
            f"{f0 * (1 + df):.5g} Hz after; fit with --model nonlinear"
        ),
    )


def _mm(a_m: float) -> str:
    """An amplitude in mm (or µm when small)."""
    return f"{a_m * 1e3:.3g} mm" if a_m >= 1e-4 else f"{a_m * 1e6:.3g} um"


# --------------------------------------------------------------------------- model choice
MODELS = ("linear", "nonlinear", "auto")


def choose_model(cal, observations, model: str, terms=None, *, resid=None, jac=None, core=None,
           free_modes: bool = False):  # fmt: skip
    """The calibration ``model`` asks for, from the linear one ``cal``.

    ``linear``: ``cal``, marked ``check`` (``amplitude-dependent``) when the score tests
    reject it; ``nonlinear``: the nonlinear fit started at ``cal``; ``auto``: the nonlinear
    fit when the tests reject the linear one, else ``cal``; ``free_modes``: as
    :func:`whiskerid.fit.calibrate_nonlinear`. The test's figures are in
    ``diagnostics["amplitude_test"]`` of the linear fit.
    """
    test = None
    if amplitude_test_applies(cal):
        test = amplitude_test(cal, resid=resid, jac=jac, core=core)
        cal.diagnostics["amplitude_test"] = {
            k: {kk: vv for kk, vv in v.items() if kk != "step"} if isinstance(v, dict) else v
            for k, v in test.items()
        }
        if test["rejects"]:
            cal.checks["amplitude-dependent"] = test["message"]
            cal.warnings.append(f"amplitude-dependent: {test['message']}")
            if cal.status == "ok":
                cal.status = "check"
            cal.record.extra["fit"]["status"] = cal.status
            cal.record.extra["fit"]["warnings"] = list(cal.warnings)
        elif test["model_error"]["preferred"]:
            apply_model_error(cal, test["model_error"])
    if amplitude_test_applies(cal):
        cal.diagnostics["residual_spectrum"] = residual_spectra(cal, observations)
    check_noise_floor(cal, observations, _LINEAR_ADVICE)
    if model == "linear" or (model == "auto" and not (test and test["rejects"])):
        return cal
    nl = calibrate_nonlinear(cal, observations, terms=terms or NL_TERMS, free_modes=free_modes)
    check_noise_floor(nl, observations, _NONLINEAR_ADVICE)
    return nl


#: What to do when a fit's residuals stand above the noise floor (:mod:`._noise_floor`).
_LINEAR_ADVICE = (
    "an amplitude-dependent frequency or damping (fit with --model nonlinear), a mode left "
    "out (--modes) or a decay that starts in the wrong place (--t-start)"
)
_NONLINEAR_ADVICE = (
    "a mode left out (--modes), nonlinear terms that do not describe the whisker, "
    "or a decay that starts in the wrong place (--t-start)"
)
