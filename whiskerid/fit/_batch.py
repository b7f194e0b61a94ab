"""Many single-recording calibrations of one shape at once (one compiled, batched program).

A fleet records the same kind of pluck on many whiskers: each pluck's fit is the same
program on other numbers (a :class:`whiskerid.fit.FitProblem`'s whisker, sensor and data are
traced leaves), so the fits of one shape are stacked along a leading axis and solved together
by ``vmap`` of calibrate's own least squares (the same solver, tolerances and convergence
tests: module ``_core``'s ``solve``), from the start values :func:`whiskerid.fit.calibrate`
would use (:func:`whiskerid.fit.start_values`). A batch has a fixed number of lanes (the last one
filled with copies of its last fit) so that one program serves every batch of a shape.

Each fit gets its own status, decided by calibrate's own rules (module ``_core``'s
``solve_status``, then ``_calibrate``'s ``fit_status``): a fit that fails to converge or gives
non-finite numbers marks only its own lane; ``ok`` when converged with a finite covariance,
``poor fit`` when the model explains little of the signal, else ``check`` when one of
calibrate's checks of the converged fit fails (correlated residuals, a line left in them, ζ
at a bound or implausible, f_1 far from the record's, imprecise values, mode 1 silent). Only
the values that change detection needs are kept (f_1, ζ and their 1σ from ``s²(JᵀJ)⁻¹``).
Unlike calibrate, the fit is not solved a second time after the recording's residual scale
is known: for one recording that scale is one factor on every residual, which leaves the
optimum and ``s²(JᵀJ)⁻¹`` unchanged.
"""

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._choices import PINS
from ..model import WhiskerRecord
from ._checks import check_fit, lag1, residual_peak
from ._checks import decay_sampling_rates_hz as decay_rates
from ._data import CalibrationError, Observation
from ._linear import FitProblem, flat_residuals, reported_names, solve_status, start_values
from ._linear import solve_masked as solve
from ._numerics import lsq
from ._result import fit_status, poor_fit_warnings

#: Lanes of one batched program (fits of one shape solved together).
BATCH_LANES = 16


@dataclass(frozen=True)
class PluckFit:
    """One recording's fit from :func:`calibrate_each`.

    Attributes:
        status: ``ok``, ``check``, ``poor fit``, ``not converged``, ``non-finite``, or
            ``error`` (the recording could not be set up as a fit; see ``message``).
        f1_hz: Fitted f_1 (Hz; NaN for ``error``).
        zeta: Fitted ζ (NaN for ``error``).
        f1_std: 1σ of f_1 (white noise).
        zeta_std: 1σ of ζ (white noise).
        steps: Solver steps.
        checks: The failed checks of a converged fit, name → sentence.
        optimum: The parameter pytree at the optimum (None for ``error``).
        message: Why a fit could not be set up (``error``), else empty.
    """

    status: str
    f1_hz: float
    zeta: float
    f1_std: float = float("nan")
    zeta_std: float = float("nan")
    steps: int = 0
    checks: dict | None = None
    optimum: Any = None
    message: str = ""


def stack_problems(problems: list[FitProblem]) -> FitProblem:
    """Problems of one structure and shape as one problem with a leading batch axis.

    Raises:
        ValueError: The problems differ in structure or shapes.
    """
    keys = {problem_shape(p) for p in problems}
    if len(keys) != 1:
        raise ValueError("problems of different structures or shapes cannot be stacked")
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *problems)


def problem_shape(problem: FitProblem) -> tuple:
    """What must match for problems to share one compiled program: the pytree's structure
    (the static fields included) and the shapes and types of its leaves."""
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    return treedef, tuple(
        (np.shape(x), str(getattr(x, "dtype", np.asarray(x).dtype))) for x in leaves
    )


def calibrate_each(
    items: list[tuple[WhiskerRecord, Observation]],
    *,
    n_modes: int = 2,
    pin: str = "auto",
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    lanes: int = BATCH_LANES,
) -> list[PluckFit]:
    """Calibrate each recording on its own (its record's whisker), fits of one shape batched.

    Args:
        items: ``(record, observation)`` pairs, each fitted on its own.
        n_modes: Modes in the model.
        pin: What fixes EI or C (``auto``, ``geometry``, ``material``).
        solver: Least-squares solver.
        max_steps: Solver step limit.
        lanes: Fits per batched program (the last batch of a shape is padded).

    Returns:
        One :class:`PluckFit` per item, in order; never raises for a bad recording or a
        failed fit (see ``status``).
    """
    if pin not in PINS:
        raise CalibrationError(f"pin must be one of {PINS}, not {pin!r}")
    if solver not in lsq.SOLVERS:
        raise CalibrationError(f"solver must be one of {', '.join(lsq.SOLVERS)}; got {solver!r}")
    pin = "geometry" if pin == "auto" else pin
    out: list[PluckFit | None] = [None] * len(items)
    groups: dict[tuple, list] = {}
    for i, (record, obs) in enumerate(items):
        try:
            problem = FitProblem.from_observations(record, [obs], n_modes=n_modes, pin=pin)
            nominal = record.whisker().with_modes(n_modes)
            theta0 = start_values(problem, [obs], nominal)
        except (CalibrationError, ValueError) as err:
            nan = float("nan")
            out[i] = PluckFit("error", nan, nan, message=" ".join(str(err).split()))
            continue
        f1_nominal = float(nominal.natural_frequencies_hz[0])
        groups.setdefault(problem_shape(problem), []).append(
            (i, problem, problem.flatten(theta0), obs, f1_nominal)
        )
    for group in groups.values():
        for k in range(0, len(group), lanes):
            chunk = group[k : k + lanes]
            padded = chunk + [chunk[-1]] * (lanes - len(chunk))
            batch = _fit_batch(
                stack_problems([g[1] for g in padded]),
                jnp.stack([g[2] for g in padded]),
                solver,
                max_steps,
            )
            batch = jax.tree_util.tree_map(np.asarray, batch)
            names = reported_names(chunk[0][1])
            for lane, (i, problem, _, obs, f1_nominal) in enumerate(chunk):
                one = {key: v[lane] for key, v in batch.items()}
                out[i] = _pluck_fit(problem, obs, one, names, f1_nominal)
    return out


@eqx.filter_jit
def _fit_batch(problems, flat0, solver, max_steps):
    def one(problem, y0):
        # calibrate's own solve (same solver, tolerances and tests): no padding rows
        masks = [jnp.ones(r.t.shape[0]) for r in problem.recordings]
        value, ok, steps = solve(problem, masks, y0, solver=solver, max_steps=max_steps)
        resid, jac = flat_residuals(value, problem), jax.jacfwd(flat_residuals)(value, problem)
        cov = lsq.residual_variance(resid, value.size) * lsq.scaled_inverse_gram(jac)

        def reported(flat):
            return jnp.stack(list(problem.reported(problem.unflatten(flat)).values()))

        rjac = jax.jacfwd(reported)(value)
        ((design, fixed),) = problem.design(problem.unflatten(value))
        return {
            "value": value,
            "ok": ok,
            "steps": steps,
            "cost": 0.5 * jnp.sum(resid**2),
            "gcos": lsq.gradient_cosine_from(jac, resid),
            "cov_diag": jnp.diag(cov),
            "reported": reported(value),
            "reported_var": jnp.einsum("ij,jk,ik->i", rjac, cov, rjac),
            "design": design,
            "fixed": fixed,
        }

    return eqx.filter_vmap(one)(problems, flat0)


def _pluck_fit(problem: FitProblem, obs: Observation, b: dict, names, f1_nominal) -> PluckFit:
    """One lane of a batch as calibrate would judge it (see the module docstring)."""
    status, ok = solve_status(b["ok"], float(b["gcos"]), b["cov_diag"], float(b["cost"]))
    optimum = problem.unflatten(jnp.asarray(b["value"]))
    std = np.sqrt(np.maximum(b["reported_var"], 0.0))
    params = {n: {"value": float(v), "std": float(s)}
              for n, v, s in zip(names, b["reported"], std, strict=True)}  # fmt: skip
    checks: dict = {}
    if ok:  # calibrate's rule (fit_status): a poor fit first, else its checks' verdict
        per_rec = _recording_diagnostics(problem, obs, b, np.asarray(optimum["recs"][0]["c"]))
        checks = check_fit(params, [per_rec], f1_nominal, decay_rates_hz=decay_rates([obs]))
        status, _ = fit_status(status, ok, poor_fit_warnings([per_rec]), checks)
    return PluckFit(
        status=status,
        f1_hz=params["f1_hz"]["value"],
        zeta=params["zeta"]["value"],
        f1_std=params["f1_hz"]["std"],
        zeta_std=params["zeta"]["std"],
        steps=int(b["steps"]),
        checks=checks,
        optimum=optimum,
    )


def _recording_diagnostics(problem: FitProblem, obs: Observation, b: dict, c) -> dict:
    """What the checks read of a recording's residuals (as calibrate reports them)."""
    design = b["design"]
    y_std = float(np.std(obs.y))
    r = obs.y - ((design @ c + b["fixed"]) * y_std + float(np.mean(obs.y)))
    rms = float(np.sqrt(np.mean(r**2)))
    nm = problem.n_modes
    cols = design[:, 2 : 2 + 2 * nm] * c[2 : 2 + 2 * nm]
    modal = cols[:, :nm] + cols[:, nm:]
    return {
        "name": obs.name,
        "excitation": obs.excitation,
        "snr_db": float(20 * np.log10(y_std / max(rms, 1e-300))),
        "lag1_autocorr": lag1(r),
        "residual_peak": residual_peak(obs.t, r, obs.y),
        "modal_rms": [float(v) for v in np.sqrt(np.mean(modal**2, axis=0)) * y_std],
    }
