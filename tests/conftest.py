"""Test configuration: float64 everywhere (the models need it)."""

import jax

jax.config.update("jax_enable_x64", True)
