"""Results of a run: diagnostics from the autocorrelation time, burn-in, thinning, the
reported quantities' summaries and the record's ``[posterior]`` table."""

import datetime
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..fit import reported_names, sha256_of
from ..model import WhiskerRecord
from ._agreement import calibration_agreement
from ._arviz import by_chain, inference_data
from ._arviz import diagnostics as arviz_diagnostics
from ._likelihood import _unravel
from ._predictive import observed, predictive_draws
from ._problem import Problem

#: Simulated recordings kept for the posterior-predictive check (all chains together).
N_PREDICTIVE = 100


# --------------------------------------------------------------------------- results
@dataclass
class Posterior:
    """Outcome of :func:`sample_posterior`.

    Attributes:
        params: Reported quantity → ``median, q16, q84, q2.5, q97.5, mean, std, tau, ess``
            (and ``rhat``, ``ess_bulk``, ``ess_tail`` from ArviZ with several chains).
        diagnostics: ``converged``, ``steps``, ``steps_needed``, ``walkers``, ``burn``,
            ``thin``, ``acceptance`` (mean), ``acceptance_min``, ``tau`` per sampled
            coordinate, ``max_tau``, ``log_prob_evals``, ``message``.
        correlations: ``{"names", "matrix"}`` of the reported quantities.
        samples: Burnt-in, thinned samples of the reported quantities ``(n, p)``.
        names: Their names.
        chain: The full chain in the sampled space ``(steps, walkers, ndim)``; with several
            independent ensembles (chains) their walkers side by side, chain after chain.
        chain_names: Names of the sampled coordinates.
        record: The record with a ``[posterior]`` table.
        provenance: Seed, sampler, likelihood, priors, data files with SHA-256, version.
        derived_chain: The reported quantities along the full chain ``(steps, walkers, p)``.
        log_prob: The log-posterior along the chain ``(steps, walkers)``.
        acceptance_fraction: Each walker's acceptance fraction ``(walkers,)``.
        n_chains: Independent ensembles run (their walkers are ``chain``'s, in order).
        calibration: The calibration the run started from, beside it
            (:func:`~whiskerid.posterior._agreement.calibration_agreement`): its ``status``,
            its warnings repeated, the ``width_ratio`` of each quantity (posterior 68 %
            half-width / calibrate's 1σ) and ``warnings`` (those, and any width narrower by
            more than 1.5×).
        predictive: ``{"t", "observed", "draws"}``: per recording its timestamps, its data and
            simulated recordings ``(draws, samples)`` at posterior draws (observed units);
            None until :meth:`predictive_draws` (or ``summarize(n_predictive=...)``) makes them.
        problem: The problem sampled (for :meth:`predictive_draws`).
    """

    params: dict[str, dict]
    diagnostics: dict[str, Any]
    correlations: dict[str, Any]
    samples: np.ndarray
    names: list[str]
    chain: np.ndarray = field(repr=False)
    chain_names: list[str] = field(default_factory=list)
    record: WhiskerRecord | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    derived_chain: np.ndarray | None = field(default=None, repr=False)
    log_prob: np.ndarray | None = field(default=None, repr=False)
    acceptance_fraction: np.ndarray | None = field(default=None, repr=False)
    n_chains: int = 1
    predictive: dict | None = field(default=None, repr=False)
    calibration: dict = field(default_factory=dict)
    problem: Problem | None = field(default=None, repr=False)

    def predictive_draws(self, n: int = N_PREDICTIVE) -> dict:
        """Simulated recordings at ``n`` posterior draws (:attr:`predictive`), made on first
        call (they compile the design for a batch of draws: seconds, so not on every run)."""
        if self.predictive is None:
            if self.problem is None:
                raise ValueError("this posterior keeps no problem to simulate recordings from")
            kept = self.chain[self.diagnostics["burn"] :: self.diagnostics["thin"]]
            seed = self.provenance.get("seed", 0)
            self.predictive = _predictive(self.problem, kept, self.n_chains, n, seed)
        return self.predictive

    def to_arviz(self):
        """The run as ArviZ ``InferenceData`` (needs ``whiskerid[arviz]``): groups
        ``posterior`` (the reported quantities), ``sample_stats`` (``lp``,
        ``acceptance_rate``), ``observed_data`` and ``posterior_predictive``; one ``chain`` per
        independent ensemble (see :mod:`whiskerid.posterior._arviz`)."""
        return inference_data(self)

    def to_json(self) -> dict:
        """The JSON summary (``whiskerid posterior --json``); a number that could not be
        estimated (τ and ESS of a chain too short) is null, never NaN."""
        return finite_or_none(
            {
                "converged": self.diagnostics["converged"],
                "params": self.params,
                "tau": self.diagnostics["tau"],
                "acceptance": self.diagnostics["acceptance"],
                "ess": {k: v["ess"] for k, v in self.params.items()},
                "diagnostics": self.diagnostics,
                "correlations": self.correlations,
                "provenance": self.provenance,
                "calibration": self.calibration,
                "width_ratio": self.calibration.get("width_ratio", {}),
                "warnings": self.calibration.get("warnings", []),
                **(
                    {
                        k: {n: v[k] for n, v in self.params.items()}
                        for k in ("rhat", "ess_bulk", "ess_tail")
                    }
                    if self.n_chains > 1
                    else {}
                ),
            }
        )


def finite_or_none(obj):
    """``obj`` with every non-finite float replaced by None (JSON's null): NaN is not JSON,
    and an estimate that does not exist must read as absent, not as a number."""
    if isinstance(obj, dict):
        return {k: finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_or_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def without_none(obj):
    """``obj`` without the None values of its tables (TOML has no null): an estimate that
    does not exist is left out of the record, and so is a list (a correlation matrix)
    holding one."""
    if isinstance(obj, dict):
        kept = {k: without_none(v) for k, v in obj.items()}
        return {k: v for k, v in kept.items() if v is not None}
    if isinstance(obj, list):
        items = [without_none(v) for v in obj]
        return None if any(v is None for v in items) else items
    return obj


def derived_quantities(prob: Problem, z: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Reported quantities (f_1, ζ, κ, EI or C …, σ per recording) at points ``z``."""
    if hasattr(prob, "derived_quantities"):  # the nonlinear model's (its own names)
        return prob.derived_quantities(z)
    m = prob.model
    problem = prob.args["problem"]
    names = reported_names(problem)
    vals = np.asarray(
        _derived_batch(problem, m.marginal, jnp.asarray(np.asarray(z)[:, : m.n_theta]))
    )
    sig = np.exp(np.asarray(z)[:, m.n_theta :]) * np.asarray(prob.y_std)
    names += [f"sigma_{j + 1}" for j in range(m.n_rec)]
    return np.concatenate([vals, sig], axis=1), names


@eqx.filter_jit
def _derived_batch(problem, marginal, z):
    unravel = _unravel(problem, marginal)
    return jax.vmap(lambda v: jnp.stack(list(problem.reported(unravel(v)).values())))(z)


def _tau(x: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time of a chain ``(steps, walkers, ndim)`` (quiet)."""
    import logging

    import emcee

    log = logging.getLogger("emcee.autocorr")
    level = log.level
    log.setLevel(logging.ERROR)  # the "shorter than 50 tau" verdict is reported by us
    try:
        return np.asarray(emcee.autocorr.integrated_time(x, quiet=True), float)
    except Exception:  # too short for any estimate
        return np.full(x.shape[2], np.nan)
    finally:
        log.setLevel(level)


def summarize(
    prob: Problem, sampler, *, seed: int | None = None, n_predictive: int = 0
) -> Posterior:
    """Diagnostics, burn-in and thinning from τ, and the summary of the reported quantities.

    Args:
        prob: The problem sampled.
        sampler: An emcee sampler, or a list of them (independent ensembles of the same
            walkers and steps: their walkers are pooled, and ArviZ gives R-hat and bulk and
            tail ESS of each reported quantity across them).
        seed: For the provenance and the posterior-predictive draws.
        n_predictive: Simulated recordings to make now (0: on demand, by
            :meth:`Posterior.predictive_draws`).
    """
    samplers = list(sampler) if isinstance(sampler, list | tuple) else [sampler]
    n_chains = len(samplers)
    chain = np.concatenate([s.get_chain() for s in samplers], axis=1)
    log_prob = np.concatenate([s.get_log_prob() for s in samplers], axis=1)
    steps, walkers, ndim = chain.shape
    tau = _tau(chain)
    max_tau = float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else float("nan")
    finite_tau = np.isfinite(max_tau)
    burn = math.ceil(2 * max_tau) if finite_tau else steps // 2
    burn = min(burn, steps - 1)
    min_tau = float(np.nanmin(tau)) if finite_tau else 2.0
    thin = max(1, int(0.5 * min_tau))
    needed = math.ceil(50 * max_tau) if finite_tau else None
    converged = bool(finite_tau and steps >= needed)
    acc = np.concatenate([np.asarray(s.acceptance_fraction) for s in samplers])
    derived_full, names = derived_quantities(prob, chain.reshape(-1, ndim))
    derived_full = derived_full.reshape(steps, walkers, -1)
    tau_d = _tau(derived_full)
    kept = derived_full[burn::thin].reshape(-1, derived_full.shape[2])
    params = {}
    for i, name in enumerate(names):
        x = kept[:, i]
        q = np.percentile(x, [2.5, 16, 50, 84, 97.5])
        t_i = float(tau_d[i])
        ess = walkers * (steps - burn) / t_i if np.isfinite(t_i) and t_i > 0 else float("nan")
        params[name] = {
            "median": float(q[2]),
            "q16": float(q[1]),
            "q84": float(q[3]),
            "q2.5": float(q[0]),
            "q97.5": float(q[4]),
            "mean": float(np.mean(x)),
            "std": float(np.std(x)),
            "tau": t_i,
            "ess": float(ess),
        }
    if n_chains > 1:
        per_chain = by_chain(derived_full[burn::thin], n_chains)
        found = arviz_diagnostics({n: per_chain[..., i] for i, n in enumerate(names)})
        for name in names:
            params[name].update(found[name])
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.corrcoef(kept.T) if kept.shape[0] > 2 else np.eye(len(names))
    if not finite_tau:
        msg = f"not converged: {steps} steps are too few for any estimate of tau"
    elif converged:
        msg = f"converged: {steps} steps >= 50 max tau = {needed}"
    else:
        msg = (
            f"not converged: {steps} steps < 50 max tau = {needed}; run at least {needed} "
            f"steps (e.g. resume with {needed - steps} more)"
        )
    diagnostics = {
        "converged": converged,
        "message": msg,
        "steps": int(steps),
        "steps_needed": needed,
        "walkers": int(walkers),
        "burn": int(burn),
        "thin": int(thin),
        "n_samples": int(kept.shape[0]),
        "acceptance": float(np.mean(acc)),
        "acceptance_min": float(np.min(acc)),
        "tau": {n: float(t) for n, t in zip(prob.names, tau, strict=True)},
        "max_tau": max_tau,
        "log_prob_evals": int(steps * walkers),
        "chains": int(n_chains),
    }
    if n_chains > 1:
        rhat = [params[n]["rhat"] for n in names]
        diagnostics["max_rhat"] = float(np.nanmax(rhat)) if np.any(np.isfinite(rhat)) else None
    provenance = _provenance(prob, walkers, seed, getattr(sampler, "whiskerid_move", None))
    post = Posterior(
        params=params,
        diagnostics=diagnostics,
        correlations={"names": names, "matrix": np.round(np.nan_to_num(corr), 6).tolist()},
        samples=kept,
        names=names,
        chain=chain,
        chain_names=list(prob.names),
        provenance=provenance,
        derived_chain=derived_full,
        log_prob=log_prob,
        acceptance_fraction=acc,
        n_chains=n_chains,
        predictive=_predictive(prob, chain[burn::thin], n_chains, n_predictive, seed),
        problem=prob,
        calibration=calibration_agreement(prob.record, params, prob.calibration),
    )
    post.record = _updated_record(prob.record, post)
    return post


def _predictive(prob, kept, n_chains, n, seed) -> dict | None:
    """``n`` simulated recordings at draws spread evenly over the chains (a whole multiple of
    the chains, so that each chain has as many)."""
    if n <= 0:
        return None
    per = math.ceil(n / n_chains)
    rng = np.random.default_rng([max(0 if seed is None else int(seed), 0), 49])
    pooled = by_chain(kept, n_chains)  # (K, W·kept, ndim)
    z = np.concatenate([c[rng.integers(0, c.shape[0], per)] for c in pooled])
    data = observed(prob)
    return {
        "t": [t for t, _ in data],
        "observed": [y for _, y in data],
        "draws": predictive_draws(prob, z, rng),
    }


def _provenance(prob, walkers, seed, move):
    import emcee

    from .._version import __version__

    files = []
    for o in prob.observations:
        if o.source and Path(o.source).exists():
            files.append({"path": str(o.source), "sha256": sha256_of(o.source), "name": o.name})
    return {
        "sampler": f"emcee {emcee.__version__} EnsembleSampler (vectorize=True)",
        "move": move or "unknown",
        "seed": -1 if seed is None else int(seed),
        "walkers": int(walkers),
        "likelihood": prob.model.likelihood,
        "nu": prob.nu if prob.model.likelihood == "student" else 0.0,
        "linear_nuisances": "marginalised analytically (flat prior)"
        if prob.model.marginal
        else "sampled (flat prior)",
        "noise": "unknown sigma per recording, sampled as log sigma",
        "model": "nonlinear" if hasattr(prob, "amplitudes_m") else "linear",
        "n_modes": getattr(prob.args["problem"], "base", prob.args["problem"]).n_modes,
        "pin": prob.pin,
        "priors": prob.priors,
        "start": "Laplace approximation of the calibration fit",
        **(
            {"backbone_amplitudes_m": list(prob.amplitudes_m)}
            if hasattr(prob, "amplitudes_m")
            else {}
        ),
        "data_files": files,
        "whiskerid_version": __version__,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def _updated_record(record: WhiskerRecord, post: Posterior) -> WhiskerRecord:
    d = post.diagnostics
    table = {
        "converged": d["converged"],
        "message": d["message"],
        "params": post.params,
        "diagnostics": {k: v for k, v in d.items() if v is not None},
        "correlations": post.correlations,
        "provenance": post.provenance,
        "calibration": post.calibration,
    }
    extra = dict(record.extra)
    extra["posterior"] = without_none(finite_or_none(table))
    return record.replace(extra=extra)
