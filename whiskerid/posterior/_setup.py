"""Set-up of a posterior: the calibration's Laplace approximation, the priors, the grids."""

import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from .._choices import LIKELIHOODS
from ..fit import Observation, calibrate
from ..model import WhiskerRecord
from ._grid import _TAYLOR_MARGIN, _decay_grid, _taylor_degree
from ._likelihood import _drop_c, _Model
from ._nonlinear import is_nonlinear, setup_nonlinear
from ._prior import PosteriorError, parse_prior, prior_arrays, prior_table
from ._problem import Problem, _names


# --------------------------------------------------------------------------- setup
def setup_posterior(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    static=None,
    n_modes: int | None = None,
    zeta_per_mode: bool = False,
    pin: str = "auto",
    likelihood: str = "gaussian",
    nu: float = 4.0,
    marginalize: bool | None = None,
    prior: dict | None = None,
    f1_start_hz: float | None = None,
    added_mass: list | None = None,
    nl_terms: tuple[str, ...] | None = None,
) -> Problem:
    """Fit the calibration model (its Laplace approximation) and build the log-posterior.

    Args:
        record: The whisker's record (a calibrated one from ``whiskerid calibrate`` is a
            good start); its ``[prior]`` table is used unless ``prior`` is given.
        observations: Recordings of this whisker, sampled jointly.
        static: Optional static test (as in :func:`whiskerid.calibrate`).
        n_modes: Modes in the model; the record's ``[fit] n_modes`` (else 1) by default.
        zeta_per_mode: One ζ per mode.
        pin: What fixes EI or C (``auto``/``geometry``/``material``).
        likelihood: ``gaussian`` or ``student``.
        nu: Student-t degrees of freedom.
        marginalize: Marginalise the linear coefficients analytically (Gaussian only; the
            default there); ``False`` samples them.
        prior: A ``[prior]`` table overriding the record's.
        f1_start_hz: Centre of the calibration's start search (the record's f_1 otherwise).
        added_mass: One :class:`whiskerid.fit.AddedMass` (or None) per recording: sample the
            added-mass model (EI and ρa fitted, each mass under its stated Gaussian prior),
            as :func:`whiskerid.calibrate` fits it.
        nl_terms: For a record fitted with ``--model nonlinear``: the nonlinear terms to
            sample (the record's by default). Such a record is sampled in the nonlinear
            model's parameters (f₀, ζ₀, the nonlinear coefficients; the linear coefficients
            sampled, not marginalised): see :mod:`whiskerid.posterior._nonlinear`.

    Returns:
        A :class:`Problem`.
    """
    obs = [observations] if isinstance(observations, Observation) else list(observations)
    if not obs:
        raise PosteriorError("no recordings")
    if likelihood not in LIKELIHOODS:
        raise PosteriorError(f"likelihood must be one of {LIKELIHOODS}, not {likelihood!r}")
    nonlinear = is_nonlinear(record)
    if nonlinear and (static is not None or added_mass is not None):
        raise PosteriorError(
            "the record holds a nonlinear calibration, which fits free decays only: sample a "
            "static test or added masses on a record calibrated with --model linear"
        )
    if marginalize is None:
        marginalize = likelihood == "gaussian" and not nonlinear
    if marginalize and likelihood != "gaussian":
        raise PosteriorError("only the Gaussian likelihood can marginalise the linear nuisances")
    if not nu > 0:
        raise PosteriorError("nu must be > 0")
    fit = record.extra.get("fit", {})
    n_modes = int(n_modes or fit.get("n_modes", 1))
    if pin == "auto" and fit.get("pin") in ("geometry", "material"):
        pin = fit["pin"]
    pin = "geometry" if pin == "auto" else pin
    table = prior if prior is not None else record.extra.get("prior")
    user = parse_prior(table)
    if nonlinear:
        return setup_nonlinear(record, obs, n_modes=n_modes, pin=pin, likelihood=likelihood,
                               nu=nu, marginalize=marginalize, user_prior=user,
                               f1_start_hz=f1_start_hz, nl_terms=nl_terms)  # fmt: skip

    problem, theta_hat, cov_full, sig, cal_params = _laplace(
        record, obs, static, n_modes, zeta_per_mode, pin, f1_start_hz, added_mass
    )
    # Sampled space: the calibration's flat vector (without c when marginalised) + log σ_j.
    idx_tree = problem.unflatten(jnp.arange(cov_full.shape[0], dtype=float))
    if marginalize:
        theta_s, idx_tree = _drop_c(theta_hat), _drop_c(idx_tree)
    else:
        theta_s = theta_hat
    flat_s = ravel_pytree(theta_s)[0]
    idx = np.asarray(ravel_pytree(idx_tree)[0]).astype(int)
    n_theta = int(flat_s.size)
    n_rec = len(obs)
    n_samples = np.array([o.t.size for o in obs], float)
    z0 = np.concatenate([np.asarray(flat_s), np.log(sig)])
    cov = np.zeros((n_theta + n_rec,) * 2)
    cov[:n_theta, :n_theta] = cov_full[np.ix_(idx, idx)]
    cov[n_theta:, n_theta:] = np.diag(1.0 / (2 * n_samples))
    names = _names(theta_s, n_rec)

    w_hat = problem.whisker(theta_s)
    f1_hat = float(w_hat.natural_frequencies_hz[0])
    priors = prior_table(f1_hat, user)
    # Free decays on near-uniform timestamps get the gridded columns, with Taylor degrees
    # for the Laplace centre's frequencies (times a margin).
    grids, grid_degrees = [], []
    for j, rec in enumerate(problem.recordings):
        omega_hat = np.asarray(problem.whisker_of(theta_s, j).omega_rad_s)
        degrees, grid_arrays = None, None
        if rec.excitation == "decay" and np.size(rec.t) >= 16:
            grid = _decay_grid(np.asarray(rec.t), np.asarray(rec.y))
            deg = [_taylor_degree(_TAYLOR_MARGIN * om * grid["dmax"]) for om in omega_hat]
            if None not in deg:
                degrees = tuple(deg)
                grid_arrays = {k: jnp.asarray(v) for k, v in grid.items()}
        grids.append(grid_arrays)
        grid_degrees.append(degrees)
    args = {
        "problem": problem,
        "grids": grids,
        "prior": prior_arrays(priors),
        "nu": jnp.asarray(float(nu)),
    }
    model = _Model(
        n_theta=n_theta,
        n_rec=n_rec,
        likelihood=likelihood,
        marginal=bool(marginalize),
        priors=tuple((k, p["dist"]) for k, p in priors.items()),
        grid_degrees=tuple(grid_degrees),
    )
    return Problem(
        model=model,
        args=args,
        z0=z0,
        cov=cov,
        names=names,
        priors=priors,
        observations=obs,
        record=record,
        pin=pin,
        y_std=[float(np.std(o.y)) for o in obs],
        nu=float(nu),
        calibration=cal_params,
    )


def _laplace(record, obs, static, n_modes, zeta_per_mode, pin, f1_start_hz, added_mass=None):
    """The calibration fit: its problem (recordings weighted by their residual scale), the
    optimum, its covariance (a small diagonal one where that is not finite), each
    recording's residual scale σ_j in normalised units and the calibration's reported
    quantities."""
    cal = calibrate(
        record,
        obs,
        static=static,
        n_modes=n_modes,
        zeta_per_mode=zeta_per_mode,
        pin=pin,
        f1_start_hz=f1_start_hz,
        added_mass=added_mass,
    )
    problem, cov = cal.problem, np.asarray(cal.covariance)
    if not np.all(np.isfinite(cov)):
        flat = np.asarray(problem.flatten(cal.optimum))
        scale = 1e-4 * np.maximum(np.abs(flat), 1e-2)
        cov = np.diag(scale**2)
    sig = np.array([1.0 / float(r.weight) for r in problem.recordings])
    return problem, cal.optimum, cov, sig, cal.params
