"""A posterior problem ready to sample (:class:`Problem`) and the names of its coordinates.

Shared by the linear set-up (``_setup``) and the nonlinear one (``_nonlinear``), which both
import it; it imports neither.
"""

from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from ..fit import Observation
from ..model import WhiskerRecord
from ._likelihood import _batch_fn, _Model, _pack


@dataclass
class Problem:
    """A posterior problem, ready to sample (from :func:`setup_posterior`).

    Attributes:
        model: Static model description.
        args: Data and prior numbers (arrays).
        z0: Laplace centre in the sampled space.
        cov: Laplace covariance in the sampled space.
        names: Names of the sampled coordinates.
        priors: The priors used, name → ``(dist, a, b)``, and whether each was a default.
        observations: The recordings.
        record: The whisker's record.
        pin: What fixes EI or C (as in the calibration).
        y_std: Each recording's standard deviation (σ in observed units = σ_rel · y_std).
        calibration: The calibration's reported quantities (value, ``std`` and, where
            computed, ``std_white`` and ``std_without_model_error``), from the fit the
            posterior starts at.
    """

    model: _Model
    args: dict
    z0: np.ndarray
    cov: np.ndarray
    names: list[str]
    priors: dict[str, dict]
    observations: list[Observation]
    record: WhiskerRecord
    pin: str
    y_std: list[float]
    nu: float = 4.0
    calibration: dict | None = None
    # (args, compiled function, packed args) of the last call: looked up and packed once,
    # not on every emcee step (hashing the model alone costs a microsecond or two).
    _compiled: Any = field(default=None, init=False, repr=False, compare=False)

    def log_prob(self, z) -> np.ndarray:
        """Log-posterior at points ``z`` of shape ``(ndim,)`` or ``(walkers, ndim)``."""
        fn, flat = self._batch()
        return np.asarray(fn(np.atleast_2d(np.asarray(z, dtype=float)), flat))

    def _batch(self):
        """The compiled batch log-probability and the packed arguments (looked up and packed
        on the first call and again only when ``args`` is replaced)."""
        if self._compiled is None or self._compiled[0] is not self.args:
            layout, flat = _pack(self.args)
            self._compiled = (self.args, _batch_fn(self.model, layout), flat)
        return self._compiled[1], self._compiled[2]

    def _emcee_log_prob(self):
        """:meth:`log_prob` for emcee's vectorised calls, ``(walkers, ndim)`` in, a list of
        floats out: emcee converts the values one by one, and Python floats convert faster
        than NumPy scalars (a few µs of the step)."""
        fn, flat = self._batch()
        return lambda z: np.asarray(fn(z, flat)).tolist()


def _names(theta, n_rec):
    names = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(theta)[0]:
        key = jax.tree_util.keystr(path).replace("['", ".").replace("']", "").lstrip(".")
        key = key.replace("zeta_u", "logit_zeta")
        n = int(np.size(leaf))
        names += [key] if n == 1 else [f"{key}[{i}]" for i in range(n)]
    return names + [f"log_sigma[{j}]" for j in range(n_rec)]
