"""ArviZ: a run as ``InferenceData`` and R-hat and bulk/tail ESS computed by ArviZ itself.

ArviZ is an optional dependency (``pip install whiskerid[arviz]``), imported here only.
Layout of the ``InferenceData`` (:func:`inference_data`):

- ``chain``: one per independent ensemble (``--chains K``); ``draw``: the ensemble's kept steps
  (after burn-in, thinned) of every walker, walker after walker (each walker's steps in order,
  so ArviZ's autocorrelation sees them as a sequence).
- ``posterior``: the reported quantities (``f1_hz``, ``zeta``, ``kappa``, ``EI`` or ``C`` …,
  ``sigma_j`` the noise σ of recording ``j`` in its observed units).
- ``sample_stats``: ``lp`` (the log-posterior of each draw, up to a constant) and
  ``acceptance_rate`` (the acceptance fraction of the walker the draw comes from: emcee
  accepts or rejects per walker, not per draw).
- ``observed_data``: ``y_j`` of each recording on its own ``time_j`` coordinate (s).
- ``posterior_predictive``: ``y_j`` simulated at posterior draws, noise included
  (:mod:`whiskerid.posterior._predictive`), ``(chain, draw, time_j)``.
"""

import warnings

import numpy as np

#: ArviZ 0.2x warns once a day, on import, about its coming refactor (a FutureWarning that
#: says nothing about this data); it is silenced here and nowhere else.
_REFACTOR_NOTICE = r"\s*ArviZ is undergoing a major refactor"


def import_arviz():
    """``arviz``, or ImportError with the extra that installs it."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=_REFACTOR_NOTICE, category=FutureWarning)
            import arviz
    except ImportError:
        raise ImportError(
            "ArviZ is not installed: pip install 'whiskerid[arviz]' (arviz, with xarray and "
            "h5netcdf for NetCDF files)"
        ) from None
    return arviz


def by_chain(x: np.ndarray, n_chains: int) -> np.ndarray:
    """Kept steps ``(steps, K·W, …)`` → ``(K, W·steps, …)``: walker after walker per chain."""
    steps, walkers = x.shape[:2]
    w = walkers // n_chains
    y = x.reshape(steps, n_chains, w, *x.shape[2:])
    y = np.moveaxis(y, 0, 2)  # (K, W, steps, …)
    return y.reshape(n_chains, w * steps, *x.shape[2:])


def diagnostics(samples: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """R-hat (rank-normalised, split) and bulk and tail ESS of each ``(chain, draw)`` array."""
    az = import_arviz()
    data = az.convert_to_dataset({k: np.asarray(v, float) for k, v in samples.items()})
    with np.errstate(invalid="ignore", divide="ignore"):
        rhat = az.rhat(data)
        bulk = az.ess(data, method="bulk")
        tail = az.ess(data, method="tail")
    return {
        k: {
            "rhat": float(rhat[k].values),
            "ess_bulk": float(bulk[k].values),
            "ess_tail": float(tail[k].values),
        }
        for k in samples
    }


def inference_data(post):
    """The :class:`~whiskerid.posterior.Posterior` ``post`` as ArviZ ``InferenceData``."""
    az = import_arviz()
    k = post.n_chains
    kept = post.derived_chain[post.diagnostics["burn"] :: post.diagnostics["thin"]]
    values = by_chain(kept, k)
    posterior = {name: values[..., i] for i, name in enumerate(post.names)}
    lp = post.log_prob[post.diagnostics["burn"] :: post.diagnostics["thin"]]
    acc = np.broadcast_to(post.acceptance_fraction, lp.shape)
    sample_stats = {"lp": by_chain(lp, k), "acceptance_rate": by_chain(acc, k)}
    pred = post.predictive_draws()
    observed, predictive, coords, dims = {}, {}, {}, {}
    for j, (t, y) in enumerate(zip(pred["t"], pred["observed"], strict=True)):
        name, time = f"y_{j + 1}", f"time_{j + 1}"
        observed[name] = np.asarray(y)
        draws = np.asarray(pred["draws"][j])
        predictive[name] = draws.reshape(k, draws.shape[0] // k, draws.shape[1])
        coords[time] = np.asarray(t)
        dims[name] = [time]
    return az.from_dict(
        posterior=posterior,
        sample_stats=sample_stats,
        observed_data=observed,
        posterior_predictive=predictive,
        coords=coords,
        dims=dims,
        attrs={"inference_library": "emcee", "creation_library": "whiskerid"},
    )
