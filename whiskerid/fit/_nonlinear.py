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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ..model import NonlinearMode, mode_shape, slow_flow
from . import _lsq as _lsq
from ._calibrate import (
    GTOL,
    Calibration,
    _blocks,
    _poor_fit_warnings,
    fit_diagnostics,
    fit_status,
)
from ._checks import check_fit, decay_rates, hac_covariance, no_smaller_than, residual_peak
from ._checks import lag1 as lag1_autocorr
from ._core import unflatten_numpy
from ._decay import conversion_average
from ._nl_accelerometer import accelerometer_columns, start_on_backbone
from ._nl_core import reported_with_jacobian, solve_nonlinear
from ._nl_friction import _friction_offset, friction_stop
from ._nl_friction import friction_waveform as friction_waveform
from ._nl_logpoly import logpoly_mode, lowest_informed_amplitude
from ._observation import CalibrationError
from ._problem import FitProblem, recording_design
from ._short_windows import short_window_points
from ._spectral_floor import residual_spectra

#: The nonlinear terms fitted by default, in the order of the parameter vector ``nl``.
NL_TERMS = ("cubic", "quadratic", "coulomb")
#: Every term: the defaults and ``kappa`` (``κu|u|``, a frequency shift linear in ``a``).
ALL_TERMS = (*NL_TERMS, "kappa")
#: Physical coefficient (as :class:`whiskerid.model.NonlinearMode` names it) of each term.
COEFFICIENT_OF = {"cubic": "gamma_per_m2", "quadratic": "quadratic_per_m",
                  "coulomb": "coulomb_m_s2", "kappa": "kappa_per_m"}  # fmt: skip
_SCALED = {"cubic": "g", "quadratic": "zeta_v", "coulomb": "zeta_c", "kappa": "h"}
#: Points of the reported backbone between the smallest and largest amplitudes.
BACKBONE_POINTS = 9


class NonlinearProblem(eqx.Module):
    """A linear :class:`FitProblem` whose first mode follows the slow flow.

    Attributes:
        base: The linear problem (recordings, whisker, weights).
        a_ref: Reference amplitude (m) that scales the nonlinear parameters.
        terms: The nonlinear terms fitted (a subset of :data:`ALL_TERMS`; empty for a
            log-polynomial backbone).
        n_knots: 0 for the parametric backbone, else the knots of a log-polynomial backbone
            (:mod:`._nl_logpoly`; ``nl`` then holds its values at knots 2…).
        ln_a_lo: ``ln a_lo`` (m) of a log-polynomial backbone's first knot (None without one).
        masks: Per recording, 1 for a sample and 0 for the zero-weight padding of its shape
            bucket (:func:`whiskerid.fit._nl_core.padded`); None when not padded.
    """

    base: FitProblem
    a_ref: Array
    terms: tuple[str, ...] = eqx.field(static=True)
    n_knots: int = eqx.field(static=True, default=0)
    ln_a_lo: Array | None = None
    masks: tuple[Array, ...] | None = None

    def __check_init__(self):
        if jnp.shape(self.a_ref) != ():
            raise ValueError("NonlinearProblem.a_ref must be a scalar")
        if self.n_knots and (self.terms or self.ln_a_lo is None):
            raise ValueError("a log-polynomial backbone takes no terms and needs ln_a_lo")
        if not self.n_knots and (not self.terms or any(t not in ALL_TERMS for t in self.terms)):
            raise ValueError(f"terms must be a non-empty subset of {ALL_TERMS}")

    def zero_params(self) -> dict:
        """The linear problem's pytree plus ``nl`` (one entry per term, or the polynomial's
        ``S_f``, ``S_z`` at knots 2…)."""
        p = self.base.zero_params()
        p["nl"] = np.zeros(2 * (self.n_knots - 1) if self.n_knots else len(self.terms))
        return p

    def flatten(self, params) -> Array:
        """The parameter pytree as one flat vector (the solver's and covariance's order)."""
        return ravel_pytree(params)[0]

    def unflatten(self, flat) -> dict:
        """Inverse of :meth:`flatten`."""
        return ravel_pytree(self.zero_params())[1](flat)

    def scaled(self, params) -> dict[str, Array]:
        """``g``, ``h``, ``zeta_v``, ``zeta_c`` (zero for the terms not fitted)."""
        out = dict.fromkeys(_SCALED.values(), 0.0)
        for i, term in enumerate(self.terms):
            out[_SCALED[term]] = params["nl"][i]
        return out

    def mode(self, params) -> NonlinearMode:
        """The first mode at ``params`` (physical coefficients from the scaled ones, or the
        log-polynomial backbone)."""
        if self.n_knots:
            return logpoly_mode(self, params)
        w = self.base.whisker(params)
        s = self.scaled(params)
        w0 = w.omega_rad_s[0]
        a = self.a_ref
        return NonlinearMode(
            f0_hz=w0 / (2 * jnp.pi),
            zeta0=w.zeta[0],
            gamma_per_m2=8 * s["g"] / (3 * a**2),
            quadratic_per_m=3 * jnp.pi * s["zeta_v"] / (4 * a),
            coulomb_m_s2=jnp.pi * w0**2 * s["zeta_c"] * a / 2,
            kappa_per_m=3 * jnp.pi * s["h"] / (4 * a),
        )

    def design(self, params) -> list[tuple[Array, Array, Array]]:
        """``(D, g, a)`` per recording: the linear design with mode 1's two columns replaced
        by the slow flow's, and the envelope ``a(t)`` (m)."""
        w = self.base.whisker(params)
        mode = self.mode(params)
        nm = self.base.n_modes
        out = []
        for i, (rec, p) in enumerate(zip(self.base.recordings, params["recs"], strict=True)):
            D, g = recording_design(rec, w, p)
            obs = _observed_per_metre(rec, mode, w)
            a0 = jnp.hypot(p["c"][2], p["c"][2 + nm]) / (jnp.abs(rec.scale) * obs)
            if rec.observable == "acceleration":  # it reads a·|K(a)|, not a·ω₀²
                a0 = start_on_backbone(mode, a0)
            a, phi = slow_flow(mode, rec.t, a0)
            if "coulomb" in self.terms:
                psi = phi - jnp.arctan2(p["c"][2 + nm], p["c"][2])
                a, held, _ = friction_stop(mode, rec.t, a, psi)
            env = a / jnp.maximum(a0, 1e-300)
            if rec.observable == "acceleration":
                c, s = accelerometer_columns(mode, jnp.maximum(a, 0.0), a0, env, phi)
            else:
                c, s = env * jnp.cos(phi), env * jnp.sin(phi)
            if rec.avg_offsets is not None:
                wd = mode.omega(a) * jnp.sqrt(1 - mode.zeta0**2)
                re, im = conversion_average(mode.zeta0 * mode.omega0 + 0 * wd, wd, rec.avg_offsets)
                c, s = c * re - s * im, s * re + c * im
            D = D.at[:, 2].set(c).at[:, 2 + nm].set(s)
            if "coulomb" in self.terms:
                g = g + _friction_offset(rec, psi, held, mode, obs)
                # the held level is profiled out (a free constant after the stop): the stop's
                # turn is discrete, and one turn more or less would move the exact level by
                # 2F/ω₀², a step over the whole rest of the recording (a rugged cost)
                real = held if self.masks is None else held & (self.masks[i] > 0)
                level = jnp.sum(jnp.where(real, rec.y - D @ p["c"] - g, 0.0))
                g = g + jnp.where(held, level / jnp.maximum(jnp.sum(real), 1), 0.0)
            out.append((D, g, jnp.maximum(a, 0.0)))
        return out

    def residuals(self, params) -> Array:
        """Weighted residuals of all recordings, one vector (0 where padded)."""
        masks = self.masks or (1.0,) * len(self.base.recordings)
        return jnp.concatenate(
            [
                (D @ p["c"] + g - r.y) * r.weight * m
                for (D, g, _), r, p, m in zip(
                    self.design(params), self.base.recordings, params["recs"], masks, strict=True
                )
            ]
        )

    def reported(self, params, amplitudes: Array) -> dict[str, Array]:
        """The linear fit's quantities (f1_hz, ζ … at ``a → 0``), the physical nonlinear
        coefficients, and the backbone ``f(a)``, ``ζ(a)`` at ``amplitudes`` (m)."""
        out = dict(self.base.reported(params))
        m = self.mode(params)
        for term in self.terms:
            out[COEFFICIENT_OF[term]] = getattr(m, COEFFICIENT_OF[term])
        for i in range(amplitudes.shape[0]):
            out[f"backbone_f_{i}"] = m.frequency_hz(amplitudes[i])
            out[f"backbone_zeta_{i}"] = m.zeta(amplitudes[i])
        return out


def _observed_per_metre(rec, mode, whisker):
    """Observed (physical) amplitude per metre of mode-1 tip deflection: the mode shape's
    ``φ₁(x)/φ₁(l)`` where it is read, times ``ω₀²`` for acceleration."""
    acc = mode.omega0**2 if rec.observable == "acceleration" else 1.0
    return acc / tip_per_sensor(whisker, rec.x_m)


def tip_per_sensor(whisker, x_m):
    """``φ₁(l)/φ₁(x)``: mode 1's tip deflection per unit of its deflection at ``x_m``."""
    shape = mode_shape(whisker.beta, jnp.stack([x_m / whisker.length_m, 1.0]))[:, 0]
    return shape[1] / shape[0]


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
        from ._nl_select import calibrate_nonlinear_selected

        return calibrate_nonlinear_selected(linear, observations, solver=solver,
                                            max_steps=max_steps, free_modes=free_modes)  # fmt: skip
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
        / (abs(float(r.scale)) * float(_observed_per_metre(r, mode_l, wl)))
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
        from ._nl_free_modes import free_higher_modes

        problem, theta0 = free_higher_modes(problem, theta0, obs)
    # in NumPy (ravel_pytree's order): eager JAX would compile small programs in every run
    flat0 = np.concatenate([np.ravel(np.asarray(x)) for x in jax.tree_util.tree_leaves(theta0)])
    problem, core = solve_nonlinear(problem, flat0, solver=solver, max_steps=max_steps,
                                    observed_per_metre=_observed_per_metre)  # fmt: skip
    res = _lsq.FitResult(core["value"], core["ok"], core["steps"], core["cost"], core["resid"].size)
    resid_w, jac = core["resid"], core["jac"]
    s2, gcos = float(core["s2"]), float(core["gcos"])
    cov_white = s2 * core["bread"]
    converged = bool(res.ok) or gcos < GTOL
    ok = converged and bool(np.all(np.isfinite(np.diag(cov_white))))
    status = "ok" if ok else ("non-finite" if not np.isfinite(float(res.cost)) else "not converged")
    cov, lag = hac_covariance(_blocks(jac, resid_w, obs), core["bread"])
    cov = no_smaller_than(cov, cov_white)
    uncertainty = (
        f"HAC (Newey-West, Bartlett weights to lag {lag}; never below the white-noise 1-sigma)"
    )
    optimum = unflatten_numpy(problem, res.value)
    per_rec, curves, envelopes = _per_recording(problem, optimum, obs, core)
    grid = _amplitude_grid(envelopes, per_rec)
    params, corr, backbone = _report(problem, res.value, cov, cov_white, grid, linear)
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
    warnings = _poor_fit_warnings(per_rec)
    checks: dict[str, str] = {}
    if ok:
        f1_nom = float(linear.record.whisker().natural_frequencies_hz[0])
        checks = check_fit(params, per_rec, f1_nom, decay_rates_hz=decay_rates(obs))
        # residuals at the whisker's frequency after the nonlinear model: a lag-1 test
        # does not see them, the HAC 1σ does allow for them
        checks.pop("correlated-residuals", None)
        z = np.asarray(backbone["zeta"])
        if np.any(z < -2 * np.asarray(backbone["zeta_std"])):
            checks["negative-damping"] = (
                f"zeta(a) falls to {z.min():.3g} within the recorded amplitudes: the damping "
                "terms fitted do not describe these data; fit fewer terms (--nl-terms)"
            )
    status, warnings = fit_status(status, ok, warnings, checks)
    out = NonlinearCalibration(
        status=status, ok=ok, params=params, correlations=corr, fixed=dict(linear.fixed),
        note=_note(linear.note, terms), diagnostics=diagnostics, per_recording=per_rec,
        record=linear.record, solver=solver, curves=curves, warnings=warnings, checks=checks,
        problem=problem, optimum=optimum, covariance=cov, backbone=backbone, linear=linear,
    )  # fmt: skip
    out.record = _updated_record(out)
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


def _per_recording(problem: NonlinearProblem, optimum, obs, core):
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


def _report(problem, flat, cov, cov_white, grid, linear):
    values, jac = reported_with_jacobian(problem, flat, grid)
    names = _reported_names(problem, flat, grid)
    dcov = jac @ cov @ jac.T
    std = np.sqrt(np.maximum(np.diag(dcov), 0.0))
    std_white = np.sqrt(np.maximum(np.diag(jac @ cov_white @ jac.T), 0.0))
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
    with np.errstate(invalid="ignore", divide="ignore"):
        sub = dcov[np.ix_(keep, keep)]
        corr = sub / np.outer(std[keep], std[keep])
    correlations = {
        "names": [names[i] for i in keep],
        "matrix": np.round(np.nan_to_num(corr), 6).tolist(),
    }
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


def _updated_record(cal: NonlinearCalibration):
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
        from ._nl_logpoly import logpoly_table

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
    if hasattr(cal.problem, "higher"):  # free higher modes (._nl_free_modes)
        from ._nl_free_modes import free_modes_table

        fit["nonlinear"]["free_modes"] = free_modes_table(p, cal.problem.base.n_modes)
    extra["fit"] = fit
    return rec.replace(zeta=p["zeta"]["value"], extra=extra)
