"""Test configuration: float64 everywhere (the models need it), compiled code freed per module."""

import gc

import jax
import pytest

jax.config.update("jax_enable_x64", True)


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Drop JAX's compiled executables after each test module.

    Every module compiles its own problem shapes; kept for the whole session they add up to
    gigabytes, while a later module rarely reuses them.
    """
    yield
    jax.clear_caches()
    gc.collect()
