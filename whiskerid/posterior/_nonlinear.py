"""Posteriors of a nonlinear calibration: f₀, ζ₀ and the nonlinear coefficients.

A record fitted with ``--model nonlinear`` (``[fit] model = "nonlinear"``) is sampled in the
nonlinear fit's own parameters (:class:`whiskerid.fit.NonlinearProblem`): ``log κ`` (so f₀),
``logit ζ₀``, the scaled nonlinear terms ``nl`` (``g``: relative frequency rise at the
reference amplitude ``a_ref``; ``ζ_v``, ``ζ_c``: velocity-squared and friction damping ratios
at ``a_ref``), each recording's linear coefficients ``c`` and its noise ``log σ_j``.

The linear coefficients are *sampled*, not marginalised: mode 1's slow flow starts at the
amplitude ``a₀ = |(c_cos, c_sin)|``, so the design depends on ``c`` and the closed-form
integral of the linear model does not apply. The likelihood is the Gaussian (or Student-t) of
the residuals ``D(θ, c) c + g − y`` in the fit's normalised units. Priors: those of the record's
``[prior]`` table on ``zeta`` (ζ₀), ``f1_hz`` (f₀) or ``kappa`` and ``sigma_rel``, as for the
linear model, and flat priors on the three scaled coefficients (flat on the physical ones,
which are fixed multiples of them: ``γ = 8g/(3a_ref²)``, ``c = 3πζ_v/(4a_ref)``,
``F = πω₀²ζ_c a_ref/2``).

Reported: the nonlinear fit's quantities (``f1_hz`` and ``zeta`` at ``a → 0``, κ, EI or C,
``gamma_per_m2``, ``quadratic_per_m``, ``coulomb_m_s2`` for the terms fitted) and the backbone at
the smallest and largest amplitudes the calibration reported (``f_hz_at_a_min`` …
``zeta_at_a_max``; the amplitudes are in the provenance).
"""

from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..fit import calibrate
from ._likelihood import _log_prior, _pack, _unpack
from ._prior import PosteriorError, prior_arrays, prior_table
from ._problem import Problem, _names

#: The record's ``[fit.nonlinear]`` coefficient of each term.
_COEFFICIENTS = {"cubic": "gamma_per_m2", "quadratic": "quadratic_per_m",
                 "coulomb": "coulomb_m_s2"}  # fmt: skip


def is_nonlinear(record) -> bool:
    """Whether ``record`` holds a nonlinear calibration (``[fit] model = "nonlinear"``)."""
    return (record.extra.get("fit") or {}).get("model") == "nonlinear"


def fitted_terms(record) -> tuple[str, ...]:
    """The nonlinear terms the record's calibration fitted: those with a coefficient (a fitted
    value is never exactly zero; a term left out is stored as 0)."""
    nl = (record.extra.get("fit") or {}).get("nonlinear") or {}
    terms = tuple(t for t, key in _COEFFICIENTS.items() if float(nl.get(key, 0.0)) != 0.0)
    return terms or tuple(_COEFFICIENTS)


@dataclass(frozen=True)
class _NonlinearModel:
    """Static description of the nonlinear log-probability (the jit key)."""

    n_theta: int
    n_rec: int
    likelihood: str
    priors: tuple[tuple[str, str], ...]
    marginal: bool = False  # the linear coefficients are always sampled here

    @property
    def ndim(self) -> int:
        return self.n_theta + self.n_rec


def log_prob_nonlinear(model: _NonlinearModel, z, args):
    """Log-posterior (up to a constant) at one point ``z`` of the sampled space."""
    problem = args["problem"]
    theta = problem.unflatten(z[: model.n_theta])
    log_sigma = z[model.n_theta :]
    lp = _log_prior(model, theta, problem.base.whisker(theta), log_sigma, args)
    designs = problem.design(theta)
    recs = zip(designs, problem.base.recordings, theta["recs"], strict=True)
    for j, ((D, g, _), rec, p) in enumerate(recs):
        z_j = (D @ p["c"] + g - rec.y) / jnp.exp(log_sigma[j])
        n = rec.y.shape[0]
        if model.likelihood == "gaussian":
            lp = lp - n * log_sigma[j] - 0.5 * jnp.sum(z_j**2)
        else:
            nu = args["nu"]
            const = (jax.scipy.special.gammaln((nu + 1) / 2) - jax.scipy.special.gammaln(nu / 2)
                     - 0.5 * jnp.log(nu * jnp.pi))  # fmt: skip
            lp = lp + n * (const - log_sigma[j]) - 0.5 * (nu + 1) * jnp.sum(jnp.log1p(z_j**2 / nu))
    return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)


_COMPILED: dict = {}
#: The backbone's names in :meth:`NonlinearProblem.reported` at the two amplitudes.
_BACKBONE_NAMES = {
    "backbone_f_0": "f_hz_at_a_min",
    "backbone_f_1": "f_hz_at_a_max",
    "backbone_zeta_0": "zeta_at_a_min",
    "backbone_zeta_1": "zeta_at_a_max",
}


def _batch_fn(model, layout):
    """Jitted, vmapped :func:`log_prob_nonlinear` ``(z, packed args) → (walkers,)``."""
    fn = _COMPILED.get((model, layout))
    if fn is None:

        def call(zz, flat):
            a = _unpack(layout, flat)
            return jax.vmap(lambda v: log_prob_nonlinear(model, v, a))(zz)

        fn = jax.jit(call)
        if len(_COMPILED) > 16:
            _COMPILED.clear()
        _COMPILED[model, layout] = fn
    return fn


@dataclass
class NonlinearPosteriorProblem(Problem):
    """A :class:`Problem` of the nonlinear model (from :func:`setup_posterior` on a record
    fitted with ``--model nonlinear``).

    Attributes:
        amplitudes_m: The smallest and largest amplitudes (mode 1 tip, m) at which the
            backbone is reported.
    """

    amplitudes_m: tuple[float, float] = (0.0, 0.0)

    def _batch(self):
        if self._compiled is None or self._compiled[0] is not self.args:
            layout, flat = _pack(self.args)
            self._compiled = (self.args, _batch_fn(self.model, layout), flat)
        return self._compiled[1], self._compiled[2]

    def derived_quantities(self, z: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """Reported quantities at points ``z`` (see the module docstring)."""
        problem = self.args["problem"]
        amps = jnp.asarray(self.amplitudes_m)
        flat = jnp.asarray(np.asarray(z)[:, : self.model.n_theta])
        names = list(problem.reported(problem.unflatten(flat[0]), amps))
        vals = np.asarray(_derived_batch(problem, flat, amps))
        names = [_BACKBONE_NAMES.get(n, n) for n in names]
        sig = np.exp(np.asarray(z)[:, self.model.n_theta :]) * np.asarray(self.y_std)
        names += [f"sigma_{j + 1}" for j in range(self.model.n_rec)]
        return np.concatenate([vals, sig], axis=1), names


@eqx.filter_jit
def _derived_batch(problem, flat, amps):
    def one(v):
        return jnp.stack(list(problem.reported(problem.unflatten(v), amps).values()))

    return jax.vmap(one)(flat)


def setup_nonlinear(record, obs, *, n_modes, pin, likelihood, nu, marginalize, user_prior,
                    f1_start_hz, nl_terms=None) -> NonlinearPosteriorProblem:  # fmt: skip
    """The nonlinear calibration (its Laplace approximation) and the log-posterior around it.

    Args: as :func:`whiskerid.posterior.setup_posterior` (``user_prior``: the parsed
    ``[prior]`` table); ``nl_terms``: the terms to sample (the record's by default).
    """
    if ((record.extra.get("fit") or {}).get("nonlinear") or {}).get("backbone_model"):
        raise PosteriorError(
            "this record's backbone is an identified log-polynomial curve, which posterior "
            "does not sample: calibrate with the parametric nonlinear model to sample it"
        )
    if ((record.extra.get("fit") or {}).get("nonlinear") or {}).get("free_modes"):
        raise PosteriorError(
            "this record's nonlinear fit has free higher modes (calibrate --free-modes), which "
            "posterior does not sample: use the calibration's 1-sigma, or calibrate without "
            "--free-modes to sample f1, zeta and the nonlinear terms"
        )
    if marginalize:
        raise PosteriorError(
            "the nonlinear model's design depends on its amplitudes (its linear coefficients), "
            "so they cannot be marginalised: leave marginalize unset (they are sampled)"
        )
    terms = tuple(nl_terms) if nl_terms else fitted_terms(record)
    cal = calibrate(record, obs, n_modes=n_modes, pin=pin, f1_start_hz=f1_start_hz,
                    model="nonlinear", nl_terms=terms)  # fmt: skip
    if not cal.ok or cal.problem is None:
        raise PosteriorError(
            f"the nonlinear calibration of these recordings did not converge ({cal.status}): "
            "calibrate them with --model nonlinear first and check its report"
        )
    problem = cal.problem
    cov = np.asarray(cal.covariance)
    flat = np.asarray(problem.flatten(cal.optimum))
    if not np.all(np.isfinite(cov)):
        cov = np.diag((1e-4 * np.maximum(np.abs(flat), 1e-2)) ** 2)
    sig = np.array([1.0 / float(r.weight) for r in problem.base.recordings])
    n_theta, n_rec = flat.size, len(obs)
    n_samples = np.array([o.t.size for o in obs], float)
    z0 = np.concatenate([flat, np.log(sig)])
    cov_z = np.zeros((n_theta + n_rec,) * 2)
    cov_z[:n_theta, :n_theta] = cov
    cov_z[n_theta:, n_theta:] = np.diag(1.0 / (2 * n_samples))
    names = _names(cal.optimum, n_rec)
    names = [_term_name(n, problem.terms) for n in names]
    f1_hat = float(cal.params["f1_hz"]["value"])
    priors = prior_table(f1_hat, user_prior)
    priors["nl"] = {"dist": "flat", "terms": list(problem.terms), "default": True}
    sampled = {k: p for k, p in priors.items() if k != "nl"}
    args = {
        "problem": problem,
        "prior": prior_arrays(sampled),
        "nu": jnp.asarray(float(nu)),
    }
    model = _NonlinearModel(
        n_theta=n_theta,
        n_rec=n_rec,
        likelihood=likelihood,
        priors=tuple((k, p["dist"]) for k, p in sampled.items()),
    )
    amps = cal.backbone["amplitude_m"]
    return NonlinearPosteriorProblem(
        model=model, args=args, z0=z0, cov=cov_z, names=names, priors=priors,
        observations=list(obs), record=record, pin=pin,
        y_std=[float(np.std(o.y)) for o in obs], nu=float(nu), calibration=cal.params,
        amplitudes_m=(float(amps[0]), float(amps[-1])),
    )  # fmt: skip


def _term_name(name: str, terms) -> str:
    """``nl[i]`` (or ``nl`` for one term) → ``nl.<term>``: the scaled coefficient's name."""
    if name == "nl":
        return f"nl.{terms[0]}"
    if name.startswith("nl["):
        return f"nl.{terms[int(name[3:-1])]}"
    return name
