"""Posteriors of the whisker's parameters with emcee and a vectorised JAX log-density."""

from .. import _jax_setup as _jax_setup
from ._posterior import Posterior as Posterior
from ._posterior import PosteriorError as PosteriorError
from ._posterior import sample_posterior as sample_posterior
from ._posterior import setup_posterior as setup_posterior
