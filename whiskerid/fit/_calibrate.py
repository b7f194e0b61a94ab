"""Calibrate a whisker from its recordings: stiffness (κ, EI or C), damping ζ, nuisances.

What the data determine. Vibration records alone determine the natural
frequencies, hence ``κ = EI/(ρa)`` (equivalently ``f_1``), and the modal damping ``ζ``;
``EI`` and ``ρa`` (so the coil factor ``C``) only as their ratio. The fit is therefore
parametrised in identifiable quantities, ``log κ`` and ``ζ`` (a logistic transform keeps
``0 < ζ < 0.95``), and EI or C is *derived* from κ and one pinned quantity, with the
uncertainty propagated through the Jacobian:

* ``geometry`` (default for coils and beams): ``ρa`` from the record's geometry and density
  (a coil's ``C`` from its wire and coil dimensions) → ``EI = κ ρa``;
* ``material``: ``EI`` from the record's material (``G_w J_w`` or ``E I``) → ``ρa = EI/κ``
  and a coil's ``C = ρa/(ρ_w a)``;
* a static test (tip force and deflection) fitted jointly: ``EI`` from the test, ``ρa`` and
  ``C`` from ``EI/κ``. Only then are both EI and C reported as fitted.

A tip mass makes the mode-frequency ratios depend on ``μ = M_t/(ρa l)``, so on ρa, but only
weakly; μ is taken from the record unless a static test fixes ρa.

The model (:class:`whiskerid.fit.FitProblem`, module ``_linear._problem``) is linear in most
nuisances, ``y = D(θ) c + g(θ)``. Start values come from the data (module ``_linear._start``: a
grid over ``(κ, ζ)`` seeded by the spectral peaks and the envelope's logarithmic decay, with
the linear coefficients solved exactly at every grid point); the best point starts a
Levenberg–Marquardt fit by variable projection (module ``_linear._varpro``: the linear coefficients
solved at every point; optimistix's dogleg or Gauss–Newton over all parameters on request),
with a status per fit.
The covariance is ``s²(JᵀJ)⁻¹`` at the optimum (through the SVD of the column-scaled
Jacobian, see :func:`whiskerid.fit.covariance`); with several recordings (or a static test)
each block is weighted by its own residual scale from a first pass. When the residuals are
correlated a HAC (Newey–West) sandwich replaces it, and a converged fit must pass the checks
of sub-package ``_checks`` (residuals, bounds, plausibility, precision) to be called ``ok``.

jaxopt is not used as a second backend: version 0.8.5 warns on import that it is no longer
maintained (which fails a test run with ``filterwarnings = error``) and its
Levenberg–Marquardt ignored ``tol`` (always ``maxiter`` steps); the bounds it
could add are handled here by transforms. ``scipy.optimize.least_squares`` and lmfit are
compared in ``benchmarks/calibrate.py`` instead.

"""

import numpy as np

from .._choices import PINS, SOLVERS
from ..model import WhiskerRecord
from ._added_mass import calibrate_added_mass
from ._checks import (
    LAG1_MAX,
    check_fit,
    data_side,
    robust_covariance,
)
from ._checks import moments as recording_moments
from ._choice import choose_model
from ._data import CalibrationError, Observation, StaticTest
from ._linear import GTOL as GTOL
from ._linear import (
    MODULUS_TOLERANCE,
    FitProblem,
    Parameters,
    at_bound,
    check_tolerance,
    fit_problem,
    modulus_covariance,
    nominal_whisker,
    problem_limits,
    reported_names,
    solve_status,
)
from ._numerics import single_blas_thread, with_compile_cache
from ._result import (
    Calibration,
    correlation_table,
    fit_diagnostics,
    fit_status,
    poor_fit_warnings,
    record_with_fit,
    recording_blocks,
    recording_diagnostics,
    reported_std,
)

#: Samples larger than this (in any units) are refused: their squares and sums overflow.
MAX_SAMPLE = 1e100


# --------------------------------------------------------------------------- calibrate


@with_compile_cache  # its small eager programs too, not only the calibration's own
@single_blas_thread(jax_lapack=True)  # small solves: threads only wait on a busy machine
def calibrate(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    static: StaticTest | None = None,
    n_modes: int = 2,
    zeta_per_mode: bool = False,
    pin: str = "auto",
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    f1_start_hz: float | None = None,
    start: dict | None = None,
    added_mass: list | None = None,
    modulus_tolerance: float = MODULUS_TOLERANCE,
    model: str = "linear",
    nl_terms: tuple[str, ...] | None = None,
    free_modes: bool = False,
    parameters: Parameters | None = None,
) -> Calibration:
    """Fit κ (f_1), ζ and the nuisances to one or more recordings (and a static test).

    Args:
        record: The whisker's record: geometry, material, tip mass, sensor, ADC, and the
            nominal values the start grid is centred on.
        observations: Recordings, fitted jointly (shared κ, ζ; own nuisances each).
        static: Optional static test; pins EI, so that ρa (a coil's C) follows from κ.
        n_modes: Modes in the model (frequencies tied by the cantilever's eigenvalues).
        zeta_per_mode: One ζ per mode instead of one for all.
        pin: What fixes EI or C without a static test: ``geometry`` (ρa, so C, from the
            record → EI derived), ``material`` (EI from the record → ρa, C derived), or
            ``auto`` (= geometry).
        solver: ``levenberg-marquardt`` (default), ``dogleg`` or ``gauss-newton``.
        max_steps: Solver step limit.
        f1_start_hz: Override the nominal f_1 the start search is centred on.
        start: Start parameters instead of the start search: a pytree of the problem's
            structure (``FitProblem.zero_params()``), e.g. from earlier fits of the same
            recordings.
        added_mass: One :class:`whiskerid.fit.AddedMass` (or None) per recording: the known
            mass clipped to the tip for it. Recordings with two or more different tip masses
            determine EI and ρa (so C) themselves (the added-mass method,
            :func:`whiskerid.fit.calibrate_added_mass`); ``pin`` and ``static`` are then not
            used.
        modulus_tolerance: Relative 1σ of the record's modulus under ``pin="material"``,
            carried into ρa's and C's 1σ (default 20 %, see ``whiskerid.fit._linear._modulus``).
        model: ``linear`` (default; free decays are also tested for amplitude-dependent
            frequency and damping, ``check`` when found), ``nonlinear`` (cubic stiffness and
            amplitude-dependent damping of mode 1, free decays only: a
            :class:`whiskerid.fit.NonlinearCalibration`) or ``auto`` (nonlinear when the
            test rejects the linear fit). See :mod:`whiskerid.fit._choice._amplitude`.
        nl_terms: The nonlinear model's terms (default all: ``cubic``, ``quadratic``,
            ``coulomb``).
        free_modes: The nonlinear model's modes 2… with their own frequency and damping,
            started at the data's line near the beam's ``f_k`` (reported as ``f2_hz``,
            ``zeta_2``, …): for a higher mode the beam puts in the wrong place, seen as a
            residual line near it. Needs ``model`` nonlinear or auto, ``n_modes ≥ 2`` and
            free decays (:func:`whiskerid.fit.calibrate_nonlinear`).
        parameters: Reported quantities held fixed or kept within bounds
            (:class:`whiskerid.fit.Parameters`: ``f1_hz``, ``zeta``; linear model only). A
            fixed one is reported with 1σ 0, one that ends at a bound with its 1σ refused
            (None, the reason in ``diagnostics["parameters"]``); the amplitude test is then
            not run (its steps assume the unlimited parameters).

    Returns:
        A :class:`Calibration`; never raises on a failed solve (see ``status``).
    """
    obs = [observations] if isinstance(observations, Observation) else list(observations)
    if not obs:
        raise CalibrationError("no recordings to calibrate")
    modulus_tolerance = check_tolerance(modulus_tolerance)
    _check_model(model, obs, static, free_modes, n_modes, added_mass)
    if added_mass is not None and parameters is not None and parameters.limits:
        raise CalibrationError("--fix/--bounds apply to the linear fit without added masses")
    if added_mass is not None:
        if static is not None:
            raise CalibrationError("give a static test or added masses, not both")
        return calibrate_added_mass(record, obs, list(added_mass), n_modes=n_modes,
                                    zeta_per_mode=zeta_per_mode, solver=solver,
                                    max_steps=max_steps, f1_start_hz=f1_start_hz,
                                    start=start)  # fmt: skip
    _check_linear(obs, pin, n_modes, f1_start_hz)
    pin = "geometry" if pin == "auto" else pin
    nominal = nominal_whisker(record, n_modes)
    limits, limit_values = (), None
    if parameters is not None and parameters.limits:
        if model != "linear":
            raise CalibrationError("--fix/--bounds apply to the linear model: leave out --model")
        f1_nom = float(np.asarray(nominal.natural_frequencies_hz)[0])
        kappa = float(nominal.EI) / float(nominal.rho_a)
        scale = None if static is not None else f1_nom / float(np.sqrt(kappa))
        limits, limit_values = problem_limits(parameters, f1_per_sqrt_kappa=scale)
    problem = FitProblem.from_observations(
        record, obs, static=static, n_modes=n_modes, zeta_per_mode=zeta_per_mode, pin=pin,
        nominal=nominal, limits=limits, limit_values=limit_values,
    )  # fmt: skip
    # One compiled program (module _linear._program): the start grid over (κ, ζ) with the linear
    # coefficients solved exactly, the solve, each block (recording, static test) weighted by
    # its own residual scale (s² ≈ 1, a reduced χ²), and one Jacobian at the optimum for the
    # covariance, the gradient test and the HAC below.
    if solver not in SOLVERS:
        raise CalibrationError(f"solver must be one of {', '.join(SOLVERS)}; got {solver!r}")
    res = fit_problem(problem, obs, nominal, solver=solver, max_steps=max_steps,
                      f1_start_hz=f1_start_hz, start=start,
                      host_work=lambda: (data_side(obs), recording_moments(obs)))  # fmt: skip
    (peak_refs, rates), moments = res.host_work_result
    problem, resid_w, jac, bread, s2 = res.problem, res.resid, res.jac, res.bread, res.s2
    cov = s2 * bread
    # The solver's own test (steps below rtol 1e-10 of every parameter) can stall at
    # rounding level on long real recordings (timestamps rounded to 1 µs: the same optimum,
    # 400 steps); MINPACK's gradient test says whether the point is stationary anyway.
    gcos = res.gcos
    status, ok = solve_status(res.ok, gcos, np.diag(cov), res.cost)

    optimum = res.optimum
    per_rec, curves, resid = recording_diagnostics(problem, optimum, obs, res.models, resid_w,
                                            peak_refs, moments)  # fmt: skip
    uncertainty = "white noise: s^2 (J^T J)^-1"
    cov_white = cov
    if ok:  # a sandwich where the residuals are correlated or their spread changes
        correlated = max(r["lag1_autocorr"] for r in per_rec) > LAG1_MAX
        cov, uncertainty = robust_covariance(
            recording_blocks(jac, resid_w, obs, correlated), bread, cov
        )
    tol = modulus_tolerance
    params, corr, fixed, note = _linear_params(
        record, problem, res.reported, cov, static, nominal, tol
    )
    if cov is not cov_white:
        white, *_ = _linear_params(record, problem, res.reported, cov_white, static, nominal, tol)
        for k in params:
            params[k]["std_white"] = white[k]["std"]
            # never below the white-noise 1σ, to the last digit (the floor is applied to the
            # covariance; the reported quantities' transform can round it an ulp under)
            params[k]["std"] = max(params[k]["std"], white[k]["std"])
    diagnostics = fit_diagnostics(per_rec, obs, res, resid, s2=s2, gcos=gcos,
                                  uncertainty=uncertainty)  # fmt: skip
    warnings = poor_fit_warnings(per_rec)
    checks = {}
    if ok:
        checks = check_fit(params, per_rec, float(np.asarray(nominal.natural_frequencies_hz)[0]),
                           decay_rates_hz=rates, f1_expected_hz=f1_start_hz)  # fmt: skip
    status, warnings = fit_status(status, ok, warnings, checks)
    out = Calibration(
        status=status,
        ok=ok,
        params=params,
        correlations=corr,
        fixed=fixed,
        note=note,
        diagnostics=diagnostics,
        per_recording=per_rec,
        record=record,
        solver=solver,
        curves=curves,
        warnings=warnings,
        checks=checks,
        problem=problem,
        optimum=optimum,
        covariance=cov,
    )
    out.record = record_with_fit(record, out, pin, static, obs, problem)
    if problem.limits:  # the amplitude test's steps assume the unlimited parameters
        _apply_limits(out, parameters)
        return out
    # amplitude dependence and the choice of model
    return choose_model(out, obs, model, nl_terms, resid=resid_w, jac=jac, core=res.amplitude,
                  free_modes=free_modes)  # fmt: skip


#: Reported quantities that follow from κ (f_1's parameter) or from ζ.
_FROM_ZETA = "zeta"


def _apply_limits(cal: Calibration, parameters: Parameters) -> None:
    """Mark what the user fixed or bounded: a fixed quantity (and what follows from it) has
    1σ 0, one at a bound has its 1σ refused (None), as lmfit refuses it."""
    limits = cal.problem.limits
    hit = at_bound(limits, cal.optimum)
    names = {"log_kappa": "f1_hz", "zeta_u": "zeta"}
    summary = {}
    for (param, fixed), (name, ulo, uhi) in zip(limits, _user_order(parameters, limits),
                                                  strict=True):  # fmt: skip
        value = cal.params[name]["value"]
        follows = [k for k in cal.params if k.startswith(_FROM_ZETA) == (param == "zeta_u")]
        if fixed:
            # its Jacobian column is zero: what follows from it alone already has 1σ 0 (ρa
            # under pin material keeps its modulus' share)
            entry = {"fixed": ulo, "value": value}
            p = cal.params[name]
            p.update({s: 0.0 for s in ("std", "std_white") if s in p})
            p["source"] = f"fixed by the user ({name} = {ulo:g})"
        else:
            entry = {"bounds": [ulo, uhi], "value": value, "at_bound": hit[param]}
            if hit[param]:
                side = "lower" if abs(value - ulo) <= abs(value - uhi) else "upper"
                reason = (f"{name} is at its {side} bound {ulo if side == 'lower' else uhi:g}: "
                          "its 1σ is refused (the data pull it outside the bounds)")  # fmt: skip
                entry["std_refused"] = reason
                cal.warnings.append(reason)
                for k in follows:
                    cal.params[k].update(
                        {s: None for s in ("std", "std_white") if s in cal.params[k]}
                    )
                    cal.params[k]["source"] = f"at the {side} bound of {name}"
        summary[names[param]] = entry
    cal.diagnostics["parameters"] = summary
    fit = cal.record.extra["fit"]
    fit["parameters"] = summary
    for k, v in cal.params.items():  # TOML has no null: a refused 1σ is left out
        fit["params"][k] = {kk: v[kk] for kk in ("value", "std", "source") if v[kk] is not None}
    fit["warnings"] = list(cal.warnings)


def _user_order(parameters: Parameters, limits) -> list[tuple[str, float, float]]:
    """The user's ``(name, lo, hi)`` in the order of the problem's sorted limits."""
    param_of = {"f1_hz": "log_kappa", "zeta": "zeta_u"}
    user = {param_of[n]: (n, lo, hi) for n, lo, hi in parameters.limits}
    return [user[p] for p, _ in limits]


def _check_model(model: str, obs, static, free_modes: bool, n_modes: int, added_mass) -> None:
    """Refuse a model the recordings (or the other arguments) cannot be fitted with."""
    if model not in ("linear", "nonlinear", "auto"):
        raise CalibrationError(f"model must be linear, nonlinear or auto, not {model!r}")
    if model == "nonlinear" and (static is not None or any(o.excitation != "decay" for o in obs)):
        raise CalibrationError(
            "the nonlinear model fits free decays only (no sine, base motion or static test); "
            "fit those with --model linear"
        )
    if free_modes:
        _check_free_modes(model, n_modes, static, obs)
    if added_mass is not None and model != "linear":
        raise CalibrationError(
            "the added-mass method fits the linear model; leave out --model (or give linear)"
        )


def _check_linear(obs, pin: str, n_modes: int, f1_start_hz) -> None:
    """Refuse a pin, a number of modes, samples or a start frequency no fit can use."""
    if pin not in PINS:
        raise CalibrationError(f"pin must be one of {PINS}, not {pin!r}")
    if not 1 <= n_modes <= 10:
        raise CalibrationError(f"n_modes = {n_modes} must be between 1 and 10")
    for o in obs:  # sums of squares of such samples overflow: no fit can be computed
        if float(np.max(np.abs(o.y))) > MAX_SAMPLE:
            raise CalibrationError(
                f"{o.name}: the samples reach {float(np.max(np.abs(o.y))):.3g}, too large to "
                "fit in any units (their squares overflow): scale the signal to the "
                "observable's units (--scale)"
            )
    if f1_start_hz is not None and not (np.isfinite(f1_start_hz) and f1_start_hz > 0):
        raise CalibrationError(
            f"the f1 to start from ({f1_start_hz!r} Hz, --f1-start) must be a positive "
            "frequency: give the frequency in Hz that the whisker rings at, or leave it out"
        )


def _check_free_modes(model: str, n_modes: int, static, obs) -> None:
    """Refuse ``free_modes`` where there is no nonlinear fit's higher mode to free."""
    if model == "linear":
        raise CalibrationError(
            "free modes belong to the nonlinear fit: give --model nonlinear (or auto) with "
            "--free-modes, or leave --free-modes out"
        )
    if n_modes < 2:
        raise CalibrationError(
            f"--free-modes frees modes 2 and up, but --modes is {n_modes}: give --modes 2 or more"
        )
    if static is not None or any(o.excitation != "decay" for o in obs):
        raise CalibrationError(
            "--free-modes fits free decays only (no sine, base motion or static test); "
            "leave it out for these recordings"
        )


def _linear_params(record, problem, reported, cov, static, nominal, modulus_tolerance=0.0):
    structure = record.structure
    pin = problem.pin
    values, jac = reported
    names = reported_names(problem)
    dcov = np.asarray(jac) @ cov @ np.asarray(jac).T
    if pin == "material" and static is None:  # ρa and C scale with the assumed modulus
        dcov = dcov + modulus_covariance(names, np.asarray(values), modulus_tolerance)
    std = reported_std(dcov)
    pinned = {"geometry": "rho_a", "material": "EI"}[pin]
    params = {}
    for i, name in enumerate(names):
        source = "fit"
        if static is not None and name in ("EI", "G_w"):
            source = "fit (static test)"
        elif name in ("EI", "C", "rho_a", "E", "G_w"):
            source = (
                "derived from kappa and the static test"
                if static is not None
                else f"derived from kappa and {pinned} ({pin})"
            )
        params[name] = {"value": float(values[i]), "std": float(std[i]), "source": source}
    fixed = {"length_m": float(nominal.length_m), "tip_mass_kg": float(nominal.tip_mass_kg)}
    coil = problem.kind == "coil"
    if static is None:
        if pin == "geometry":
            fixed["rho_a"] = float(nominal.rho_a)
            if coil:
                fixed["C"] = structure.coil_factor
        else:
            fixed["EI"] = float(nominal.EI)
            fixed["modulus_tolerance"] = float(modulus_tolerance)
    what = "f_1 (so kappa = EI/(rho a)) and zeta"
    if static is not None:
        note = (
            f"The vibration data determine {what}; the static test determines EI, so rho a"
            + (" and the coil factor C follow" if coil else " follows")
            + " from EI/kappa: both are reported as fitted."
        )
    elif pin == "geometry":
        note = (
            f"The vibration data determine only {what}. EI is derived as kappa * rho a with rho a "
            + (
                f"from the coil geometry (C = {structure.coil_factor:.4g} fixed, not fitted)"
                if coil
                else "from the section and density of the record"
            )
            + "; EI and C are not both identified without a static test or a material prior."
        )
    else:
        note = (
            f"The vibration data determine only {what}. EI is fixed at the record's material value "
            f"({float(nominal.EI):.4g} N m^2); rho a"
            + (" and C are" if coil else " is")
            + " derived from EI/kappa. EI and C are not both identified: "
            + ("C" if coil else "rho a")
            + f" rests on the assumed modulus, whose {100 * modulus_tolerance:.3g} % (1 sigma, "
            "--modulus-tolerance) is in its 1-sigma; plucks with and without a known tip "
            "mass (--added-mass) measure it instead."
        )
    if float(nominal.tip_mass_kg) > 0:  # a host comparison, not an eager JAX program
        note += (
            f" With the tip mass ({float(nominal.tip_mass_kg):.4g} kg) the mode ratios depend"
            " weakly on mu = M_t/(rho a l); mu was taken from the record."
            if static is None
            else ""
        )
    return params, correlation_table(names, dcov, std), fixed, note
