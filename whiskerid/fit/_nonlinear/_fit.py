"""Calibrate a weakly nonlinear whisker: f₀, ζ₀ and the backbone ``f(a)``, ``ζ(a)``.

The first mode of each free decay is the slow flow of :class:`whiskerid.model.NonlinearMode`
(cubic stiffness, velocity-squared and Coulomb damping): ``a(t) cos φ(t)`` in place of the
linear fit's ``e^{−ζω t} cos ω_d t`` columns; higher modes, offset and drift stay as in the
linear fit (:mod:`._problem`). Its amplitude ``a`` is the first mode's tip deflection (m):
the fitted amplitude through the record's gain (divided by ``ω²`` for an accelerometer) is
the mode's deflection where the recording reads it, scaled by the mode shape
``φ₁(l)/φ₁(x)`` (:func:`tip_per_sensor`).

Parameters are scaled by a reference amplitude ``a_ref`` (the largest starting amplitude of
the recordings, from the linear fit), so that each is a small dimensionless number the data
see directly:

* ``g = 3γa_ref²/8``: relative frequency rise at ``a_ref`` (cubic);
* ``h = 4κa_ref/(3π)``: relative frequency change at ``a_ref`` linear in ``a`` (``kappa``);
* ``ζ_v = 4c·a_ref/(3π)``: velocity-squared damping's ``ζ`` at ``a_ref``;
* ``ζ_c = 2F/(πω₀²a_ref)``: friction's ``ζ`` at ``a_ref`` (it grows as ``a_ref/a``).

At ``g = h = ζ_v = ζ_c = 0`` the model is the linear one exactly, so the linear optimum starts
the Levenberg–Marquardt fit of all parameters (optimistix). The covariance is the HAC
(Newey–West) sandwich at the optimum, never below the white-noise ``s²(JᵀJ)⁻¹``: a first-
order slow flow leaves small harmonics in the residuals, and real recordings leave more.
"""

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ...model import NonlinearMode
from .._checks import (
    check_fit,
    decay_sampling_rates_hz,
    hac_covariance,
    no_smaller_than,
    residual_peak,
    residual_spectra,
)
from .._checks import lag1 as lag1_autocorr
from .._data import CalibrationError
from .._linear import GTOL, unflatten_numpy
from .._numerics import lsq
from .._result import (
    Calibration,
    correlation_table,
    fit_diagnostics,
    fit_status,
    poor_fit_warnings,
    recording_blocks,
    reported_std,
)
from ._backbone_check import backbone_check, misfit_reason
from ._free_modes import FreeModesProblem, free_higher_modes, free_modes_table
from ._friction import friction_waveform as friction_waveform
from ._logpoly import logpoly_table, lowest_informed_amplitude
from ._problem import (
    ALL_TERMS,
    COEFFICIENT_OF,
    NL_TERMS,
    NonlinearProblem,
    observed_per_metre,
)
from ._program import nonlinear_reported_with_jacobian, solve_nonlinear
from ._short_windows import short_window_points

#: Points of the reported backbone between the smallest and largest amplitudes.
BACKBONE_POINTS = 9


# --------------------------------------------------------------------------- results
@dataclass
class NonlinearCalibration(Calibration):
    """A :class:`Calibration` of the nonlinear model (``model = "nonlinear"``).

    ``params["f1_hz"]`` and ``params["zeta"]`` are the small-amplitude (``a → 0``) values;
    the nonlinear coefficients are ``gamma_per_m2`` (γ), ``quadratic_per_m`` (c) and
    ``coulomb_m_s2`` (F), as fitted.

    Attributes:
        backbone: ``amplitude_m``, ``f_hz``, ``f_std``, ``zeta``, ``zeta_std``: the fitted
            backbone at amplitudes spanning the recordings' (lists), and ``windows``: short-
            window damped-sine fits (``amplitude_m``, ``f_hz``, ``zeta``) to compare with it.
        linear: The linear calibration the fit started from.
    """

    backbone: dict = field(default_factory=dict)
    linear: Calibration | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        """The linear fit's JSON summary plus ``model`` and ``backbone``."""
        out = super().to_json()
        out["model"] = "nonlinear"
        out["backbone"] = self.backbone
        return out

    def report(self) -> str:
        """The console report with the backbone's table at the end."""
        b = self.backbone
        lines = [super().report(), "[[Backbone]] (a: mode 1 tip amplitude)"]
        for i, a in enumerate(b["amplitude_m"]):
            lines.append(
                f"    a = {a:.4g} m: f = {b['f_hz'][i]:.6g} ± {b['f_std'][i]:.2g} Hz, "
                f"zeta = {b['zeta'][i]:.4g} ± {b['zeta_std'][i]:.2g}"
            )
        return "\n".join(lines)


# --------------------------------------------------------------------------- calibrate
def fit_nonlinear(
    linear: Calibration,
    observations,
    *,
    terms: tuple[str, ...] = NL_TERMS,
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    free_modes: bool = False,
    knots: int = 0,
) -> NonlinearCalibration:
    """The nonlinear fit with the given ``terms`` (or ``knots``), from a converged linear
    calibration: :func:`whiskerid.fit.calibrate_nonlinear` without the term selection
    (``terms="auto"``); the arguments are as there."""
    obs = list(observations)
    base = linear.problem
    if base is None or linear.optimum is None:
        raise CalibrationError("the nonlinear fit needs a linear calibration to start from")
    if base.static_test is not None or any(r.excitation != "decay" for r in base.recordings):
        raise CalibrationError(
            "the nonlinear model fits free decays only (no sine, base motion or static test); "
            "fit those with --model linear"
        )
    terms = tuple(t for t in ALL_TERMS if t in terms)
    nm = base.n_modes
    wl = base.whisker(linear.optimum)
    w0 = float(wl.omega_rad_s[0])
    mode_l = NonlinearMode(w0 / (2 * np.pi), float(wl.zeta[0]))
    amps = [
        float(np.hypot(p["c"][2], p["c"][2 + nm]))
        / (abs(float(r.scale)) * float(observed_per_metre(r, mode_l, wl)))
        for r, p in zip(base.recordings, linear.optimum["recs"], strict=True)
    ]
    if knots:
        terms = ()
        flexible = {"n_knots": int(knots),
                  "ln_a_lo": jnp.log(lowest_informed_amplitude(linear, amps))}  # fmt: skip
    else:
        flexible = {}
    problem = NonlinearProblem(base=base, a_ref=jnp.asarray(max(amps)), terms=terms, **flexible)
    theta0 = dict(linear.optimum)
    theta0["nl"] = jnp.zeros_like(problem.zero_params()["nl"])
    if free_modes and nm > 1:
        problem, theta0 = free_higher_modes(problem, theta0, obs)
    # in NumPy (ravel_pytree's order): eager JAX would compile small programs in every run
    flat0 = np.concatenate([np.ravel(np.asarray(x)) for x in jax.tree_util.tree_leaves(theta0)])
    problem, core = solve_nonlinear(problem, flat0, solver=solver, max_steps=max_steps,
                                    observed_per_metre=observed_per_metre)  # fmt: skip
    res = lsq.FitResult(core["value"], core["ok"], core["steps"], core["cost"], core["resid"].size)
    resid_w, jac = core["resid"], core["jac"]
    s2, gcos = float(core["s2"]), float(core["gcos"])
    cov_white = s2 * core["bread"]
    converged = bool(res.ok) or gcos < GTOL
    ok = converged and bool(np.all(np.isfinite(np.diag(cov_white))))
    status = "ok" if ok else ("non-finite" if not np.isfinite(float(res.cost)) else "not converged")
    cov, lag = hac_covariance(recording_blocks(jac, resid_w, obs), core["bread"])
    cov = no_smaller_than(cov, cov_white)
    uncertainty = (
        f"HAC (Newey-West, Bartlett weights to lag {lag}; never below the white-noise 1-sigma)"
    )
    optimum = unflatten_numpy(problem, res.value)
    per_rec, curves, envelopes = _nonlinear_per_recording(problem, optimum, obs, core)
    grid = _amplitude_grid(envelopes, per_rec)
    params, corr, backbone = _nonlinear_params(problem, res.value, cov, cov_white, grid, linear)
    backbone["windows"] = short_window_points(obs, per_rec, float(params["f1_hz"]["value"]))
    diagnostics = {
        "model": "nonlinear",
        **fit_diagnostics(per_rec, obs, res, resid_w, s2=s2, gcos=gcos, uncertainty=uncertainty),
        "a_ref_m": float(problem.a_ref),
        **_logpoly_diagnostics(problem),
        # RSS of the linear fit over the nonlinear one (normalised data, unweighted)
        "linear_rss_over_nonlinear": rss_of_curves(linear)
        / max(_rss_nonlinear(problem, core), 1e-300),
    }
    warnings = poor_fit_warnings(per_rec)
    checks: dict[str, str] = {}
    if ok:
        f1_nom = float(linear.record.whisker().natural_frequencies_hz[0])
        checks = check_fit(params, per_rec, f1_nom, decay_rates_hz=decay_sampling_rates_hz(obs))
        # residuals at the whisker's frequency after the nonlinear model: a lag-1 test
        # does not see them, the HAC 1σ does allow for them
        checks.pop("correlated-residuals", None)
        z = np.asarray(backbone["zeta"])
        if np.any(z < -2 * np.asarray(backbone["zeta_std"])):
            checks["negative-damping"] = (
                f"zeta(a) falls to {z.min():.3g} within the recorded amplitudes: the damping "
                "terms fitted do not describe these data; fit fewer terms (--nl-terms)"
            )
        # the backbone against the decays' own short-window f and zeta (model-free)
        bb_check = backbone_check(obs, curves, per_rec, float(params["f1_hz"]["value"]))
        diagnostics["backbone_check"] = bb_check
        if (reason := misfit_reason(bb_check)) is not None:
            checks["backbone-misfit"] = reason
    status, warnings = fit_status(status, ok, warnings, checks)
    out = NonlinearCalibration(
        status=status, ok=ok, params=params, correlations=corr, fixed=dict(linear.fixed),
        note=_note(linear.note, terms), diagnostics=diagnostics, per_recording=per_rec,
        record=linear.record, solver=solver, curves=curves, warnings=warnings, checks=checks,
        problem=problem, optimum=optimum, covariance=cov, backbone=backbone, linear=linear,
    )  # fmt: skip
    out.record = _record_with_nonlinear_fit(out)
    # the residual's spectrum near each mode against the sensor noise's (lag-1 is no
    # whiteness measure for a misfit at the whisker's own frequency)
    out.diagnostics["residual_spectrum"] = residual_spectra(out, obs)
    return out


def _logpoly_diagnostics(problem) -> dict:
    if not problem.n_knots:
        return {}
    a_lo = float(np.exp(problem.ln_a_lo))
    return {"backbone_model": "log-polynomial", "knots": problem.n_knots, "a_lo_m": a_lo}


def rss_of_curves(cal: Calibration) -> float:
    """Unweighted normalised RSS of a fit's curves (a linear or a nonlinear fit: comparable
    with each other)."""
    return float(sum(np.sum(((np.asarray(m) - y) / np.std(y)) ** 2) for _, y, m in cal.curves))


def _rss_nonlinear(problem, core) -> float:
    """Unweighted normalised RSS of the nonlinear fit (the program's curves)."""
    return float(sum(np.sum((core[f"model_{i}"] - np.asarray(r.y)) ** 2)
                     for i, r in enumerate(problem.base.recordings)))  # fmt: skip


def _note(linear_note: str, terms) -> str:
    if not terms:
        return (
            f"{linear_note} Backbone f(a), zeta(a): polynomials in ln a. f1 and zeta are "
            "their values at the smallest informed amplitude a_lo (diagnostics a_lo_m), not "
            "a -> 0 values; the backbone is identified only between a_lo and the largest "
            "amplitude recorded."
        )
    return (
        f"{linear_note} Nonlinear terms fitted: {', '.join(terms)}. f1 and zeta are the "
        "small-amplitude (a -> 0) values; the backbone f(a), zeta(a) is identified only "
        "between the smallest and largest amplitudes recorded, and the amplitude a (mode 1 "
        "tip deflection, m) rests on the record's gain and mode shape."
    )


def _nonlinear_per_recording(problem: NonlinearProblem, optimum, obs, core):
    out, curves, envelopes = [], [], []
    for i, (rec, p, o) in enumerate(zip(problem.base.recordings, optimum["recs"], obs,
                                        strict=True)):  # fmt: skip
        y_mean, y_std = float(np.mean(o.y)), float(np.std(o.y))
        model = core[f"model_{i}"] * y_std + y_mean
        r = o.y - model
        rms = float(np.sqrt(np.mean(r**2)))
        obs_per_m = float(core[f"per_m_{i}"])
        c = np.asarray(p["c"])
        modal = core[f"modal_{i}"]
        a = core[f"env_{i}"]
        out.append(
            {
                "name": o.name,
                "source": o.source,
                "excitation": o.excitation,
                "observable": o.observable,
                "n_samples": int(o.t.size),
                "t_start_s": float(o.t[0]),
                "rms_residual": rms,
                "rms_signal": y_std,
                "snr_db": float(20 * np.log10(y_std / max(rms, 1e-300))),
                "lag1_autocorr": lag1_autocorr(r),
                "residual_peak": residual_peak(o.t, r),
                "selection": o.selection,
                "offset": float(c[0] * y_std + y_mean),
                "modal_rms": [float(v) for v in np.sqrt(np.mean(modal**2, axis=0)) * y_std],
                "amplitude_start_m": float(a[0]),
                "amplitude_end_m": float(a[-1]),
                # the residual RMS as a mode-1 amplitude (m): below it the data say little
                "noise_amplitude_m": rms * np.sqrt(2) / (abs(float(rec.scale)) * y_std * obs_per_m),
            }
        )
        curves.append((o.t, o.y, model))
        envelopes.append(np.asarray(a))
    return out, curves, envelopes


def _amplitude_grid(envelopes, per_rec) -> np.ndarray:
    """Amplitudes (m) where the recordings inform the backbone: from the largest start
    down to the smallest envelope still three times above its recording's noise."""
    hi = max(float(e[0]) for e in envelopes)
    lows = [max(float(e[-1]), 3 * r["noise_amplitude_m"]) for e, r in zip(envelopes, per_rec,
                                                                        strict=True)]  # fmt: skip
    lo = min(min(lows), 0.5 * hi)
    return np.geomspace(lo, hi, BACKBONE_POINTS)


def _nonlinear_params(problem, flat, cov, cov_white, grid, linear):
    values, jac = nonlinear_reported_with_jacobian(problem, flat, grid)
    names = _reported_names(problem, flat, grid)
    dcov = jac @ cov @ jac.T
    std = reported_std(dcov)
    std_white = reported_std(jac @ cov_white @ jac.T)
    params, bb = {}, {"f_hz": [], "f_std": [], "zeta": [], "zeta_std": []}
    keep = []
    for i, name in enumerate(names):
        if name.startswith("backbone_"):
            key = "f" if name.startswith("backbone_f_") else "zeta"
            bb[f"{key}_hz" if key == "f" else key].append(float(values[i]))
            bb[f"{key}_std"].append(float(std[i]))
            continue
        keep.append(i)
        source = linear.params[name]["source"] if name in linear.params else "fit"
        params[name] = {"value": float(values[i]), "std": float(std[i]), "source": source,
                        "std_white": float(std_white[i])}  # fmt: skip
    bb["amplitude_m"] = [float(a) for a in grid]
    correlations = correlation_table([names[i] for i in keep], dcov[np.ix_(keep, keep)], std[keep])
    return params, correlations, bb


def _reported_names(problem, flat, grid) -> list[str]:
    """The names of :meth:`NonlinearProblem.reported` in its order (traced for shapes only:
    a dict returned through JAX comes back with its keys sorted)."""
    names: list[str] = []

    def fn(params, amplitudes):
        names.extend(problem.reported(params, amplitudes))
        return 0.0

    jax.eval_shape(fn, unflatten_numpy(problem, flat), grid)
    return names


def _record_with_nonlinear_fit(cal: NonlinearCalibration):
    """The linear fit's record with the a→0 values and a ``[fit.nonlinear]`` table."""
    rec = cal.linear.record
    extra = dict(rec.extra)
    fit = dict(extra.get("fit", {}))
    p = cal.params
    fit["status"] = cal.status
    fit["model"] = "nonlinear"
    fit.pop("warnings", None)  # the linear fit's
    if cal.warnings:
        fit["warnings"] = list(cal.warnings)
    fit["params"] = {k: {"value": v["value"], "std": v["std"], "source": v["source"]}
                     for k, v in p.items()}  # fmt: skip
    if cal.problem.n_knots:  # an identified f(a), ζ(a): no a → 0 values or coefficients
        fit["nonlinear"] = logpoly_table(cal)
        extra["fit"] = fit
        return rec.replace(zeta=p["zeta"]["value"], extra=extra)
    fit["nonlinear"] = {
        "f0_hz": p["f1_hz"]["value"],
        "zeta0": p["zeta"]["value"],
        **{k: p.get(k, {"value": 0.0})["value"] for k in COEFFICIENT_OF.values()},
        "amplitude": "mode 1 tip deflection (m)",
        "backbone": {k: v for k, v in cal.backbone.items() if k != "windows"},
    }
    if isinstance(cal.problem, FreeModesProblem):  # free higher modes (._free_modes)
        fit["nonlinear"]["free_modes"] = free_modes_table(p, cal.problem.base.n_modes)
    extra["fit"] = fit
    return rec.replace(zeta=p["zeta"]["value"], extra=extra)
