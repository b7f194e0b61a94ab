"""Test configuration: float64 everywhere (the models need it), compiled code freed when a
process grows large, quick compilation for the default run.

The default run compiles hundreds of small programs that each run for milliseconds: compiling
them dominates its time, so LLVM's optimisation of the generated machine code is turned down
(``--xla_backend_optimization_level=0`` in ``XLA_FLAGS``, set before JAX compiles anything and
inherited by the workers and by the commands the tests run). The programs compute the same
thing; what changes is how fast their machine code runs, which the tests do not measure
(results may differ in the last bits, far below any test's tolerance). ``pytest -m slow`` uses
it too: its long programs (seeded repeats of fits, sampling) run a little slower, but the
compiles it saves weigh more (the slow checks took 416 s with it against 456 s without, on
2 cores). An optimisation level already in ``XLA_FLAGS`` is left as it is.

JAX's persistent compilation cache points at a folder made for this run (removed at its end):
a test after compiled code was freed loads what an earlier test compiled instead of
compiling it again, and with ``pytest -n 2`` (pytest-xdist) one worker loads what the other
compiled. Nothing is kept between runs, so every run is a cold start, unless
``WHISKERID_TEST_JAX_CACHE`` names a folder: the run then uses it and leaves it in place
(``.ci/run`` gives its default and slow runs one folder, so that the slow checks load what the
default run compiled).
"""

import ctypes
import gc
import os
import shutil
import tempfile

import jax
import pytest

jax.config.update("jax_enable_x64", True)

# Made once by the main pytest process; xdist's workers inherit it through the environment
# (and the marker that this run made it, so that only then is it removed at the end).
_GIVEN = os.environ.get("WHISKERID_TEST_JAX_CACHE")
_CACHE = _GIVEN or tempfile.mkdtemp(prefix="whiskerid-test-jax-cache-")
if not _GIVEN:
    os.environ["WHISKERID_TEST_JAX_CACHE_MADE"] = _CACHE
os.environ["WHISKERID_TEST_JAX_CACHE"] = _CACHE
# Commands run as subprocesses use it too, instead of the user's cache folder.
os.environ["WHISKERID_COMPILE_CACHE"] = _CACHE
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


_QUICK = "--xla_backend_optimization_level=0"


def pytest_configure(config):
    """Quick compilation (JAX reads ``XLA_FLAGS`` when it first compiles, after this hook;
    the workers and commands inherit it)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" in flags:
        return
    os.environ["XLA_FLAGS"] = f"{flags} {_QUICK}".strip()


def pytest_sessionfinish(session, exitstatus):
    """Remove the compilation cache this run made (the main process, after its workers); a
    folder given in ``WHISKERID_TEST_JAX_CACHE`` is left to whoever gave it."""
    made = os.environ.get("WHISKERID_TEST_JAX_CACHE_MADE") == _CACHE
    if os.environ.get("PYTEST_XDIST_WORKER") is None and made:
        shutil.rmtree(_CACHE, ignore_errors=True)


#: A test process holding more than this after a test frees JAX's compiled code (bytes).
FREE_ABOVE_BYTES = 600 * 2**20


@pytest.fixture(autouse=True)
def _free_compiled_code(request):
    """Drop JAX's compiled executables after a test when the process has grown large.

    Every test compiles its own problem shapes; kept, they add up (a module's tests to a
    gigabyte), while later tests rarely reuse them, and then load them from the compilation
    cache above. Freeing after every test would trace again what neighbouring tests share, so
    it happens when the process passes :data:`FREE_ABOVE_BYTES`, and after each module. A
    module that checks what stays compiled between its tests sets ``KEEP_COMPILED = True``.
    """
    yield
    if getattr(request.module, "KEEP_COMPILED", False):
        return
    rss = _resident_bytes()
    if rss is None or rss > FREE_ABOVE_BYTES:
        _free()


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code_of_the_module():
    yield
    _free()


def _resident_bytes() -> int | None:
    """This process's resident memory, or None where ``/proc`` does not tell it."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def _free():
    jax.clear_caches()
    gc.collect()
    _malloc_trim()


def _malloc_trim() -> None:
    """Hand the heap that freed code leaves back to the system (glibc keeps it otherwise, and
    the process stays as large as it ever was); a no-op where there is no glibc."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
