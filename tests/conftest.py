"""Test configuration: float64 everywhere (the models need it), compiled code freed after each
test, quick compilation.

The tests compile hundreds of small programs that each run for milliseconds: compiling them
dominates the suite's time, so LLVM's optimisation of the generated machine code is turned down
(``--xla_backend_optimization_level=0`` in ``XLA_FLAGS``, set before JAX starts and inherited
by the workers and by the commands the tests run). The programs compute the same thing; what
changes is how fast their machine code runs, which the tests do not measure (results may differ
in the last bits, far below any test's tolerance).

JAX's persistent compilation cache points at a folder made for this run (removed at its end):
a test whose compiled code was freed loads what an earlier test compiled instead of
compiling it again, and with ``pytest -n 2`` (pytest-xdist) one worker loads what the other
compiled. Nothing is kept between runs, so every run is a cold start.
"""

import gc
import os
import shutil
import tempfile

_QUICK = "--xla_backend_optimization_level=0"
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_QUICK}".strip()

import jax  # noqa: E402  (after XLA_FLAGS: JAX reads it when it starts)
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

# Made once by the main pytest process; xdist's workers inherit it through the environment.
_CACHE = os.environ.get("WHISKERID_TEST_JAX_CACHE") or tempfile.mkdtemp(
    prefix="whiskerid-test-jax-cache-"
)
os.environ["WHISKERID_TEST_JAX_CACHE"] = _CACHE
# Commands run as subprocesses use it too, instead of the user's cache folder.
os.environ["WHISKERID_COMPILE_CACHE"] = _CACHE
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def pytest_sessionfinish(session, exitstatus):
    """Remove this run's compilation cache (the main process, after its workers)."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        shutil.rmtree(_CACHE, ignore_errors=True)


@pytest.fixture(autouse=True)
def _free_compiled_code(request):
    """Drop JAX's compiled executables after each test.

    Every test compiles its own problem shapes; kept, they add up (a module's tests to a
    gigabyte), while the next test rarely reuses them, and then loads them from the
    compilation cache above in a fraction of the time compiling took. A module that checks
    what stays compiled from one test to the next sets ``KEEP_COMPILED = True``: its code is
    freed when the module ends.
    """
    yield
    if not getattr(request.module, "KEEP_COMPILED", False):
        _free()


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code_of_the_module():
    yield
    _free()


def _free():
    jax.clear_caches()
    gc.collect()
